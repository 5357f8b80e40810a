"""rtmesh.core.vecmath against closed forms and scalar textbook references."""

import math
import warnings

import numpy as np
import pytest

from rtmesh.core.vecmath import (dot, fresnel_dielectric, fresnel_schlick, norm, normalize, orthonormal_basis,
                                 reflect, refract)

ETAS = [1.0 / 1.5, 1.0 / 1.33, 1.0 / 2.4, 1.5, 1.33, 2.4, 1.25]


def random_unit_vectors(count, seed):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1)[:, None]


def directions_at_angles(normals, angles, seed):
    """Unit directions making ``angles`` (radians) with ``normals``, random azimuth."""
    rng = np.random.default_rng(seed)
    helper = rng.normal(size=normals.shape)
    tangent = helper - np.einsum("ij,ij->i", helper, normals)[:, None] * normals
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    return np.cos(angles)[:, None] * normals + np.sin(angles)[:, None] * tangent


# ---------------------------------------------------------------- scalar references
def refract_reference(wo, normal, refraction_ratio):
    """Ray Tracing in One Weekend's refract, for the incoming direction ``-wo``.

    Returns None when the ray cannot refract.
    """
    incoming = [-x for x in wo]
    cos_theta = min(-sum(incoming[i] * normal[i] for i in range(3)), 1.0)
    sin_theta = math.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    cannot_refract = refraction_ratio * sin_theta >= 1.0
    if cannot_refract:
        return None
    perpendicular = [refraction_ratio * (incoming[i] + cos_theta * normal[i]) for i in range(3)]
    parallel_length = -math.sqrt(abs(1.0 - sum(x * x for x in perpendicular)))
    return [perpendicular[i] + parallel_length * normal[i] for i in range(3)]


def fresnel_reference(incident_angle, n_incident, n_transmitted):
    """Unpolarised Fresnel reflectance from Hecht's s/p amplitude formulas in angles.

    ``r_s = -sin(i - t) / sin(i + t)`` and ``r_p = tan(i - t) / tan(i + t)``; valid away
    from normal incidence (0 / 0 there).  Returns (R, R_s, R_p).
    """
    sin_transmitted = n_incident / n_transmitted * math.sin(incident_angle)
    if sin_transmitted >= 1.0:
        return 1.0, 1.0, 1.0
    transmitted_angle = math.asin(sin_transmitted)
    difference = incident_angle - transmitted_angle
    total = incident_angle + transmitted_angle
    amplitude_s = -math.sin(difference) / math.sin(total)
    amplitude_p = math.tan(difference) / math.tan(total)
    reflectance_s = amplitude_s * amplitude_s
    reflectance_p = amplitude_p * amplitude_p
    return 0.5 * (reflectance_s + reflectance_p), reflectance_s, reflectance_p


# ---------------------------------------------------------------- dot / normalize
def test_dot_and_norm_match_numpy():
    a = random_unit_vectors(100, 1) * 3.0
    b = random_unit_vectors(100, 2)
    np.testing.assert_allclose(dot(a, b), (a * b).sum(axis=1), rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(norm(a), 3.0, rtol=1e-14)


def test_dot_is_bit_identical_for_every_layout_and_length():
    # renders are bit-identical for any chunking only if a row's dot product does not depend
    # on how its array is stored or how many rows are beside it
    rng = np.random.default_rng(11)
    a, b = rng.normal(size=(2, 257, 3)) * rng.uniform(1e-3, 1e3, size=(2, 257, 1))
    expected = (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]) + a[:, 2] * b[:, 2]
    for layout in (np.ascontiguousarray, np.asfortranarray):
        np.testing.assert_array_equal(dot(layout(a), layout(b)), expected)
        for start, stop in ((0, 1), (5, 7), (3, 260)):
            np.testing.assert_array_equal(dot(layout(a[start:stop]), layout(b[start:stop])),
                                          expected[start:stop])
    np.testing.assert_array_equal(dot(a, np.broadcast_to(b[0], a.shape)), dot(a, np.tile(b[0], (257, 1))))


