"""Blue noise: the zsobol sampler's error against sobol's (and random's) on the soft-shadow scene.

For each spp, sampler and seed, ``assets/effects/soft_shadow.toml`` is rendered with one
light sample a hit (``light_samples = 1``) and compared with a reference (the same scene at
high spp with four light samples, rendered once and kept in ``--cache``):

- relative RMSE (:func:`benchmarks._lib.relative_rmse`: RMSE over pixels and channels / the
  reference's mean), raw and after a Gaussian blur of 1 pixel applied to both images
  (:func:`benchmarks._lib.gaussian_blur`);
- the radially averaged power spectrum of the error's channel mean
  (:func:`benchmarks._lib.radial_power_spectrum`) and its top-third / bottom-third ratio
  (:func:`benchmarks._lib.blue_noise_ratio`: 1 for white noise);
- the render time (median over the seeds).

Errors are pooled over the seeds (root of the mean of the squared errors), spectra averaged.
Every figure is also given "without emitters": without the pixels whose reference is
brighter than 1.5 (:func:`emitter_mask`: the lights seen directly and the floor touching the
glowing ball, whose 1/r^2 fireflies dominate any RMSE of the whole image at low spp, so much
that random's can come out below sobol's), and "far from emitters": without the pixels
within 2 pixels of those too (:func:`far_mask`: the antialiased edges of the lights seen
directly, whose partly covered pixels pass the 1.5 of the first mask).

``--lights quad`` or ``--lights mesh`` render the scene lit by its quad light alone (the
glowing ball's emission set to 0; the ball stays as a black occluder) or by the emissive
ball alone (the quad light removed), each against its own reference: which light's
estimator holds the error that does not turn blue (docs/SAMPLERS.md).  The figures (error images side by side, spectra)
are written to ``docs/`` for docs/SAMPLERS.md.

Run from the repository root::

    python -m benchmarks.bench_zsobol                      # 480x360, 8 seeds
    python -m benchmarks.bench_zsobol --width 160 --height 120 --seeds 4 --no-figures
    python -m benchmarks.bench_zsobol --lights quad --no-figures
    python -m benchmarks.bench_zsobol --fixed-point      # each light's estimator at one point

``--fixed-point`` measures each area light's estimator alone, the same integrand in every
pixel (:func:`fixed_point_errors`): what the sampler makes of the light's sample mapping
when neighbouring pixels integrate exactly the same function.
"""

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from benchmarks import _lib
from rtmesh.rendering.settings import INTEGRATORS, LIGHT_SAMPLERS

SCENE = _lib.ROOT / "assets" / "effects" / "soft_shadow.toml"
SAMPLERS = ("random", "sobol", "zsobol")
LIGHTS = ("all", "quad", "mesh")
# pixels this close to an emitter pixel (in pixels) are left out "far from emitters"
EMITTER_MARGIN = 2


def render(width, height, spp, sampler, seed, light_samples, threads, lights="all", overrides=None):
    """One linear image of the scene, (h, w, 3) float64, and its render seconds.

    ``lights``: ``"all"`` (the scene as it is), ``"quad"`` (no emissive material) or
    ``"mesh"`` (no quad light), see the module notes.  ``overrides``: more render settings
    (``integrator``, ``light_sampler``).
    """
    from rtmesh import api
    from rtmesh.materials.table import MaterialTable

    start = time.perf_counter()
    scene, settings = api.load_scene(str(SCENE), width=width, height=height, spp=spp, sampler=sampler, seed=seed,
                                     light_samples=light_samples, threads=threads, **(overrides or {}))
    if lights == "quad":
        scene.materials = MaterialTable([dataclasses.replace(m, emission=np.zeros(3))
                                         for m in scene.materials.materials])
    elif lights == "mesh":
        scene.lights = []
    image = api.render(scene, settings).image
    return np.asarray(image, np.float64), time.perf_counter() - start


def reference(width, height, spp, threads, cache, lights="all", overrides=None):
    """The reference image (``spp`` x 4 light samples, jittered), rendered once per size,
    lights and settings and kept in the folder ``cache``."""
    variant = ("" if lights == "all" else f"_{lights}") + "".join(f"_{v}" for v in (overrides or {}).values())
    path = Path(cache) / f"soft_shadow{variant}_{width}x{height}_{spp}spp.npy"
    if path.exists():
        return np.load(path)
    image, took = render(width, height, spp, "jittered", 12345, 4, threads, lights, overrides)
    print(f"reference: {spp} spp x 4 light samples in {took:.0f} s")
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, image)
    return image


