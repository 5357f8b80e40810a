"""Rays/s and samples/s of the real assets, rendered as a new user renders them: the command line.

The four glTF assets of ``../shared/assets/real`` (Duck, CesiumMilkTruck, monkey (Suzanne),
AlphaBlendModeTest) are rendered with ``rtmesh render ASSET -o OUT.png --width 320 --height
240 --spp 16 --background rtmesh/scene/studio.exr --threads 2``, each render in a fresh
process (``python -m rtmesh.cli`` from the source tree measured, so it imports that tree's
rtmesh), after one warm-up render per asset (it fills numba's disk cache: compile time is
``bench_first_run``'s subject, not this one's); the assets alternate run by run, so a
shared machine's load falls on all of them alike.

Each render's own summary line gives its rays and render seconds (``M rays (M rays/s), s``:
the rays as the render counts them, the time without start-up, loading or writing); the
table reports per asset the medians over ``--runs`` runs of the rays/s, of the samples/s
(pixels x spp / render seconds) and of the whole process's wall time.

``--integrator NAME`` is passed on as ``--integrator NAME`` when the measured rtmesh's
``render`` command has that option; a tree without it renders with its only integrator and
the report says so.  ``--tree PATH`` (repeatable) measures other source trees (e.g. a
worktree of an older commit) in the same run, alternating with this one.

Usage, from the repository root::

    python -m benchmarks.bench_real_assets [--runs 5] [--integrator path] [--tree ../old] [--no-write]
"""

import argparse
import datetime
import functools
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._lib import ROOT, machine, publish, rtmesh_commit

SECTION = "Real assets: rays/s and samples/s"
ASSETS = ("Duck.glb", "CesiumMilkTruck.glb", "monkey.glb", "AlphaBlendModeTest.glb")
DEFAULT_FOLDER = ROOT.parent / "shared" / "assets" / "real"
if not DEFAULT_FOLDER.exists():
    DEFAULT_FOLDER = Path("/work/shared/assets/real")
STUDIO = ROOT / "rtmesh" / "scene" / "studio.exr"
SUMMARY = re.compile(r"(?P<spp>\d+) spp, (?P<rays>[\d.]+) M rays \((?P<rate>[\d.]+) M rays/s\), "
                     r"(?P<seconds>[\d.]+) s, (?P<threads>\d+) threads")


@functools.lru_cache(maxsize=None)
def render_help(tree):
    """The help text of ``rtmesh render`` of the source tree ``tree`` ('' if it fails)."""
    done = subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", "--help"], cwd=tree,
                          env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True, text=True)
    return done.stdout if done.returncode == 0 else ""


def has_option(tree, option):
    """Whether ``rtmesh render`` of the source tree ``tree`` takes ``option``."""
    return re.search(rf"(^|\s){re.escape(option)}\b", render_help(Path(tree))) is not None


def render_command(asset, output, args, integrator):
    """The ``rtmesh render`` arguments of one render (``integrator`` None: not passed)."""
    command = [sys.executable, "-m", "rtmesh.cli", "render", str(asset), "-o", str(output),
               "--width", str(args.width), "--height", str(args.height), "--spp", str(args.spp),
               "--background", str(STUDIO), "--threads", str(args.threads), "-q"]
    if integrator is not None:
        command += ["--integrator", integrator]
    return command


def parse_summary(text):
    """The numbers of a render's summary line.

    Parameters
    ----------
    text : str
        The command's standard output.

    Returns
    -------
    dict
        ``spp`` (int), ``rays`` (millions), ``rate`` (millions of rays a second),
        ``seconds`` (the render's), ``threads`` (int).

    Raises
    ------
    ValueError
        If no line has the summary's form.
    """
    match = SUMMARY.search(text)
    if match is None:
        raise ValueError(f"no render summary in {text!r}")
    values = match.groupdict()
    return {"spp": int(values["spp"]), "rays": float(values["rays"]), "rate": float(values["rate"]),
            "seconds": float(values["seconds"]), "threads": int(values["threads"])}


def render_once(tree, asset, output, args, integrator):
    """Render once in a fresh process from ``tree``; the summary's numbers and the wall time."""
    start = time.perf_counter()
    done = subprocess.run(render_command(asset, output, args, integrator), cwd=tree,
                          env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"bench_real_assets: {asset.name} failed in {tree}: {done.stderr.strip()}")
    return dict(parse_summary(done.stdout), wall=wall)


