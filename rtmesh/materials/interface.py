"""What a material model answers for a batch of hits.

Two questions, asked by different stages:

- **Reflection toward the lights** (the local shading stage, for every light sample):
  ``evaluate`` gives ``f(wo, wi) |cos(ns, wi)|`` for given incoming directions, per hit.
  Blinn-Phong answers it in compiled code
  (:func:`rtmesh.materials.blinn_phong.surface_reflectance`, and its row helpers inside the
  fused stage and :func:`rtmesh.shading.direct_light.add_light`).
- **The rays the integrator follows** (the secondary-ray stage): ``sample`` gives, for
  each lobe, the hits that send a ray, its direction and its weight ``f |cos| / pdf``;
  ``pdf`` the density with which a direction is drawn (infinite for a delta lobe) and
  ``evaluate`` the lobe's value toward a direction, so that a light-sampling strategy and
  a BSDF-sampling one can be weighed against each other.
  :class:`rtmesh.materials.specular.SpecularScattering` (mirror, glossy, smooth dielectric)
  is this interface's implementation.

The Whitted integrator follows specular lobes only: Blinn-Phong's diffuse and highlight
terms are evaluated toward the lights and not sampled, so Blinn-Phong offers no
``sample``.  The physically based model of glTF materials
(:mod:`rtmesh.materials.metallic_roughness`) offers all three for one lobe set (per-hit
parameters instead of a material table's rows), and its stage
(the tests' wavefront, ``tests/wavefront/physical_shading.py``) uses its ``pdf`` for multiple importance
sampling.
"""

from typing import Protocol


class Scattering(Protocol):
    """Sampled lobes of a material table, batched over hits (see the module notes)."""

    def sample(self, wo, ns, ng, mat, mirror_tint, refracting, follow, glossy_points=None):
        """The rays of every lobe: ``(reflection, refraction)`` :class:`~rtmesh.materials.specular.Lobe`."""

    def pdf(self, wo, ns, mat, wi):
        """(k,) solid-angle density of drawing ``wi``; ``inf`` for a delta lobe."""

    def evaluate(self, wo, ns, mat, wi):
        """(k, 3) ``f(wo, wi) |cos|``; 0 for a delta lobe."""
