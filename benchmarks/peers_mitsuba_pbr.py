"""Mitsuba 3 side of benchmarks/bench_pbr_peers.py; runs inside the peers venv, never imports rtmesh.

Reads a JSON list of render jobs that bench_pbr_peers.py wrote, renders each with Mitsuba's
``path`` integrator in one variant, and writes, per job, an ``.npz`` file holding the two
half-sample renders (seeds 0 and 1, ``spp / 2`` samples each, a square number: the
``stratified`` sampler jitters one sample in each cell of a ``sqrt(spp / 2)`` grid, which
the sharp reflections of the studio's softboxes need; their mean is the reference, their
difference measures its noise), the seconds they took and Mitsuba's version.

A job names its mesh (a PLY file with vertex normals, the exact triangles rtmesh renders),
its BSDF, its light and its camera:

- ``bsdf.model``: ``gltf`` (:class:`GltfBSDF` below: the glTF 2.0 metallic-roughness BRDF of
  the specification's Appendix B, written here as a Mitsuba plugin in Python), ``principled``
  (Mitsuba's Disney BSDF with ``specular = 0.5``, i.e. F0 = 0.04, eta = 1.5), ``roughplastic``
  (GGX, ``int_ior = 1.5``, ``nonlinear = false``), ``diffuse`` or ``mirror`` (a perfect
  conductor);
- ``light.type``: ``point`` (intensity in W/sr, Mitsuba's ``point``) or ``envmap`` (a
  ``.npy`` latitude-longitude image in Mitsuba's layout and a rotation about +Y that turns
  Mitsuba's map into rtmesh's; see bench_pbr_peers.py);
- the camera goes through :func:`benchmarks.peers_mitsuba.sensor_dict`, shared with benchmarks/bench_peers.py.

Usage, from the repository root (bench_pbr_peers.py runs it; ``--self-test`` checks the glTF
BSDF, see :func:`self_test`)::

    /tmp/peers-venv/bin/python -m benchmarks.peers_mitsuba_pbr JOBS.json VARIANT
    /tmp/peers-venv/bin/python -m benchmarks.peers_mitsuba_pbr --self-test
"""

import argparse
import json
import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from benchmarks.peers_mitsuba import sensor_dict

# Mitsuba's own plugins for the peer models, from a job's base colour, metallic and roughness
PEER_MODELS = ("principled", "roughplastic")