def emitter_mask(ref):
    """(h, w) bool: the pixels compared "without emitters", whose reference is at most 1.5
    (leaving out the lights seen directly and the floor touching the glowing ball)."""
    return ref.mean(axis=2) <= 1.5


# floor points (world space, the floor's normal +y) where fixed_point_errors evaluates each
# area light's estimator: beside the quad light's penumbrae, and beside the glowing ball
FIXED_POINTS = {"quad": (0, (-1.0, 0.0, 2.0)), "mesh": (1, (1.9, 0.0, 1.9))}


def fixed_point_errors(spps, seeds=4, size=128, points=FIXED_POINTS):
    """zsobol against sobol where every pixel integrates the same function: one area light's
    one-sample estimator ``f cos_s cos_l L / (d^2 pdf_A)`` (diffuse ``f``, channel mean) at
    one floor point, unoccluded, on a ``size`` x ``size`` image.

    The glowing ball hides its own far side from the floor (it is convex): its faces count
    only where they face the point (``cos_l > 0``), as the shadow rays of a render find.

    Returns
    -------
    list of dict
        ``light``, ``spp``, ``raw`` and ``blurred`` (zsobol's RMSE over sobol's, pooled over
        the seeds, blurred with σ = 1 pixel), ``blue`` and ``blue_sobol``
        (:func:`benchmarks._lib.blue_noise_ratio` of each one's mean spectrum).
    """
    from rtmesh import api
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.sampling.sampler import light_dimension
    from rtmesh.sampling.patterns import decorrelated_points

    scene, settings = api.load_scene(str(SCENE), width=size, height=size, light_samples=1)
    it = Integrator(scene, settings)
    lights = it.area_lighting.lights
    rows = []
    for name, (index, point) in points.items():
        light = lights[index]
        for spp in spps:
            pixel = np.repeat(np.arange(size * size), spp)
            sample = np.tile(np.arange(spp), size * size)
            p = np.tile(np.asarray(point, np.float64) - it.shift, (len(pixel), 1))
            errors = {}
            for sampler in ("sobol", "zsobol"):
                images = []
                for seed in range(seeds):
                    u = decorrelated_points(sampler, seed, pixel, sample, spp, light_dimension(0, index, len(lights)),
                                            resolution=(size, size))
                    y, normal, radiance, inverse_pdf = light.sample(u, p)
                    to_light = y - p
                    d2 = np.einsum("ij,ij->i", to_light, to_light)
                    w = to_light / np.sqrt(d2)[:, None]
                    cos_l = np.maximum(-np.einsum("ij,ij->i", w, np.broadcast_to(normal, w.shape)), 0.0)
                    value = (np.maximum(w[:, 1], 0.0) * cos_l / d2 * inverse_pdf
                             * np.mean(radiance, axis=-1) / np.pi)
                    images.append(value.reshape(-1, spp).mean(axis=1).reshape(size, size))
                errors[sampler] = np.array(images)
            # the exact integral is unknown: the mean over both samplers' 2 x seeds x size^2
            # pixel estimates stands for it (its own error is 1/(2 seeds size^2) of a pixel's)
            truth = np.mean([errors["sobol"].mean(), errors["zsobol"].mean()])

            def rmse(e, blur=False):
                return np.sqrt(np.mean([np.mean(((_lib.gaussian_blur(x) if blur else x) - truth) ** 2) for x in e]))

            def blue(e):
                return _lib.blue_noise_ratio(np.mean([_lib.radial_power_spectrum(x - truth)[1] for x in e], axis=0))

            z, s = errors["zsobol"], errors["sobol"]
            rows.append(dict(light=name, spp=spp, raw=rmse(z) / rmse(s), blurred=rmse(z, True) / rmse(s, True),
                             blue=blue(z), blue_sobol=blue(s)))
    return rows


def far_mask(ref):
    """(h, w) bool: the pixels compared "far from emitters": at least
    :data:`EMITTER_MARGIN` pixels (in x and in y) from any pixel :func:`emitter_mask` leaves
    out, so that the antialiased edges of the lights seen directly (partly covered pixels,
    whose reference may stay below 1.5) are left out too."""
    r = EMITTER_MARGIN
    bright = np.pad(~emitter_mask(ref), r)
    windows = np.lib.stride_tricks.sliding_window_view(bright, (2 * r + 1, 2 * r + 1))
    return ~windows.any(axis=(2, 3))


