"""Surface appearance: the material table and the reflection lobes sampled from it."""
