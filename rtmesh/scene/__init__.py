"""The flattened scene a render reads: triangles with per-face ids, materials, lights, camera, background, texture images."""
