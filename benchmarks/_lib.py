"""What the benchmarks share: one error measure, one scene builder, one peer runner, publishing.

- :func:`relative_rmse` is the one error measure of every benchmark and of the tests that
  compare images with references: the RMSE over pixels and channels (optionally of block
  means, optionally over a mask) divided by the reference's mean; :func:`gaussian_blur`,
  :func:`radial_power_spectrum` and :func:`blue_noise_ratio` say how the error is spread
  over screen-space frequencies (the samplers' comparison, docs/SAMPLERS.md).
- :func:`sphere_meshes` and :func:`sphere_scene` build the benchmark scene (an icosphere on a
  ground quad, one point light), as the core benchmarks measure it and as the peers render it.
- :func:`run_peer` runs a worker script of this folder in the peers' own venv (Mitsuba 3,
  never a dependency of rtmesh; ``sh benchmarks/peers_setup.sh``), with Dr.Jit pointed at LLVM
  19 and its kernel cache in a folder of the caller's; :func:`start_peer` starts one that
  stays and answers requests line by line.
- :func:`publish` prints a benchmark's section of docs/BENCHMARKS.md and writes it there;
  :func:`write_side_by_side` shows an image beside its references.

Benchmarks run from the repository root as modules, e.g. ``python -m benchmarks.bench_peers``,
and import this module as ``from benchmarks import _lib``.
"""

import os
import platform
import re
import subprocess
import time
from pathlib import Path

import numpy as np

# only NumPy at the top: the peers' workers, in a venv without rtmesh (or trimesh), import
# this module too; the scene builders import what they need

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "BENCHMARKS.md"

# ---------------------------------------------------------------- timing and publishing


def seconds(fn):
    """Wall-clock seconds of one call of ``fn()``."""
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def machine():
    """One line on the machine: CPUs, model, Python and NumPy versions, load average now."""
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    # the 1-minute load average says how busy the (shared) machine was at the start
    return (f"{os.cpu_count()} CPUs (nproc), {model}, Python {platform.python_version()}, "
            f"NumPy {np.__version__}, load average {os.getloadavg()[0]:.1f} at the start")


def write_section(text, section, doc=DOC):
    """Replace (or append) the section ``## <section>`` of docs/BENCHMARKS.md with ``text``.

    Every benchmark writes its own section through this; the others are kept.
    """
    doc = Path(doc)
    doc.parent.mkdir(exist_ok=True)
    old = doc.read_text() if doc.exists() else "# Benchmarks\n"
    pattern = re.compile(rf"^## {re.escape(section)}\n.*?(?=^## |\Z)", re.S | re.M)
    if pattern.search(old):
        # the pattern takes the blank line before the next section with it: put it back
        new = pattern.sub(lambda _: text.rstrip("\n") + "\n\n", old)
    else:
        new = old.rstrip("\n") + "\n\n" + text
    doc.write_text(new.rstrip("\n") + "\n")


def publish(text, section, write=True, doc=DOC):
    """Print a benchmark's section and, if ``write``, put it into docs/BENCHMARKS.md."""
    print(text)
    if write:
        write_section(text, section, doc)
        print(f"written to {doc}")


def rtmesh_commit(folder):
    """The last commit that changed ``folder`` (an rtmesh package), ``+changes`` when its files
    differ from it; ``?`` outside git."""
    try:
        commit = subprocess.run(["git", "-C", str(folder), "log", "-1", "--format=%h", "--", "."],
                                capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(folder), "status", "--porcelain", "--", "."],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"
    return (commit or "?") + ("+changes" if dirty else "")


# ---------------------------------------------------------------- error