def gltf_bsdf_class():
    """The class of the glTF metallic-roughness BSDF (defined once a variant is set).

    Returns
    -------
    type
        A ``mi.BSDF`` subclass taking the properties ``base_r``, ``base_g``, ``base_b``
        (linear base colour), ``metallic`` and ``roughness``.
    """

    class GltfBSDF(mi.BSDF):
        """glTF 2.0 metallic-roughness, as written in the specification's Appendix B.

        ``f = (1 - m) [(1 - F_d) c / pi + F_d V D] + m F_m V D`` with D the GGX (Trowbridge-Reitz)
        distribution of ``alpha = roughness^2``, V the height-correlated Smith visibility
        ``G2 / (4 |n.l| |n.v|)``, ``F_d = 0.04 + 0.96 (1 - |v.h|)^5`` (dielectric, ior 1.5)
        and ``F_m = c + (1 - c) (1 - |v.h|)^5`` (Schlick with F0 = base colour c); one-sided
        like Mitsuba's other reflection models.  Sampled by the GGX visible normals with
        probability ``1 - (1 - m) / 2`` and the cosine hemisphere otherwise; ``pdf`` is the
        mixture's, so the weight is ``f cos / pdf`` for either choice.
        """

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.base = mi.Color3f(props["base_r"], props["base_g"], props["base_b"])
            self.metallic = mi.Float(props["metallic"])
            self.alpha = mi.Float(max(float(props["roughness"]) ** 2, 1e-4))
            self.diffuse_probability = mi.Float(0.5 * (1.0 - float(props["metallic"])))
            glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [glossy, diffuse]
            self.m_flags = glossy | diffuse

        def _distribution(self):
            return mi.MicrofacetDistribution(mi.MicrofacetType.GGX, self.alpha, True)

        def _value(self, wi, wo):
            """BSDF times the cosine at ``wo``, and the half vector."""
            cos_i, cos_o = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
            h = dr.normalize(wi + wo)
            a2 = dr.square(self.alpha)
            # GGX: a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2), the bracket written as
            # sin^2 + cos^2 a^2 from h's components: in float32, 1 - cos^2 near the peak of
            # roughness 0.1 (a^2 = 1e-4) would lose three digits of D
            sin2 = dr.square(h.x) + dr.square(h.y)
            d = a2 / (math.pi * dr.square(sin2 + dr.square(h.z) * a2))
            # height-correlated Smith: 0.5 / (n.l sqrt((n.v)^2 (1 - a^2) + a^2) + n.v sqrt(...))
            vis = 0.5 / (cos_o * dr.sqrt(dr.square(cos_i) * (1.0 - a2) + a2)
                         + cos_i * dr.sqrt(dr.square(cos_o) * (1.0 - a2) + a2))
            weight = dr.clip(1.0 - dr.abs(dr.dot(wi, h)), 0.0, 1.0)
            weight = dr.square(dr.square(weight)) * weight
            f_dielectric = 0.04 + 0.96 * weight
            f_metal = self.base + (1.0 - self.base) * weight
            specular = vis * d
            value = ((1.0 - self.metallic) * ((1.0 - f_dielectric) * self.base / math.pi + f_dielectric * specular)
                     + self.metallic * f_metal * specular)
            return value * cos_o, h

        def _pdf(self, wi, wo, h):
            distribution = self._distribution()
            glossy = distribution.pdf(wi, h) / (4.0 * dr.abs(dr.dot(wo, h)))
            diffuse = mi.warp.square_to_cosine_hemisphere_pdf(wo)
            return self.diffuse_probability * diffuse + (1.0 - self.diffuse_probability) * glossy

        def _active(self, wi, wo, active):
            return active & (mi.Frame3f.cos_theta(wi) > 0.0) & (mi.Frame3f.cos_theta(wo) > 0.0)

        def sample(self, ctx, si, sample1, sample2, active=True):
            wi = si.wi
            diffuse = sample1 < self.diffuse_probability
            m, _ = self._distribution().sample(wi, sample2)
            wo = dr.select(diffuse, mi.warp.square_to_cosine_hemisphere(sample2), mi.reflect(wi, m))
            active = self._active(wi, wo, active)
            value, h = self._value(wi, wo)
            pdf = self._pdf(wi, wo, h)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = wo
            bs.pdf = dr.select(active, pdf, 0.0)
            bs.eta = 1.0
            bs.sampled_component = dr.select(diffuse, mi.UInt32(1), mi.UInt32(0))
            bs.sampled_type = dr.select(diffuse, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                                        mi.UInt32(+mi.BSDFFlags.GlossyReflection))
            ok = active & (pdf > 0.0)
            return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

        def eval(self, ctx, si, wo, active=True):
            value, _ = self._value(si.wi, wo)
            return dr.select(self._active(si.wi, wo, active), value, 0.0)

        def pdf(self, ctx, si, wo, active=True):
            h = dr.normalize(si.wi + wo)
            return dr.select(self._active(si.wi, wo, active), self._pdf(si.wi, wo, h), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            value, h = self._value(si.wi, wo)
            active = self._active(si.wi, wo, active)
            return dr.select(active, value, 0.0), dr.select(active, self._pdf(si.wi, wo, h), 0.0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return "GltfBSDF[]"

    return GltfBSDF


def bsdf_dict(bsdf):
    """The Mitsuba BSDF of a job's ``bsdf`` entry (see the module docstring)."""
    model, base = bsdf["model"], bsdf.get("base_color")
    if model == "gltf":
        return {"type": "gltf_metallic_roughness", "base_r": base[0], "base_g": base[1], "base_b": base[2],
                "metallic": float(bsdf["metallic"]), "roughness": float(bsdf["roughness"])}
    if model == "principled":
        # specular 0.5 is eta 1.5 (F0 = 0.04); metallic 1 is Schlick with F0 = base colour;
        # GGX of alpha = roughness^2 (anisotropic 0); Smith G separable (not height-correlated)
        return {"type": "principled", "base_color": {"type": "rgb", "value": base},
                "metallic": float(bsdf["metallic"]), "roughness": float(bsdf["roughness"]), "specular": 0.5}
    if model == "roughplastic":
        return {"type": "roughplastic", "distribution": "ggx", "alpha": float(bsdf["roughness"]) ** 2,
                "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": False,
                "diffuse_reflectance": {"type": "rgb", "value": base}}
    if model == "diffuse":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": base}}
    if model == "mirror":
        return {"type": "conductor", "material": "none"}
    raise ValueError(f"unknown bsdf model {model!r}")


def emitter_dict(light):
    """The Mitsuba emitter of a job's ``light`` entry."""
    if light["type"] == "point":
        return {"type": "point", "position": light["position"],
                "intensity": {"type": "rgb", "value": light["intensity"]}}
    image = np.load(light["image"]).astype(np.float32)
    return {"type": "envmap", "bitmap": mi.Bitmap(image, mi.Bitmap.PixelFormat.RGB),
            "to_world": mi.ScalarTransform4f().rotate([0.0, 1.0, 0.0], light["rotate_y"])}


def scene_dict(job):
    """The Mitsuba scene of one job."""
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": job["max_depth"], "hide_emitters": False},
        "sensor": sensor_dict(job["camera"], job["width"], job["height"],
                              {"type": "stratified", "sample_count": job["spp"] // 2}),
        "light": emitter_dict(job["light"]),
    }
    if job.get("mesh"):
        scene["object"] = {"type": "ply", "filename": job["mesh"], "face_normals": False,
                           "bsdf": bsdf_dict(job["bsdf"])}
    return scene


def self_test(directions=4096, seed=7):
    """Check :class:`GltfBSDF` against Mitsuba's own code; print one line per check.

    1. Sampling: Mitsuba's chi-square test (``mitsuba.chi2``) of the sampled directions
       against ``pdf``, for metallic 0 and 1, roughness 0.1, 0.3, 0.7, at incidence 20, 45
       and 72 degrees, on a fine grid (at normal incidence, or on the default grid, the
       test cannot integrate the narrow lobe of roughness 0.1: Mitsuba's own
       ``roughconductor`` fails it there too).
    2. Weights: ``sample``'s weight equals ``eval / pdf`` of the sampled direction.
    3. D and F: at metallic 1 the ratio ``principled.eval / gltf.eval`` must be Smith's
       separable G over the height-correlated one, ``G1(wi) G1(wo) (1 + L(wi) + L(wo))``
       (``L`` Smith's Lambda of GGX), at random direction pairs, to 0.01 %: D, the Schlick
       Fresnel with F0 = base colour and the cosine factor then agree with Mitsuba's.

    Returns
    -------
    bool
        True when every check passes.
    """
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    ok = True
    rng = np.random.default_rng(seed)
    base = [0.8, 0.3, 0.2]
    for metallic in (0.0, 1.0):
        for roughness in (0.1, 0.3, 0.7):
            spec = bsdf_dict({"model": "gltf", "base_color": base, "metallic": metallic, "roughness": roughness})
            for angle in (20.0, 45.0, 72.0):
                wi = [math.sin(math.radians(angle)), 0.0, math.cos(math.radians(angle))]
                sample_func, pdf_func = BSDFAdapter(spec["type"], spec, wi=wi)
                # a fine grid: the default one integrates the pdf of roughness 0.1 (alpha 0.01)
                # too coarsely (Mitsuba's own roughconductor fails there as well)
                test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                                     sample_dim=3, res=201, ires=12)
                # 18 tests together at the 1 % level (Sidak's correction, done by run())
                passed = bool(test.run(significance_level=0.01, test_count=18, quiet=True))
                ok &= passed
                print(f"chi2 metallic {metallic:g} roughness {roughness:g} incidence {angle:g}: "
                      f"{'pass' if passed else 'FAIL'}", flush=True)
            # weights against eval / pdf at sampled directions
            bsdf = mi.load_dict(spec)
            si = dr.zeros(mi.SurfaceInteraction3f, directions)
            wi = rng.normal(size=(directions, 3))
            wi[:, 2] = np.abs(wi[:, 2])
            wi /= np.linalg.norm(wi, axis=1, keepdims=True)
            si.wi = mi.Vector3f(wi.T.astype(np.float32))
            ctx = mi.BSDFContext()
            bs, weight = bsdf.sample(ctx, si, mi.Float(rng.random(directions).astype(np.float32)),
                                     mi.Point2f(rng.random((2, directions)).astype(np.float32)))
            value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
            weight, value, pdf = np.array(weight), np.array(value), np.array(pdf)
            good = pdf > 1e-3
            expected = value[:, good] / pdf[good]
            error = float(np.max(np.abs(weight[:, good] - expected) / np.maximum(np.abs(expected), 1e-3)))
            passed = error < 1e-3
            ok &= passed
            print(f"weight = eval / pdf, metallic {metallic:g} roughness {roughness:g}: largest relative "
                  f"error {error:.1e} {'pass' if passed else 'FAIL'}", flush=True)
    for roughness in (0.1, 0.3, 0.7):
        values = {}
        wi = rng.normal(size=(directions, 3))
        wo = rng.normal(size=(directions, 3))
        wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        wo /= np.linalg.norm(wo, axis=1, keepdims=True)
        for model in ("gltf", "principled"):
            bsdf = mi.load_dict(bsdf_dict({"model": model, "base_color": base, "metallic": 1.0,
                                           "roughness": roughness}))
            si = dr.zeros(mi.SurfaceInteraction3f, directions)
            si.wi = mi.Vector3f(wi.T.astype(np.float32))
            values[model] = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo.T.astype(np.float32))))
        alpha2 = roughness ** 4

        def smith_lambda(v):
            tan2 = (1.0 - v[:, 2] ** 2) / v[:, 2] ** 2
            return 0.5 * (np.sqrt(1.0 + alpha2 * tan2) - 1.0)

        separable = 1.0 / ((1.0 + smith_lambda(wi)) * (1.0 + smith_lambda(wo)))
        correlated = 1.0 / (1.0 + smith_lambda(wi) + smith_lambda(wo))
        good = (values["gltf"] > 1e-4).all(axis=0)
        ratio = values["principled"][:, good] / values["gltf"][:, good]
        error = float(np.max(np.abs(ratio - (separable / correlated)[good])))
        passed = error < 1e-4
        ok &= passed
        print(f"principled / gltf at metallic 1, roughness {roughness:g} = separable G / correlated G: "
              f"largest error {error:.1e} over {int(good.sum())} pairs {'pass' if passed else 'FAIL'}", flush=True)
    return ok


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("jobs", nargs="?", help="JSON list of jobs (see the module docstring)")
    parser.add_argument("variant", nargs="?", default="llvm_ad_rgb", help="llvm_ad_rgb or scalar_rgb")
    parser.add_argument("--self-test", action="store_true",
                        help="check the glTF BSDF against Mitsuba's chi-square test and its principled BSDF")
    args = parser.parse_args()

    mi.set_variant(args.variant)
    gltf_bsdf = gltf_bsdf_class()
    mi.register_bsdf("gltf_metallic_roughness", lambda props: gltf_bsdf(props))
    if args.self_test:
        raise SystemExit(0 if self_test() else 1)
    if not args.jobs:
        parser.error("JOBS.json is required (or --self-test)")
    with open(args.jobs) as f:
        jobs = json.load(f)
    for job in jobs:
        scene = mi.load_dict(scene_dict(job))
        half = job["spp"] // 2
        start = time.perf_counter()
        halves = [np.array(mi.render(scene, spp=half, seed=seed), dtype=np.float32)[:, :, :3] for seed in (0, 1)]
        seconds = time.perf_counter() - start
        np.savez(job["out"], half0=halves[0], half1=halves[1], seconds=np.array(seconds),
                 version=np.array(mi.__version__), variant=np.array(args.variant))
        print(f"mitsuba {args.variant} {job['name']}: {2 * half} spp, {seconds:.1f} s", flush=True)


if __name__ == "__main__":
    main()