def measure(ref, spps, seeds, threads=1, samplers=SAMPLERS, log=print, lights="all", overrides=None):
    """Errors, spectra and times of every (spp, sampler), and seed 0's error images.

    Returns
    -------
    rows : list of dict
        ``spp``, ``sampler``, ``raw``, ``blurred`` (relative RMSE of the image, pooled over
        the seeds), ``raw_masked``, ``blurred_masked`` (over :func:`emitter_mask`),
        ``raw_far``, ``blurred_far`` (over :func:`far_mask`), ``blue``, ``blue_masked``,
        ``blue_far`` (:func:`benchmarks._lib.blue_noise_ratio` of the mean spectrum of the
        error, and of the error with the masked-out pixels set to 0), ``seconds`` (median
        render time).
    spectra : dict
        ``(spp, sampler)``: (frequency, power) of the masked error.
    examples : dict
        ``(spp, sampler)``: seed 0's error (channel mean), (h, w).
    """
    height, width = ref.shape[:2]
    masks = {"": np.ones((height, width), bool), "_masked": emitter_mask(ref), "_far": far_mask(ref)}
    blurred_ref = _lib.gaussian_blur(ref)
    rows, spectra, examples = [], {}, {}
    for spp in spps:
        for sampler in samplers:
            sq = {name: np.zeros(2) for name in masks}
            power = {name: 0.0 for name in masks}
            times = []
            for seed in range(seeds):
                image, took = render(width, height, spp, sampler, seed, 1, threads, lights, overrides)
                times.append(took)
                error = image - ref
                blurred = _lib.gaussian_blur(image) - blurred_ref
                for name, mask in masks.items():
                    sq[name] += [np.mean(error[mask] ** 2), np.mean(blurred[mask] ** 2)]
                    frequency, p = _lib.radial_power_spectrum(np.where(mask, error.mean(axis=2), 0.0))
                    power[name] = power[name] + p / seeds
                if seed == 0:
                    examples[spp, sampler] = np.where(masks["_masked"], error.mean(axis=2), 0.0)
            row = dict(spp=spp, sampler=sampler, seconds=float(np.median(times)))
            for name, mask in masks.items():
                raw, blurred = np.sqrt(sq[name] / seeds) / ref[mask].mean()
                row.update({"raw" + name: raw, "blurred" + name: blurred,
                            "blue" + name: _lib.blue_noise_ratio(power[name])})
            rows.append(row)
            spectra[spp, sampler] = (frequency, power["_masked"])
            r = rows[-1]
            log(f"{spp:3d} spp {sampler:8s} raw {r['raw']:.4f} blurred {r['blurred']:.4f} "
                f"(masked {r['raw_masked']:.4f} / {r['blurred_masked']:.4f}, far {r['raw_far']:.4f} / "
                f"{r['blurred_far']:.4f}) blue {r['blue']:.2f} (masked {r['blue_masked']:.2f}, far "
                f"{r['blue_far']:.2f}) median {r['seconds']:.2f} s")
    return rows, spectra, examples