def block_means(image, block):
    """Means of ``block`` x ``block`` pixel blocks of an (h, w[, c]) image.

    Rows and columns beyond the last whole block are left out.
    """
    image = np.asarray(image, np.float64)
    h, w = image.shape[0] // block * block, image.shape[1] // block * block
    trimmed = image[:h, :w]
    return trimmed.reshape(h // block, block, w // block, block, *image.shape[2:]).mean(axis=(1, 3))


def relative_rmse(image, reference, block=1, mask=None, mean=None):
    """Relative RMSE of an image against a reference: RMSE over pixels and channels / the reference's mean.

    The error measure of every benchmark: 0 for identical images, and a uniform offset of
    ``d`` on a reference of mean ``m`` gives ``d / m``.

    Parameters
    ----------
    image, reference : array_like, (h, w[, c])
        Linear images.
    block : int, optional
        Compare the means of ``block`` x ``block`` pixel blocks instead of pixels (8: how
        far two converged images disagree, with little of their noise).
    mask : (h, w) bool array, optional
        Pixels to compare (``block`` must be 1); the mean is the reference's over them.
    mean : float, optional
        Divide by this instead of the reference's mean (e.g. the noise of two halves of an
        image over the mean of the whole).

    Returns
    -------
    float
    """
    image, reference = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    if image.shape != reference.shape:
        raise ValueError(f"image {image.shape} and reference {reference.shape} differ in shape")
    if mask is not None:
        if block != 1:
            raise ValueError("a mask compares pixels: block must be 1")
        image, reference = image[mask], reference[mask]
    elif block != 1:
        image, reference = block_means(image, block), block_means(reference, block)
    denominator = float(np.mean(reference)) if mean is None else float(mean)
    return float(np.sqrt(np.mean((image - reference) ** 2)) / max(denominator, 1e-30))


def gaussian_blur(image, sigma=1.0):
    """An (h, w[, c]) image blurred by a Gaussian of ``sigma`` pixels (cut at 3 sigma, edges
    mirrored): what an eye or a light denoiser does to pixel noise."""
    image = np.asarray(image, np.float64)
    radius = max(1, int(np.ceil(3 * sigma)))
    taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    taps /= taps.sum()
    pad = [(radius, radius), (radius, radius)] + [(0, 0)] * (image.ndim - 2)
    padded = np.pad(image, pad, mode="reflect")
    h, w = image.shape[:2]
    rows = sum(t * padded[k:k + h] for k, t in enumerate(taps))
    return sum(t * rows[:, k:k + w] for k, t in enumerate(taps))


def radial_power_spectrum(error, bins=24):
    """Radially averaged power spectrum of an (h, w) error image (its mean removed).

    Returns
    -------
    frequency : (bins,) float64
        Centre of each ring, cycles per pixel (0 .. 0.5).
    power : (bins,) float64
        Mean of |FFT|^2 / (h w) over the frequencies of each ring (white noise of variance
        v: v in every ring).
    """
    error = np.asarray(error, np.float64)
    power = np.abs(np.fft.fft2(error - error.mean())) ** 2 / error.size
    radius = np.hypot(*np.meshgrid(np.fft.fftfreq(error.shape[0]), np.fft.fftfreq(error.shape[1]), indexing="ij"))
    ring = np.minimum((radius / 0.5 * bins).astype(int), bins)
    inside = ring < bins
    power = np.bincount(ring[inside], power[inside], bins) / np.maximum(np.bincount(ring[inside], None, bins), 1)
    return (np.arange(bins) + 0.5) * 0.5 / bins, power


def blue_noise_ratio(power):
    """Mean power of the top third of a :func:`radial_power_spectrum`'s rings over that of
    the bottom third (the constant ring left out): 1 for white noise, above 1 for blue."""
    third = len(power) // 3
    return float(power[-third:].mean() / power[1:third].mean())


def display(image, exposure=0.0, operator="pbr-neutral"):
    """8-bit sRGB of a linear image (by default Khronos PBR Neutral tone mapping: base colours stay true)."""
    from rtmesh.io.colour import linear_to_srgb, tonemap

    return (linear_to_srgb(tonemap(image, exposure, operator)) * 255.0 + 0.5).astype(np.uint8)


def difference_panel(image, reference, mask=None):
    """Signed difference ``(image - reference) / mean(reference)``: red where the image is
    brighter, blue where darker, full colour at +-50 %, grey outside ``mask``."""
    from rtmesh.io.colour import linear_to_srgb

    mask = np.ones(image.shape[:2], bool) if mask is None else mask
    mean = float(reference[mask].mean()) if mask.any() else 1.0
    d = np.clip((image - reference).mean(axis=2) / mean / 0.5, -1.0, 1.0)
    out = np.zeros(image.shape, np.float64)
    out[..., 0] = np.clip(d, 0, 1)
    out[..., 2] = np.clip(-d, 0, 1)
    out[~mask] = 0.15
    return (linear_to_srgb(out.astype(np.float32)) * 255.0 + 0.5).astype(np.uint8)


def write_side_by_side(path, image, references, mask=None, exposure=0.0):
    """A PNG, pixels doubled: rtmesh | each reference | difference to the first reference.

    Parameters
    ----------
    path : str or Path
    image : (h, w, 3) float
        rtmesh's linear image.
    references : dict of str to (h, w, 3) float
        Linear references by name, in panel order.
    mask : (h, w) bool, optional
        Pixels the difference panel shows (the others grey).
    exposure : float, optional
        Stops, for the tone-mapped panels.

    Returns
    -------
    str
        The file and what its panels are.
    """
    from PIL import Image

    panels = [display(image, exposure)] + [display(r, exposure) for r in references.values()]
    panels.append(difference_panel(image, next(iter(references.values())), mask))
    gap = np.full((image.shape[0], 4, 3), 255, np.uint8)
    row = np.concatenate([p for panel in panels for p in (panel, gap)][:-1], axis=1)
    Image.fromarray(row).resize((2 * row.shape[1], 2 * row.shape[0]), Image.NEAREST).save(path)
    return f"{path}: rtmesh | " + " | ".join(f"Mitsuba {m}" for m in references) + \
        f" | (rtmesh - {next(iter(references))}) / mean, +-50 %"


# ---------------------------------------------------------------- the benchmark scene

ALBEDO = 0.7
LIGHT_POSITION = [3.0, -3.0, 6.0]
LIGHT_INTENSITY = 40.0  # W/sr in rtmesh's Lambert model (kd I cos / d^2)
CAMERA = dict(position=[0.0, -4.0, 2.5], look_at=[0.0, 0.0, 0.8], up=[0.0, 0.0, 1.0], fov=45.0)


def sphere_meshes():
    """The benchmark scene's sphere and ground as (vertices, faces, vertex normals or None).

    An icosphere (5 subdivisions, 20480 triangles, radius 1) centred at (0, 0, 1) with its
    vertex normals, and a 20 x 20 ground quad of two triangles at z = 0.  Positions and
    normals are rounded to float32, the precision every ray tracer here traces: rtmesh and
    a peer reading them from a file see exactly the same triangles.
    """
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=5)
    sphere.apply_translation([0.0, 0.0, 1.0])
    sphere_v = sphere.vertices.astype(np.float32).astype(np.float64)
    normals = np.asarray(sphere.vertex_normals).astype(np.float32).astype(np.float64)
    ground_v = np.array([[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]], dtype=np.float64)
    return {"sphere": (sphere_v, np.asarray(sphere.faces), normals),
            "ground": (ground_v, np.array([[0, 1, 2], [0, 2, 3]]), None)}


