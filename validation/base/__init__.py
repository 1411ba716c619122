"""The shared basics, the lowest layer: planar geometry, YAML reading, strict config models, error types."""