def medians(runs, pixels):
    """Medians over runs of rays/s, samples/s, render and process seconds; rays per sample."""
    samples = [pixels * r["spp"] for r in runs]
    return {"rays_per_second": statistics.median(r["rate"] * 1e6 for r in runs),
            "samples_per_second": statistics.median(s / r["seconds"] for s, r in zip(samples, runs)),
            "seconds": statistics.median(r["seconds"] for r in runs),
            "wall": statistics.median(r["wall"] for r in runs),
            "rays_per_sample": statistics.median(r["rays"] * 1e6 / s for s, r in zip(samples, runs))}


def command_line(args):
    """The command that reproduces this run (options off their defaults only)."""
    words = ["python -m benchmarks.bench_real_assets"]
    for name, default in (("runs", 5), ("width", 320), ("height", 240), ("spp", 16), ("threads", 2)):
        if getattr(args, name) != default:
            words.append(f"--{name} {getattr(args, name)}")
    if args.integrator:
        words.append(f"--integrator {args.integrator}")
    words += [f"--tree {tree}" for tree in args.tree]
    return " ".join(words)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="timed renders per asset and tree")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--integrator", help="passed on as --integrator where the command has it")
    parser.add_argument("--assets", type=Path, default=DEFAULT_FOLDER, help="folder of the four assets")
    parser.add_argument("--tree", action="append", default=[], help="another source tree to measure too")
    parser.add_argument("--no-write", action="store_true", help="print only; leave docs/BENCHMARKS.md alone")
    args = parser.parse_args(argv)
    assets = [args.assets / name for name in ASSETS]
    missing = [str(a) for a in assets if not a.exists()]
    if missing:
        parser.error("missing assets: " + ", ".join(missing))
    trees = {"this": ROOT, **{str(t): Path(t).resolve() for t in args.tree}}
    trees = {f"{name} ({rtmesh_commit(tree / 'rtmesh')})": tree for name, tree in trees.items()}
    integrators, notes = {}, []
    for name, tree in trees.items():
        supported = args.integrator is not None and has_option(tree, "--integrator")
        integrators[name] = args.integrator if supported else None
        if args.integrator is not None and not supported:
            notes.append(f"{name} has no `--integrator`: rendered with its only integrator")
            print(f"bench_real_assets: {notes[-1]}", flush=True)
    at_start = machine()
    runs = {(name, asset.name): [] for name in trees for asset in assets}
    with tempfile.TemporaryDirectory(prefix="rtmesh-real-") as folder:
        output = Path(folder) / "out.png"
        for name, tree in trees.items():  # warm-up: numba's disk cache, the page cache
            for asset in assets:
                render_once(tree, asset, output, args, integrators[name])
        for run in range(args.runs):
            for asset in assets:
                for name, tree in trees.items():
                    result = render_once(tree, asset, output, args, integrators[name])
                    runs[(name, asset.name)].append(result)
                    print(f"run {run + 1} {name} {asset.name}: {result['rate']:.2f} M rays/s, "
                          f"{result['seconds']:.2f} s render, {result['wall']:.2f} s process", flush=True)
    pixels = args.width * args.height
    rows = []
    for (name, asset), results in runs.items():
        m = medians(results, pixels)
        rows.append(f"| {asset} | {name} | {m['rays_per_second'] / 1e6:.2f} | {m['samples_per_second'] / 1e6:.3f} "
                    f"| {m['rays_per_sample']:.1f} | {m['seconds']:.2f} | {m['wall']:.2f} |")
    text = "\n".join([
        f"## {SECTION}",
        "",
        f"Command: `{command_line(args)}`",
        "",
        f"- {datetime.date.today().isoformat()}; {at_start}, {os.getloadavg()[0]:.1f} at the end",
        f"- Each asset rendered by `rtmesh render` at {args.width}x{args.height}, {args.spp} spp, the studio "
        f"environment (`--background rtmesh/scene/studio.exr`), {args.threads} threads, each render a fresh "
        f"process after one warm-up per asset; medians of {args.runs} runs, the assets alternating",
        f"- Integrator: {args.integrator or 'the file default'}" + ("; " + "; ".join(notes) if notes else ""),
        "- M rays/s as the render's summary line counts them; samples/s = pixels x spp / render seconds; "
        "render s from the summary line (no start-up, loading or writing); process s: the whole command",
        "",
        "| asset | tree (rtmesh/ at) | M rays/s | M samples/s | rays a sample | render s | process s |",
        "|---|---|---:|---:|---:|---:|---:|",
        *rows,
        "",
    ])
    publish(text, SECTION, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
