"""The interface every point-like (delta) light offers to the renderer.

A delta light reaches a shading point from exactly one direction, so it needs one sample
and no pdf: what it answers for a batch of points is the direction toward it, the distance
to it (where a shadow ray ends) and its incident term.  The renderer asks every such light
through :meth:`PointLikeLight.illuminate`, traces one shadow ray per lit point and applies
the material's reflection model (:mod:`rtmesh.shading.direct_light`).  A light may also
offer a compiled row (:meth:`PointLikeLight.kernel_row`): the fused direct-lighting stage
(:mod:`rtmesh.rendering.direct_stage`) then evaluates it inside its kernel; a render with a
light that has no row runs the general path instead, with the same result.

Area lights (quad, disk, emissive meshes: :mod:`rtmesh.lights.area_lights`) are sampled
several times per point with a pdf and are handled by their own stage.

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
