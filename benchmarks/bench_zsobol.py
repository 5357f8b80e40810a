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
that random's can come out below sobol's).  The figures (error images side by side, spectra)
are written to ``docs/`` for docs/SAMPLERS.md.

Run from the repository root::

    python -m benchmarks.bench_zsobol                      # 480x360, 8 seeds
    python -m benchmarks.bench_zsobol --width 160 --height 120 --seeds 4 --no-figures
"""

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks import _lib

SCENE = _lib.ROOT / "assets" / "effects" / "soft_shadow.toml"
SAMPLERS = ("random", "sobol", "zsobol")


def render(width, height, spp, sampler, seed, light_samples, threads):
    """One linear image of the scene, (h, w, 3) float64, and its render seconds."""
    from rtmesh import api

    start = time.perf_counter()
    image = api.render(str(SCENE), width=width, height=height, spp=spp, sampler=sampler, seed=seed,
                       light_samples=light_samples, threads=threads).image
    return np.asarray(image, np.float64), time.perf_counter() - start


def reference(width, height, spp, threads, cache):
    """The reference image (``spp`` x 4 light samples, jittered), rendered once per size and
    kept in the folder ``cache``."""
    path = Path(cache) / f"soft_shadow_{width}x{height}_{spp}spp.npy"
    if path.exists():
        return np.load(path)
    image, took = render(width, height, spp, "jittered", 12345, 4, threads)
    print(f"reference: {spp} spp x 4 light samples in {took:.0f} s")
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, image)
    return image


def emitter_mask(ref):
    """(h, w) bool: the pixels compared "without emitters", whose reference is at most 1.5
    (leaving out the lights seen directly and the floor touching the glowing ball)."""
    return ref.mean(axis=2) <= 1.5


def measure(ref, spps, seeds, threads=1, samplers=SAMPLERS, log=print):
    """Errors, spectra and times of every (spp, sampler), and seed 0's error images.

    Returns
    -------
    rows : list of dict
        ``spp``, ``sampler``, ``raw``, ``blurred`` (relative RMSE of the image, pooled over
        the seeds), ``raw_masked``, ``blurred_masked`` (over :func:`emitter_mask`),
        ``blue``, ``blue_masked`` (:func:`benchmarks._lib.blue_noise_ratio` of the mean
        spectrum of the error, and of the error with the masked-out pixels set to 0),
        ``seconds`` (median render time).
    spectra : dict
        ``(spp, sampler)``: (frequency, power) of the masked error.
    examples : dict
        ``(spp, sampler)``: seed 0's error (channel mean), (h, w).
    """
    height, width = ref.shape[:2]
    mask = emitter_mask(ref)
    blurred_ref = _lib.gaussian_blur(ref)
    rows, spectra, examples = [], {}, {}
    for spp in spps:
        for sampler in samplers:
            sq = np.zeros(4)
            power, power_masked, times = 0.0, 0.0, []
            for seed in range(seeds):
                image, took = render(width, height, spp, sampler, seed, 1, threads)
                times.append(took)
                error = image - ref
                blurred = _lib.gaussian_blur(image) - blurred_ref
                sq += [np.mean(error ** 2), np.mean(blurred ** 2), np.mean(error[mask] ** 2),
                       np.mean(blurred[mask] ** 2)]
                power = power + _lib.radial_power_spectrum(error.mean(axis=2))[1] / seeds
                frequency, p = _lib.radial_power_spectrum(np.where(mask, error.mean(axis=2), 0.0))
                power_masked = power_masked + p / seeds
                if seed == 0:
                    examples[spp, sampler] = np.where(mask, error.mean(axis=2), 0.0)
            rmse = np.sqrt(sq / seeds)
            rows.append(dict(spp=spp, sampler=sampler, raw=rmse[0] / ref.mean(), blurred=rmse[1] / ref.mean(),
                             raw_masked=rmse[2] / ref[mask].mean(), blurred_masked=rmse[3] / ref[mask].mean(),
                             blue=_lib.blue_noise_ratio(power), blue_masked=_lib.blue_noise_ratio(power_masked),
                             seconds=float(np.median(times))))
            spectra[spp, sampler] = (frequency, power_masked)
            r = rows[-1]
            log(f"{spp:3d} spp {sampler:8s} raw {r['raw']:.4f} blurred {r['blurred']:.4f} "
                f"(masked {r['raw_masked']:.4f} / {r['blurred_masked']:.4f}) blue {r['blue']:.2f} "
                f"(masked {r['blue_masked']:.2f}) median {r['seconds']:.2f} s")
    return rows, spectra, examples


def table(rows, args):
    """The markdown table of the measurements, with zsobol / sobol ratios."""
    by = {(r["spp"], r["sampler"]): r for r in rows}
    lines = ["| spp | sampler | rel. RMSE | blurred (σ = 1 px) | without emitters: raw / blurred | "
             "spectrum top/bottom third: image / without emitters | median time (s) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['spp']} | {r['sampler']} | {r['raw']:.4f} | {r['blurred']:.4f} | "
                     f"{r['raw_masked']:.4f} / {r['blurred_masked']:.4f} | {r['blue']:.2f} / {r['blue_masked']:.2f} | "
                     f"{r['seconds']:.2f} |")
    lines += ["", "| spp | zsobol / sobol: raw | blurred | without emitters: raw | blurred |", "|---|---|---|---|---|"]
    for spp in args.spp:
        z, s = by[spp, "zsobol"], by[spp, "sobol"]
        lines.append(f"| {spp} | {z['raw'] / s['raw']:.3f} | {z['blurred'] / s['blurred']:.3f} | "
                     f"{z['raw_masked'] / s['raw_masked']:.3f} | {z['blurred_masked'] / s['blurred_masked']:.3f} |")
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
    parser.add_argument("--no-figures", action="store_true")
    args = parser.parse_args(argv)
    args.figures = _lib.ROOT / "docs"
    print(_lib.machine())
    ref = reference(args.width, args.height, args.ref_spp, args.threads, args.cache)
    rows, spectra, examples = measure(ref, args.spp, args.seeds, args.threads,
                                      log=lambda line: print(line, flush=True))
    print()
    print(table(rows, args))
    if not args.no_figures:
        figures(spectra, examples, args)
        print(f"figures written to {args.figures}/samplers_error.png and samplers_spectra.png")


if __name__ == "__main__":
    main()
