"""The interfaces lights offer to the renderer: point-like (delta) lights and area lights.

A delta light reaches a shading point from exactly one direction, so it needs one sample
and no pdf: what it answers for a batch of points is the direction toward it, the distance
to it (where a shadow ray ends) and its incident term.  The renderer asks every such light
through :meth:`PointLikeLight.illuminate`, traces one shadow ray per lit point and applies
the material's reflection model (:mod:`rtmesh.shading.direct_light`).  A light may also
offer a compiled row (:meth:`PointLikeLight.kernel_row`): the fused direct-lighting stage
(:mod:`rtmesh.rendering.direct_stage`) then evaluates it inside its kernel; a render with a
light that has no row runs the general path instead, with the same result.

Area lights (quad and disk: :mod:`rtmesh.lights.area_lights`; emissive meshes:
:mod:`rtmesh.lights.mesh_lights`) satisfy
:class:`AreaLight`: they are sampled several times per point (``light_samples``), each
sample a point on the light with its normal, radiance and inverse pdf by area, and rays
can meet them (``intersect``), so camera and mirror rays see them.  Their stage
(:class:`rtmesh.lights.area_lighting.AreaLighting`) turns the samples into directions,
distances and shadow rays.  A delta light is the one-sample case of the same estimator
(its "point" is fixed, its pdf a delta), which is why it gets the cheaper interface.
That stage and the environment's (:class:`rtmesh.lights.environment.EnvironmentLighting`)
both answer :meth:`SampledLighting.direct`, as the shading stages call them.

A new light type is its module (its class, which satisfies this protocol, and its
:class:`rtmesh.lights.light_types.LightType`), one entry in
:data:`rtmesh.loaders.light_registry.LIGHT_TYPES`, its documentation and its tests.
"""

from typing import Protocol, runtime_checkable


@runtime_checkable
class PointLikeLight(Protocol):
    """A light that reaches each point from one direction."""

    def illuminate(self, points):
        """Direction toward the light, distance and incident term at each point.

        Parameters
        ----------
        points : (k, 3) float64
            Shading points, world space (scene units).

        Returns
        -------
        wi : (k, 3) float64
            Unit directions from the points toward the light (0 where the light cannot
            reach a point, e.g. a point exactly at its position).
        distance : (k,) float64
            Distance to the light, scene units; ``inf`` for lights infinitely far away.
        incident : (k, 3) float64
            The term that multiplies the material's reflection factor: radiant intensity
            over squared distance (W/sr / unit^2) for local lights, irradiance (W/m^2) for
            distant ones; 0 where the light does not reach.
        """

    def kernel_row(self):
        """The light's compiled row (:func:`rtmesh.lights.point_light_rows.pack_row`), or
        None for a light that only offers :meth:`illuminate`."""

    @property
    def is_black(self):
        """True when the light emits nothing (the renderer drops it)."""


@runtime_checkable
class AreaLight(Protocol):
    """A light with a surface: sampled by area, and seen by rays that meet it."""

    two_sided: bool
    visible: bool

    def sample(self, u, p=None):
        """Points on the light for sample points ``u`` ((k, 2) in [0, 1)^2).

        Parameters
        ----------
        u : (k, 2) float64
        p : (k, 3) float64, optional
            The points being lit, for lights that sample the solid angle they subtend.

        Returns
        -------
        points : (k, 3) float64
        normals : (3,) or (k, 3) float64
            Unit normals of the light at the points (its emitting side).
        radiance : (3,) or (k, 3) float64
            Emitted radiance, W / (sr m^2).
        inverse_pdf : float or (k,) float64
            ``1 / pdf`` with respect to area on the light (scene units^2).
        """

    def intersect(self, origins, directions):
        """(n,) distance along each ray to the light's emitting side; ``inf`` where it misses."""

    def pdf(self, origins, directions, t):
        """(n,) solid-angle density with which :meth:`sample` (from ``origins``) reaches the
        light along unit ``directions`` that meet it at distances ``t``: what a ray drawn by
        a BSDF needs for its multiple-importance weight.  (The emissive triangles of a
        scene, :class:`rtmesh.lights.mesh_lights.MeshLight`, are met as geometry and answer
        for faces and points instead.)"""

    @property
    def is_black(self):
        """True when the light emits nothing."""


class SampledLighting(Protocol):
    """Light that a hit gathers by sampling directions and tracing shadow rays: the area
    lights of a scene (:class:`rtmesh.lights.area_lighting.AreaLighting`) and the background
    lighting it (:class:`rtmesh.lights.environment.EnvironmentLighting`).  The shading
    stages call both the same way."""

    def direct(self, p, ng, reflectance, pixel, sample, depth, stats, clock, time=None):
        """Direct light at every hit, ``light_samples`` shadow rays per hit (and light).

        Parameters
        ----------
        p : (k, 3) float
            Shading points.
        ng : (k, 3) float
            Unit geometric normals on the side the incoming ray came from: light from
            behind the surface does not light it, and shadow rays leave on that side.
        reflectance : callable
            ``reflectance(wi, lit, pdf) -> (k, 3)``: the material's reflection factor for
            unit directions ``wi`` toward the light, evaluated (at least) where ``lit``;
            ``pdf`` is the solid-angle density of each sample (for MIS weights).
        pixel, sample : (k,) int
            Pixel and sample-in-pixel of each hit: the keys of its random numbers.
        depth : int
            Path depth of the hits (its own sample dimensions).
        stats : RenderStats
            Shadow rays are counted (each implementation names its counter).
        clock : object with ``lap(stage)``
            Times the work as ``shade`` and ``shadow``.
        time : (k,) float, optional
            Time of each hit's ray, with motion blur: the shadow rays see the moving objects
            at that time.

        Returns
        -------
        (k, 3) float64 or None
            None when no sample reached any hit.
        """
