"""rtmesh: a CPU ray tracer for triangle-mesh scenes."""
