"""The general wavefront: NumPy batches of a chunk's rays, a depth level at a time, with
the Whitted integrator's shading (``local_shading``), mirror and glass rays
(``secondary_rays``) and metallic-roughness path tracing (``physical_shading``).

It rendered every scene the fused stage did not take before the path kernel did; it is now
the kernel's test reference: ``monkeypatch.setattr(integrator_module, "REFERENCE_STAGE",
wavefront.attach)`` renders Whitted scenes through it (``tests/rendering/test_whitted_kernel.py``
compares the two on every Whitted scene of ``assets/``).
"""


def attach(integrator):
    """Build the wavefront's stages for ``integrator`` (each reads the integrator's tables;
    the shading stages are set on it as ``local_shading``, ``secondary_rays``,
    ``physical_shading``, the area lights' estimator as ``area_lighting``) and return the stage that renders its chunks
    (:data:`rtmesh.rendering.integrator.REFERENCE_STAGE`'s contract)."""
    from rtmesh.lights.area_lighting import AreaLighting
    from wavefront.kernels import GENERAL_KERNELS
    from wavefront.local_shading import LocalShading
    from wavefront.physical_shading import PhysicalShading
    from wavefront.secondary_rays import SecondaryRays
    from wavefront.stage import Wavefront

    # the area lights and the world's emissive faces (one MeshLight) as one NumPy estimator
    it = integrator
    area = it.area_lights + ([it.built.emitters] if it.built.emitters is not None else [])
    it.area_lighting = AreaLighting(area, it.accel, it.settings, it.offset_scale) if area else None
    integrator.local_shading = LocalShading(integrator)
    integrator.secondary_rays = SecondaryRays(integrator)
    integrator.physical_shading = PhysicalShading(integrator) if integrator.plan.physical else None
    integrator.wavefront = Wavefront(integrator)
    GENERAL_KERNELS.prepare()
    return integrator.wavefront
