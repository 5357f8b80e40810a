"""The Whitted integrator's rows in the path kernel (rtmesh.rendering.whitted_rows) against
the scalar references they were written from: the Blinn-Phong factor of the fused stage
(rtmesh.materials.blinn_phong), the specular lobes of rtmesh.materials.specular, and the
Fresnel reflectances of rtmesh.core.vecmath."""

import numba
import numpy as np
import pytest

from rtmesh.core.vecmath import fresnel_dielectric, fresnel_schlick, normalize
from rtmesh.materials import phong
from rtmesh.materials.blinn_phong import blinn_phong_factors
from rtmesh.materials.lobes import PARAMETER_WIDTH
from rtmesh.materials.specular import SpecularScattering
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.rendering import whitted_rows


@numba.njit
def _factors(params, wo, wi):
    out = np.zeros((len(wo), 3))
    for i in range(len(wo)):
        out[i, 0], out[i, 1], out[i, 2] = whitted_rows.light_factor(params, 0, wo[i, 0], wo[i, 1], wo[i, 2], wi[i, 0],
                                                                     wi[i, 1], wi[i, 2])
    return out


@numba.njit
def _fresnel(cos_i, eta, exact):
    out = np.zeros(len(cos_i))
    for i in range(len(cos_i)):
        out[i] = whitted_rows.fresnel(cos_i[i], eta[i], exact)
    return out


@numba.njit
def _branches(params, wo, ns, ng, entering, exact, u):
    reflect, transmit = np.zeros((len(wo), 6)), np.zeros((len(wo), 6))
    for i in range(len(wo)):
        (reflect[i, 0], reflect[i, 1], reflect[i, 2], reflect[i, 3], reflect[i, 4], reflect[i, 5], transmit[i, 0],
         transmit[i, 1], transmit[i, 2], transmit[i, 3], transmit[i, 4], transmit[i, 5]) = whitted_rows.branches(
            params, 0, wo[i, 0], wo[i, 1], wo[i, 2], ns[i, 0], ns[i, 1], ns[i, 2], ng[i, 0], ng[i, 1], ng[i, 2],
            entering, exact, u[i, 0], u[i, 1])
    return reflect, transmit


def _row(material):
    params = np.zeros((1, PARAMETER_WIDTH))
    values = phong.parameters(material)
    params[0, :len(values)] = values
    return params


def _upper(n, rng):
    v = normalize(rng.normal(size=(n, 3)))
    v[:, 2] = np.abs(v[:, 2])
    return v


@pytest.mark.parametrize("shininess", [0.0, 12.0, 250.0])
def test_light_factor_is_the_fused_stages_blinn_phong(shininess):
    """kd max(0, cos) + ks (n.h)^n in the shading frame (n = +z) against the fused stage's
    kernel on world vectors, over random directions (half of them below the horizon)."""
    rng = np.random.default_rng(4)
    material = Material(diffuse=(0.6, 0.3, 0.1), specular=(0.2, 0.4, 0.5), shininess=shininess)
    wo, wi = _upper(3000, rng), normalize(rng.normal(size=(3000, 3)))
    ours = _factors(_row(material), wo, wi)
    n = np.tile([0.0, 0.0, 1.0], (3000, 1))
    reference = blinn_phong_factors(n, wo, wi, np.tile(material.diffuse, (3000, 1)),
                                    np.tile(material.specular, (3000, 1)), np.full(3000, shininess))
    # (the stages test the horizon before they evaluate: the reference's 0 ** 0 below it
    # is never used)
    above = wi[:, 2] > 0
    assert (ours[~above] == 0).all() and ours.max() > 0
    np.testing.assert_allclose(ours[above], reference[above], rtol=1e-12, atol=1e-15)


