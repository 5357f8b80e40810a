"""Light sources: point, directional and spot lights, area lights (quad, disk, emissive mesh), and what a light type declares to scene files."""