def test_normalize_gives_unit_vectors_in_the_same_direction():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(200, 3)) * rng.uniform(1e-6, 1e6, size=(200, 1))
    unit = normalize(a)
    np.testing.assert_allclose(np.linalg.norm(unit, axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(np.cross(unit, a) / np.linalg.norm(a, axis=1)[:, None], 0.0, atol=1e-14)
    assert (dot(unit, a) > 0).all()


def test_normalize_of_zero_vector_is_zero_not_nan():
    a = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 4.0], [-0.0, 0.0, -0.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a 0/0 RuntimeWarning would fail here
        unit = normalize(a)
    assert np.isfinite(unit).all()
    np.testing.assert_array_equal(unit[0], 0.0)
    np.testing.assert_array_equal(unit[2], 0.0)
    np.testing.assert_allclose(unit[1], [0.6, 0.0, 0.8], rtol=1e-15)


# ---------------------------------------------------------------- reflect
def test_reflect_matches_the_mirror_closed_form():
    wo = np.array([[1.0, 1.0, 0.0]]) / math.sqrt(2.0)
    n = np.array([[0.0, 1.0, 0.0]])
    np.testing.assert_allclose(reflect(wo, n), [[-1.0 / math.sqrt(2.0), 1.0 / math.sqrt(2.0), 0.0]],
                               atol=1e-15)
    # head-on: straight back
    np.testing.assert_allclose(reflect(n, n), n, atol=1e-15)


def test_reflect_keeps_angle_and_plane_and_is_unit():
    n = random_unit_vectors(500, 4)
    wo = directions_at_angles(n, np.random.default_rng(5).uniform(0, math.pi / 2, 500), 6)
    wr = reflect(wo, n)
    np.testing.assert_allclose(np.linalg.norm(wr, axis=1), 1.0, rtol=1e-13)
    # equal angles on both sides of the normal
    np.testing.assert_allclose(dot(wr, n), dot(wo, n), atol=1e-13)
    # wo + wr lies along n (tangential parts cancel)
    s = wo + wr
    np.testing.assert_allclose(np.cross(s, n), 0.0, atol=1e-13)
    # reflecting twice gives back wo
    np.testing.assert_allclose(reflect(wr, n), wo, atol=1e-13)


# ---------------------------------------------------------------- refract / Snell
@pytest.mark.parametrize("eta", ETAS)
def test_refract_obeys_snells_law(eta):
    angles = np.radians(np.linspace(0.0, 89.0, 90))
    n = random_unit_vectors(len(angles), 7)
    wo = directions_at_angles(n, angles, 8)
    wt, tir = refract(wo, n, eta)
    sin_i = np.sin(angles)
    expected_tir = eta * sin_i >= 1.0
    np.testing.assert_array_equal(tir, expected_tir)
    ok = ~tir
    assert ok.any()
    # unit, into the far side
    np.testing.assert_allclose(np.linalg.norm(wt[ok], axis=1), 1.0, rtol=1e-12)
    assert (dot(wt[ok], n[ok]) < 0.0).all()
    # sin ratio: sin_t / sin_i == eta
    sin_t = np.linalg.norm(np.cross(wt[ok], n[ok]), axis=1)
    np.testing.assert_allclose(sin_t, eta * sin_i[ok], rtol=1e-10, atol=1e-13)
    # wo, n and wt lie in one plane, and the ray keeps going the same way along the surface
    np.testing.assert_allclose(dot(np.cross(wo[ok], n[ok]), wt[ok]), 0.0, atol=1e-13)
    tangent_in = -(wo - dot(wo, n)[:, None] * n)
    tangent_out = wt - dot(wt, n)[:, None] * n
    assert (dot(tangent_in[ok], tangent_out[ok]) >= -1e-15).all()


@pytest.mark.parametrize("eta", ETAS)
def test_refract_matches_scalar_reference(eta):
    n = random_unit_vectors(300, 9)
    wo = directions_at_angles(n, np.random.default_rng(10).uniform(0, math.pi / 2, 300), 11)
    wt, tir = refract(wo, n, eta)
    for i in range(len(n)):
        reference = refract_reference(wo[i].tolist(), n[i].tolist(), eta)
        if reference is None:
            assert tir[i]
        else:
            assert not tir[i]
            np.testing.assert_allclose(wt[i], reference, atol=1e-12)


def test_refract_accepts_per_ray_eta():
    n = random_unit_vectors(len(ETAS), 12)
    wo = directions_at_angles(n, np.full(len(ETAS), 0.5), 13)
    eta = np.array(ETAS)
    wt, tir = refract(wo, n, eta)
    for i, e in enumerate(ETAS):
        one, one_tir = refract(wo[i:i + 1], n[i:i + 1], e)
        np.testing.assert_array_equal(wt[i], one[0])
        assert tir[i] == one_tir[0]


def test_total_internal_reflection_exactly_at_and_beyond_the_critical_angle():
    # eta = 1.25 and cos_i = 0.6: eta^2 (1 - cos_i^2) = 1.5625 * 0.64 == 1.0 exactly in
    # float64, so this is the critical angle with no rounding on either side.
    eta = 1.25
    assert eta * eta * (1.0 - 0.6 * 0.6) == 1.0
    critical_cos = 0.6
    cos_i = np.array([
        1.0, 0.9, 0.7, np.nextafter(critical_cos, 1.0) + 1e-9,  # below the critical angle
        critical_cos,  # exactly at it
        np.nextafter(critical_cos, 0.0), 0.5, 0.2, 0.0,  # beyond it
    ])
    expected = np.array([False, False, False, False, True, True, True, True, True])
    n = np.tile([[0.0, 0.0, 1.0]], (len(cos_i), 1))
    wo = np.column_stack([np.sqrt(1.0 - cos_i ** 2), np.zeros_like(cos_i), cos_i])
    wt, tir = refract(wo, n, eta)
    np.testing.assert_array_equal(tir, expected)
    np.testing.assert_array_equal(wt[tir], 0.0)
    assert np.isfinite(wt).all()
    # under TIR every photon is reflected
    np.testing.assert_array_equal(fresnel_dielectric(cos_i[tir], eta), 1.0)
    np.testing.assert_array_equal(fresnel_schlick(cos_i[tir], eta), 1.0)
    assert (fresnel_dielectric(cos_i[~tir], eta) < 1.0).all()


@pytest.mark.parametrize("eta", [1.0 / 1.5, 1.0 / 2.4, 1.0])
def test_no_total_internal_reflection_entering_a_denser_medium(eta):
    # exactly grazing (cos_i = 0) with eta = 1 sits on the TIR boundary sin_t = 1; leave it out
    cos_i = np.linspace(1e-6, 1.0, 101) if eta == 1.0 else np.linspace(0.0, 1.0, 101)
    wo = np.column_stack([np.sqrt(1.0 - cos_i ** 2), np.zeros_like(cos_i), cos_i])
    n = np.tile([[0.0, 0.0, 1.0]], (len(cos_i), 1))
    _, tir = refract(wo, n, eta)
    assert not tir.any()


def test_refract_with_eta_one_goes_straight_through():
    n = random_unit_vectors(100, 14)
    wo = directions_at_angles(n, np.random.default_rng(15).uniform(0, 1.5, 100), 16)
    wt, tir = refract(wo, n, 1.0)
    assert not tir.any()
    np.testing.assert_allclose(wt, -wo, atol=1e-14)


# ---------------------------------------------------------------- Fresnel
@pytest.mark.parametrize("n1, n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 1.33), (1.33, 1.0),
                                    (1.0, 2.4), (2.4, 1.0), (1.2, 1.7), (1.0, 1.0)])
@pytest.mark.parametrize("fresnel", [fresnel_schlick, fresnel_dielectric])
def test_fresnel_at_normal_incidence_is_r0(fresnel, n1, n2):
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    np.testing.assert_allclose(fresnel(np.array([1.0]), n1 / n2), [r0], rtol=1e-12, atol=1e-16)


@pytest.mark.parametrize("eta", ETAS)
@pytest.mark.parametrize("fresnel", [fresnel_schlick, fresnel_dielectric])
def test_fresnel_at_grazing_incidence_is_one(fresnel, eta):
    np.testing.assert_allclose(fresnel(np.array([0.0, 1e-9]), eta), 1.0, atol=1e-7)


@pytest.mark.parametrize("n1, n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 1.33), (1.33, 1.0),
                                    (1.0, 2.4), (2.4, 1.0), (1.5, 1.7)])