def test_light_factor_seen_from_inside_is_turned_to_the_viewer():
    """A transmissive material's frame keeps its outward side: a hit from inside (wo.z < 0)
    is shaded as from outside with both directions mirrored."""
    rng = np.random.default_rng(5)
    params = _row(Material(diffuse=0.5, specular=0.3, shininess=20.0, transmission=0.5))
    wo, wi = _upper(500, rng), normalize(rng.normal(size=(500, 3)))
    flip = np.array([1.0, 1.0, -1.0])
    np.testing.assert_array_equal(_factors(params, wo * flip, wi * flip), _factors(params, wo, wi))


@pytest.mark.parametrize("exact", [False, True])
def test_fresnel_is_the_whitted_stages_reflectance(exact):
    rng = np.random.default_rng(6)
    cos_i = rng.random(4000)
    eta = np.concatenate([np.full(1000, 1 / 1.5), np.full(1000, 1.5), np.full(1000, 1.0), rng.uniform(0.5, 2, 1000)])
    reference = (fresnel_dielectric if exact else fresnel_schlick)(cos_i, eta)
    np.testing.assert_allclose(_fresnel(cos_i, eta, exact), reference, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("exact", [False, True])
@pytest.mark.parametrize("entering", [True, False])
@pytest.mark.parametrize("roughness", [0.0, 0.15])
def test_branches_are_the_specular_scattering_of_the_whitted_stages(exact, entering, roughness):
    """Mirror and glass rays with their weights (Fresnel, total internal reflection, rough
    mirrors' Phong lobe, bent shading normals) against SpecularScattering.sample."""
    rng = np.random.default_rng(7)
    n = 2000
    material = Material(mirror=(0.3, 0.2, 0.1), transmission=(0.9, 0.8, 0.7), ior=1.5, roughness=roughness)
    ng = np.tile([0.0, 0.0, 1.0], (n, 1))
    # shading normals bent up to ~35 degrees, viewers above the geometric surface
    ns = normalize(ng + 0.4 * rng.normal(size=(n, 3)) * [1, 1, 0])
    wo = _upper(n, rng)
    seen = (wo * ns).sum(axis=1) > 0.05
    wo, ns, ng = wo[seen], ns[seen], ng[seen]
    u = rng.random((len(wo), 2))
    ior = 1.5
    eta = 1.0 / ior if entering else ior
    scattering = SpecularScattering(MaterialTable([material]), "exact" if exact else "schlick")
    rows = np.arange(len(wo))
    reflection, refraction = scattering.sample(wo, ns, ng, np.zeros(len(wo), np.intp), None, (rows, np.full(len(wo), eta)),
                                               lambda r, w: np.ones(len(w), bool),
                                               (lambda r: u[r]) if roughness > 0 else None)
    params = _row(material)
    params[0, 13] = ior  # the kernel's ratio of the inside's index over the outside's
    reflect, transmit = _branches(params, wo, ns, ng, entering, exact, u)
    np.testing.assert_allclose(reflect[reflection.rows, :3], reflection.directions, atol=1e-9)
    np.testing.assert_allclose(reflect[reflection.rows, 3:], reflection.weight, rtol=1e-12, atol=1e-15)
    through = np.zeros(len(wo), bool)
    through[refraction.rows] = True
    assert through.any() and (entering or not through.all())  # from inside some are totally reflected
    np.testing.assert_allclose(transmit[refraction.rows, :3], refraction.directions, atol=1e-12)
    np.testing.assert_allclose(transmit[refraction.rows, 3:], refraction.weight, rtol=1e-12, atol=1e-15)
    assert (transmit[~through, 3:] == 0).all()


def test_branches_of_a_viewer_below_the_normals_turn_them_over():
    """Normals given on the far side are turned to the viewer's first."""
    rng = np.random.default_rng(8)
    params = _row(Material(mirror=0.8))
    wo = _upper(300, rng)
    up = np.tile([0.0, 0.0, 1.0], (300, 1))
    a, _ = _branches(params, wo, up, up, True, False, rng.random((300, 2)))
    b, _ = _branches(params, wo, -up, -up, True, False, rng.random((300, 2)))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a[:, :3], wo * [-1, -1, 1], atol=1e-15)