def sphere_scene(meshes=None, peer=True):
    """The rtmesh scene of :func:`sphere_meshes`: one point light at (3, -3, 6), camera at
    (0, -4, 2.5) looking at (0, 0, 0.8), 45 degree field of view, +Z up.

    Parameters
    ----------
    meshes : dict, optional
        From :func:`sphere_meshes` (built when not given).
    peer : bool, optional
        True: the scene the peers render too, Lambert albedo 0.7 everywhere, no ambient
        light, intensity 40 W/sr.  False: the core benchmarks' scene, a highlight on the
        sphere (specular 0.3, shininess 50), ambient 0.05, intensity 40.

    Returns
    -------
    rtmesh.scene.model.Scene
    """
    from rtmesh.lights.point_lights import PointLight
    from rtmesh.materials.table import Material
    from rtmesh.scene.camera import Camera
    from rtmesh.scene.model import MeshPart, Scene

    meshes = sphere_meshes() if meshes is None else meshes
    light = [PointLight(LIGHT_POSITION, LIGHT_INTENSITY)]
    camera = Camera(**CAMERA)
    if peer:
        parts = [MeshPart(name, v, f, 0, n) for name, (v, f, n) in meshes.items()]
        return Scene.from_parts(parts, [Material("lambert", diffuse=ALBEDO)], light, camera)
    parts = [MeshPart(name, v, f, i, n) for i, (name, (v, f, n)) in enumerate(meshes.items())]
    materials = [Material("sphere", diffuse=ALBEDO, specular=0.3, shininess=50),
                 Material("ground", diffuse=ALBEDO)]
    return Scene.from_parts(parts, materials, light, camera, ambient=[0.05] * 3)