def test_exact_fresnel_matches_s_and_p_textbook_reference(n1, n2):
    angles = np.radians(np.linspace(0.5, 89.5, 179))
    computed = fresnel_dielectric(np.cos(angles), n1 / n2)
    expected = np.array([fresnel_reference(a, n1, n2)[0] for a in angles])
    np.testing.assert_allclose(computed, expected, rtol=1e-9, atol=1e-12)
    assert ((computed >= 0.0) & (computed <= 1.0)).all()


@pytest.mark.parametrize("n1, n2", [(1.0, 1.5), (1.5, 1.0), (1.0, 2.4)])
def test_exact_fresnel_at_brewster_angle_has_no_p_reflection(n1, n2):
    brewster = math.atan(n2 / n1)
    total, reflectance_s, reflectance_p = fresnel_reference(brewster, n1, n2)
    assert reflectance_p < 1e-25
    computed = fresnel_dielectric(np.array([math.cos(brewster)]), n1 / n2)[0]
    assert computed == pytest.approx(0.5 * reflectance_s, rel=1e-9)


@pytest.mark.parametrize("eta", [1.0 / 1.5, 1.5])
def test_schlick_is_within_a_few_percent_of_exact_for_glass(eta):
    angles = np.radians(np.linspace(0.0, 89.9, 500))
    cos_i = np.cos(angles)
    exact = fresnel_dielectric(cos_i, eta)
    schlick = fresnel_schlick(cos_i, eta)
    # Schlick's well-known worst case for glass is about 0.036 absolute near 60-85 degrees
    assert np.abs(schlick - exact).max() < 0.04
    # and near-normal incidence (angle on the air side, where Schlick's cosine is taken)
    # it is accurate relative to the value itself
    air_side_sin = np.minimum(np.sin(angles) * max(eta, 1.0), 1.0)
    near_normal = np.arcsin(air_side_sin) <= np.radians(25.0)
    np.testing.assert_allclose(schlick[near_normal], exact[near_normal], rtol=0.02)
    # both reach 1 at the same critical angle going out of the glass
    np.testing.assert_array_equal(exact == 1.0, schlick == 1.0)


