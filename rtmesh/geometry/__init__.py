"""The float32 boundary: Embree scenes and queries (packets or single rays), motion, cut-outs, and the compiled mesh-building kernels."""