def write_ply(path, vertices, faces, normals=None):
    """A binary little-endian PLY with float32 positions, optional normals and int faces."""
    columns = [vertices] if normals is None else [vertices, normals]
    props = "xyz" if normals is None else ["x", "y", "z", "nx", "ny", "nz"]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}",
              *[f"property float {p}" for p in props], f"element face {len(faces)}",
              "property list uchar int vertex_indices", "end_header"]
    face_records = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", 3)])
    face_records["n"], face_records["v"] = 3, faces
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(np.ascontiguousarray(np.hstack(columns), dtype="<f4").tobytes())
        f.write(face_records.tobytes())


# ---------------------------------------------------------------- peers

# the peers' venv (benchmarks/peers_setup.sh makes it): RTMESH_PEERS_VENV or /tmp/peers-venv
PEERS_VENV = os.environ.get("RTMESH_PEERS_VENV", "/tmp/peers-venv")
# Mitsuba's llvm variants abort with the system's LLVM 15 ("Cannot select ... fminimum")
LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


def peer_python(venv=PEERS_VENV):
    """The Python of the peers' venv, or None when there is none."""
    python = os.path.join(venv, "bin", "python")
    return python if os.path.exists(python) else None


def mitsuba_environment(home):
    """Environment variables for a Mitsuba worker process.

    Parameters
    ----------
    home : str
        Folder made (if missing) and set as ``HOME``, so Dr.Jit's kernel cache stays out of
        the user's home.

    Returns
    -------
    dict
        ``os.environ`` with ``HOME`` and ``DRJIT_LIBLLVM_PATH`` (LLVM 19: the variant
        ``llvm_ad_rgb`` aborts with the system's LLVM 15, see ``benchmarks/peers_setup.sh``).
    """
    os.makedirs(home, exist_ok=True)
    return dict(os.environ, HOME=home, DRJIT_LIBLLVM_PATH=LLVM)


def run_peer(worker, args, home, venv=PEERS_VENV, capture=True):
    """Run a worker module of this folder (``benchmarks.<worker>``) in the peers' venv.

    Parameters
    ----------
    worker : str
        Module name in this folder, e.g. ``"peers_mitsuba"``; it runs as
        ``python -m benchmarks.<worker>`` from the repository root, so it may import its
        sibling workers (never rtmesh: the venv has only the peers and NumPy).
    args : list of str
        Its command-line arguments.
    home : str
        Folder for the worker's ``HOME`` (:func:`mitsuba_environment`).
    venv : str, optional
    capture : bool, optional
        Capture its output (returned) rather than letting it print.

    Returns
    -------
    subprocess.CompletedProcess or None
        None when there is no venv.
    """
    python = peer_python(venv)
    if python is None:
        return None
    return subprocess.run([python, "-m", f"benchmarks.{worker}", *map(str, args)], cwd=ROOT,
                          env=mitsuba_environment(home), capture_output=capture, text=True)


def start_peer(worker, args, home, venv=PEERS_VENV):
    """Start a worker module of this folder in the peers' venv and leave it running.

    As :func:`run_peer`, but the worker keeps its process (and Mitsuba its compiled kernels)
    between requests: it reads one request a line on its standard input and answers one
    line on its standard output (text mode, line-buffered), so a benchmark can alternate
    renders of rtmesh and of the peer on a shared machine.  The worker's stderr passes
    through.

    Returns
    -------
    subprocess.Popen or None
        None when there is no venv.  Close its stdin to end it, then ``wait()``.
    """
    python = peer_python(venv)
    if python is None:
        return None
    return subprocess.Popen([python, "-m", f"benchmarks.{worker}", *map(str, args)], cwd=ROOT,
                            env=mitsuba_environment(home), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, bufsize=1)