def table(rows, args):
    """The markdown tables of the measurements: per sampler, and zsobol / sobol ratios with
    zsobol's spectrum ratio, over the image, without emitters and far from emitters."""
    by = {(r["spp"], r["sampler"]): r for r in rows}
    regions = (("", "image"), ("_masked", "without emitters"), ("_far", "far from emitters"))
    lines = ["| spp | sampler | " + " | ".join(f"{label}: raw / blurred (σ = 1 px) / spectrum"
                                             for _, label in regions) + " | median time (s) |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        cells = [f"{r['raw' + k]:.4f} / {r['blurred' + k]:.4f} / {r['blue' + k]:.2f}" for k, _ in regions]
        lines.append(f"| {r['spp']} | {r['sampler']} | " + " | ".join(cells) + f" | {r['seconds']:.2f} |")
    lines += ["", "| spp | " + " | ".join(f"{label}: zsobol / sobol raw, blurred; zsobol's spectrum"
                                        for _, label in regions) + " |", "|---|---|---|---|"]
    for spp in args.spp:
        z, s = by[spp, "zsobol"], by[spp, "sobol"]
        cells = [f"{z['raw' + k] / s['raw' + k]:.2f}, {z['blurred' + k] / s['blurred' + k]:.2f}; {z['blue' + k]:.2f}"
                 for k, _ in regions]
        lines.append(f"| {spp} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def save_small(fig, path):
    """Save a figure as a PNG of 64 palette colours (a quarter of the bytes: the error maps
    compress poorly)."""
    fig.savefig(path, dpi=90)
    palette(path)


def palette(path):
    """Rewrite the PNG at ``path`` with an adaptive palette of 64 colours."""
    from PIL import Image

    with Image.open(path) as image:
        small = image.convert("RGB").convert("P", palette=Image.ADAPTIVE, colors=64)
    small.save(path, optimize=True)


def figures(spectra, examples, args):
    """docs/samplers_error.png (seed 0's error without emitters at the middle spp in the
    lower left quarter of the image, raw and blurred (colour scale 3x finer), per sampler)
    and docs/samplers_spectra.png (the averaged spectra of the error without emitters)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spp = args.spp[len(args.spp) // 2]
    # the floor's penumbrae (left half, lower half of the image), where the light samples
    # decide the error
    h, w = examples[spp, "sobol"].shape
    crop = (slice(h // 2, h), slice(0, w // 2))
    scale = 2.5 * np.std(examples[spp, "sobol"][crop])
    fig, axes = plt.subplots(2, len(SAMPLERS), figsize=(4 * len(SAMPLERS), 6.4))
    for column, sampler in enumerate(SAMPLERS):
        error = examples[spp, sampler]
        for row, (panel, label) in enumerate(((error, "error"), (_lib.gaussian_blur(error), "blurred error"))):
            axes[row, column].imshow(panel[crop], cmap="RdBu", vmin=-scale / (1 + 2 * row),
                                     vmax=scale / (1 + 2 * row), interpolation="nearest")
            axes[row, column].set_title(f"{sampler}, {spp} spp: {label}")
            axes[row, column].axis("off")
    fig.tight_layout()
    save_small(fig, args.figures / "samplers_error.png")
    plt.close(fig)
    fig, axes = plt.subplots(1, len(args.spp), figsize=(4.2 * len(args.spp), 3.4), sharey=True)
    for ax, spp in zip(np.atleast_1d(axes), args.spp):
        for sampler in SAMPLERS:
            frequency, power = spectra[spp, sampler]
            ax.semilogy(frequency[1:], power[1:], label=sampler)
        ax.set_title(f"{spp} spp (without emitters)")
        ax.set_xlabel("frequency (cycles / pixel)")
    np.atleast_1d(axes)[0].set_ylabel("error power")
    np.atleast_1d(axes)[0].legend()
    fig.tight_layout()
    save_small(fig, args.figures / "samplers_spectra.png")
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--spp", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--ref-spp", type=int, default=256)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--cache", default=str(_lib.ROOT / "out" / "bench_zsobol"))
    parser.add_argument("--lights", choices=LIGHTS, default="all",
                        help="the scene's lights (quad or mesh: one alone, against its own reference)")
    parser.add_argument("--no-figures", action="store_true", help="(figures are written for --lights all only)")
    parser.add_argument("--integrator", choices=INTEGRATORS, help="(default: the scene's, whitted)")
    parser.add_argument("--light-sampler", choices=LIGHT_SAMPLERS, help="path: how light samples choose a light")
    parser.add_argument("--fixed-point", action="store_true",
                        help="only each area light's estimator at one point, the same in every pixel")
    args = parser.parse_args(argv)
    args.figures = _lib.ROOT / "docs"
    print(_lib.machine())
    if args.fixed_point:
        print("| light | spp | zsobol / sobol: raw | blurred | spectrum: zsobol, sobol |\n|---|---|---|---|---|")
        for r in fixed_point_errors(args.spp):
            print(f"| {r['light']} | {r['spp']} | {r['raw']:.2f} | {r['blurred']:.2f} | "
                  f"{r['blue']:.2f}, {r['blue_sobol']:.2f} |")
        return
    overrides = {k: v for k, v in (("integrator", args.integrator), ("light_sampler", args.light_sampler)) if v}
    ref = reference(args.width, args.height, args.ref_spp, args.threads, args.cache, args.lights, overrides)
    rows, spectra, examples = measure(ref, args.spp, args.seeds, args.threads,
                                      log=lambda line: print(line, flush=True), lights=args.lights,
                                      overrides=overrides)
    print()
    print(table(rows, args))
    if not args.no_figures and args.lights == "all" and not overrides:
        figures(spectra, examples, args)
        print(f"figures written to {args.figures}/samplers_error.png and samplers_spectra.png")


if __name__ == "__main__":
    main()
