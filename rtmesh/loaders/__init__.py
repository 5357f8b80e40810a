"""Files to scenes: TOML scene files, mesh files through trimesh, MTL and glTF materials, glTF cameras and lights, the light-type registry."""
