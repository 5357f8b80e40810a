"""The render: settings, the plan of stages, the integrator and its stages, chunks on threads, adaptive rounds, the film, statistics."""