def test_fresnel_is_monotone_from_air_into_glass():
    cos_i = np.linspace(1.0, 0.0, 400)
    for fresnel in (fresnel_schlick, fresnel_dielectric):
        f = fresnel(cos_i, 1.0 / 1.5)
        assert (np.diff(f) >= -1e-15).all()


# ---------------------------------------------------------------- orthonormal basis
def basis_test_normals():
    special = np.array([
        [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -0.0],
    ])[:6]
    # normals within a hair of -z, where the classic Frisvad construction breaks down
    tiny = np.array([1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-15])
    near_minus_z = normalize(np.column_stack([tiny, -0.7 * tiny, -np.ones_like(tiny)]))
    near_plus_z = normalize(np.column_stack([tiny, 0.3 * tiny, np.ones_like(tiny)]))
    return np.concatenate([special, near_minus_z, near_plus_z, random_unit_vectors(2000, 17)])


def test_orthonormal_basis_is_orthonormal_and_right_handed():
    n = basis_test_normals()
    t, b = orthonormal_basis(n)
    assert np.isfinite(t).all() and np.isfinite(b).all()
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(dot(t, b), 0.0, atol=1e-12)
    np.testing.assert_allclose(dot(t, n), 0.0, atol=1e-12)
    np.testing.assert_allclose(dot(b, n), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-12)


def test_orthonormal_basis_at_exactly_minus_z_and_signed_zero():
    n = np.array([[0.0, 0.0, -1.0], [-0.0, -0.0, -1.0], [0.0, 0.0, 1.0], [-0.0, 0.0, 1.0]])
    t, b = orthonormal_basis(n)
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-15)
    np.testing.assert_allclose(dot(t, n), 0.0, atol=1e-15)


def test_face_viewer_bends_only_normals_facing_away_and_keeps_them_above_the_surface():
    from rtmesh.core.vecmath import normalize
    from rtmesh.shading.surfaces import face_viewer

    rng = np.random.default_rng(3)
    n = 2000
    ng = np.tile([0.0, 0.0, 1.0], (n, 1))
    # incoming directions from above (the side ng is on), some grazing
    d = normalize(np.column_stack([rng.normal(size=(n, 2)), -rng.uniform(0.02, 1.0, n)]))
    # shading normals tilted up to 80 degrees from ng, some below the surface
    ns = normalize(np.column_stack([rng.normal(size=(n, 2)) * 2.0, rng.uniform(-0.3, 1.0, n)]))
    out = face_viewer(ns, ng, d)
    wo = -d
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0)
    assert ((out * wo).sum(axis=1) > 0.0).all()  # faces the viewer: no black speckles
    assert ((out * ng).sum(axis=1) > 0.0).all()  # never below the real surface
    fine = ((ns * wo).sum(axis=1) >= 1e-2) & (ns[:, 2] > 0.0)
    np.testing.assert_array_equal(out[fine], ns[fine])  # the others are left alone
    assert (~fine).sum() > 100  # the test exercised the fix


def test_repeated_row_is_a_read_only_broadcast_of_the_row():
    from rtmesh.core.rays import repeated_row

    for row in (np.array([0.5, -1.0, 2.0]), np.array([3, 1], dtype=np.int32), np.zeros(0, np.int32)):
        view = repeated_row(row, 5)
        np.testing.assert_array_equal(view, np.broadcast_to(row, (5, len(row))))
        assert view.dtype == row.dtype and not view.flags.writeable
        with pytest.raises(ValueError):
            view[0] = 0
