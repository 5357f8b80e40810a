"""How fast a fused direct-lighting kernel can be here: a minimal one beside rtmesh's.

Issue 13 asks rtmesh to reach Mitsuba 3's equal-error time on the peer scene of
``benchmarks/bench_peers.py``.  Whether that is reachable depends on what Embree's packet
queries and numba-compiled code cost on the machine, whatever rtmesh's own design.  This
tool measures that floor: the smallest kernel that renders the peer image, with nothing a
renderer would add (no materials table, no film sums for error estimates, no highlights,
no emission, no origin offsets: the shadow rays start on the surface with ``tnear``).

Per packet of 16 of one pixel's samples (the packets of rtmesh's fused stage at 16 spp)
it hashes the sample positions, forms pinhole rays, traces them with Embree's packet query
(:func:`rtmesh.geometry.embree_packets.query_packet`: ``rtcIntersectN`` of the native width)
(coherent), interpolates the vertex normals, forms Lambert + one point light, traces the
shadow packet with ``rtcOccludedN`` (coherent) and adds the samples to the pixel.  It
runs on rtmesh's own Embree scene, camera and normal tables (taken from an
:class:`~rtmesh.rendering.integrator.Integrator`), in two compiled variants: float32
arithmetic throughout, and float64 (packets float32, as Embree needs).

Reported, 1 thread, medians of ``--runs`` interleaved runs: ns per sample of each floor
variant and of rtmesh's render of the same scene and samples, and the ns per sample spent
inside the two Embree calls (read from the CPU's cycle counter around each call).  Where
the peers venv of ``benchmarks/bench_peers.py`` exists, Mitsuba 3 ``llvm_ad_rgb`` renders the
same scene and samples too (its ``direct`` integrator, on every core), reported as ns per
sample and thread: at equal spp the renderers have equal error, so this is what the
equal-error target of issue 13 compares.  The
floor image must match rtmesh's within its noise (relative RMSE printed; the tool stops
above 2 %), so the floor renders the same picture.

Usage::

    python -m benchmarks.bench_floor [--spp 16] [--runs 7] [--size 512] [--venv /tmp/peers-venv] [--no-write]
"""

import argparse
import tempfile
import time

import numba
import numpy as np

from benchmarks._lib import (ALBEDO, PEERS_VENV, machine, peer_python, publish, relative_rmse, sphere_meshes,
                             sphere_scene)
from benchmarks.bench_peers import mitsuba_sweep, write_mitsuba_scene
from benchmarks.profile_direct_stage import counter_rate, cycle_counter
from rtmesh.core import runtime
from rtmesh.geometry import embree_packets as ep
from rtmesh.geometry.embree_library import packet_library
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

SECTION = "The floor: a minimal fused kernel beside rtmesh's"
LANES = ep.LANES


def make_floor(real):
    """The floor kernel with its arithmetic in ``real`` (np.float32 or np.float64).

    The constants are of that type (numba freezes the closure's values with their types),
    so the float32 variant computes in float32 throughout.
    """
    zero, one = real(0.0), real(1.0)
    to_unit = real(1.0 / 4294967296.0)  # a 32-bit hash to [0, 1)
    tnear = np.float32(1e-4)  # the shadow rays' start, past the surface they leave
    shorten = real(1.0 - 1e-5)

    @numba.njit(nogil=True)
    def hash32(x):
        # a 32-bit integer hash (lowbias32); numba widens uint32 products, so mask them
        mask = np.uint64(0xFFFFFFFF)
        x = np.uint64(x) & mask
        x ^= x >> np.uint64(16)
        x = (x * np.uint64(0x7FEB352D)) & mask
        x ^= x >> np.uint64(15)
        x = (x * np.uint64(0x846CA68B)) & mask
        x ^= x >> np.uint64(16)
        return x

    @numba.njit(nogil=True, error_model="numpy")
    def render(intersect, occluded, scene, width, height, spp, camera, light, power, faces, smooth,
               normals, image, ticks):
        """Adds the mean of ``spp`` samples of each pixel to ``image`` (height, width);
        ``ticks[0]``, ``ticks[1]`` gather the counter ticks inside the two queries."""
        # one packet of each kind, with rtmesh's packet helpers (64-byte aligned buffers, the
        # lane fields no query changes)
        flags = np.int64(ep.RTC_RAY_QUERY_FLAG_COHERENT)
        rays, words, valid, args = ep.packet_buffers(np.int64(1), flags)
        shadow, shadow_words, shadow_valid, _ = ep.packet_buffers(np.int64(1), flags)
        for lane in range(LANES):
            valid[lane] = -1
            ep.set_lane(rays, words, lane, camera[0], camera[1], camera[2], 0.0, 0.0, 1.0, ep.DEFAULT_TFAR)
            ep.set_lane(shadow, shadow_words, lane, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, np.float32(0.0))
            shadow[ep.lane_word(ep.TNEAR, lane)] = tnear
        term = np.empty(LANES, real)
        ox, oy, oz = real(camera[0]), real(camera[1]), real(camera[2])
        ax, bx, ay, by = real(camera[3]), real(camera[4]), real(camera[5]), real(camera[6])
        fx, fy, fz = real(camera[7]), real(camera[8]), real(camera[9])
        rx, ry, rz = real(camera[10]), real(camera[11]), real(camera[12])
        ux, uy, uz = real(camera[13]), real(camera[14]), real(camera[15])
        lx, ly, lz = real(light[0]), real(light[1]), real(light[2])
        weight = one / real(spp)
        power = real(power)
        for pixel in range(width * height):
            line, column = pixel // width, pixel % width
            total = zero
            for first in range(0, spp, LANES):
                for lane in range(LANES):
                    key = np.uint64(pixel) * np.uint64(spp) + np.uint64(first + lane)
                    h1 = hash32(key * np.uint64(2))
                    h2 = hash32(h1 ^ np.uint64(0x9E3779B9))
                    sx = (real(column) + real(h1) * to_unit) * ax + bx
                    sy = (real(line) + real(h2) * to_unit) * ay + by
                    inv = one / np.sqrt(sx * sx + sy * sy + one)
                    rays[ep.lane_word(ep.DIR, lane)] = np.float32((fx + sx * rx + sy * ux) * inv)
                    rays[ep.lane_word(ep.DIR + 1, lane)] = np.float32((fy + sx * ry + sy * uy) * inv)
                    rays[ep.lane_word(ep.DIR + 2, lane)] = np.float32((fz + sx * rz + sy * uz) * inv)
                    rays[ep.lane_word(ep.TFAR, lane)] = ep.DEFAULT_TFAR
                    ep.clear_hit(words, lane)
                start = cycle_counter()
                ep.query_packet(intersect, scene, valid, rays, args, 0)
                ticks[0] += cycle_counter() - start
                for lane in range(LANES):
                    term[lane] = zero
                    shadow_valid[lane] = 0
                    if words[ep.lane_word(ep.GEOM_ID, lane)] == ep.INVALID_ID:
                        continue
                    f = words[ep.lane_word(ep.PRIM_ID, lane)]
                    t = real(rays[ep.lane_word(ep.TFAR, lane)])
                    u, v = real(rays[ep.lane_word(ep.U, lane)]), real(rays[ep.lane_word(ep.V, lane)])
                    if smooth[f]:  # per face [n0, n1 - n0, n2 - n0]
                        nx = real(normals[f, 0]) + u * real(normals[f, 3]) + v * real(normals[f, 6])
                        ny = real(normals[f, 1]) + u * real(normals[f, 4]) + v * real(normals[f, 7])
                        nz = real(normals[f, 2]) + u * real(normals[f, 5]) + v * real(normals[f, 8])
                    else:  # the face's unit normal
                        nx, ny, nz = real(faces[f, 9]), real(faces[f, 10]), real(faces[f, 11])
                    px = ox + t * real(rays[ep.lane_word(ep.DIR, lane)])
                    py = oy + t * real(rays[ep.lane_word(ep.DIR + 1, lane)])
                    pz = oz + t * real(rays[ep.lane_word(ep.DIR + 2, lane)])
                    wx, wy, wz = lx - px, ly - py, lz - pz
                    squared = wx * wx + wy * wy + wz * wz
                    distance = np.sqrt(squared)
                    cosine = (nx * wx + ny * wy + nz * wz) / (distance * np.sqrt(nx * nx + ny * ny + nz * nz))
                    if cosine <= zero:
                        continue
                    shadow_valid[lane] = -1
                    shadow[ep.lane_word(ep.ORG, lane)] = np.float32(px)
                    shadow[ep.lane_word(ep.ORG + 1, lane)] = np.float32(py)
                    shadow[ep.lane_word(ep.ORG + 2, lane)] = np.float32(pz)
                    shadow[ep.lane_word(ep.DIR, lane)] = np.float32(wx / distance)
                    shadow[ep.lane_word(ep.DIR + 1, lane)] = np.float32(wy / distance)
                    shadow[ep.lane_word(ep.DIR + 2, lane)] = np.float32(wz / distance)
                    shadow[ep.lane_word(ep.TFAR, lane)] = np.float32(distance * shorten)
                    term[lane] = power * cosine / squared
                start = cycle_counter()
                ep.query_packet(occluded, scene, shadow_valid, shadow, args, 0)
                ticks[1] += cycle_counter() - start
                for lane in range(LANES):
                    # Embree marks an occluded ray by setting its tfar to -inf
                    if shadow_valid[lane] != 0 and shadow[ep.lane_word(ep.TFAR, lane)] != -np.inf:
                        total += term[lane]
            image[line, column] += total * weight

    return render


def floor_inputs(integrator):
    """What the floor kernel reads, from an Integrator of the peer scene (its Embree scene,
    camera, light and per-face vertex normals, in the Integrator's shifted coordinates)."""
    it = integrator
    s = it.settings
    forward, right, up = it.camera_frame
    camera = np.concatenate([it.camera.position, it.camera.image_plane(s.width, s.height), forward, right, up])
    light = it.lights[0]
    # the peer scene's albedo times the light's (grey) intensity
    power = ALBEDO * float(np.asarray(light.intensity).reshape(-1)[0])
    library = packet_library()
    return (library.intersect, library.occluded, it.accel._shared.handle, s.width, s.height, s.spp,
            camera, np.asarray(light.position, dtype=np.float64), power, it.tables.faces, it.tables.smooth,
            np.ascontiguousarray(it.tables.vertex_normals))


def mitsuba_per_sample(size, spp, runs, venv):
    """Mitsuba llvm_ad_rgb's median render time of the peer scene, as ns per sample and
    thread, and its thread count; None without the peers venv or when it fails."""
    if peer_python(venv) is None:
        return None
    with tempfile.TemporaryDirectory(prefix="rtmesh-floor-") as folder:
        spec_path = write_mitsuba_scene(sphere_meshes(), size, size, folder)
        result = mitsuba_sweep(venv, spec_path, "llvm_ad_rgb", [spp], runs, 0, folder)
    if result is None:
        return None
    threads = runtime.usable_cores()  # Dr.Jit's pool takes every core it may use
    seconds = result["sweep"][spp][1]
    return seconds * threads / (size * size * spp) * 1e9, threads


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spp", type=int, default=16, help="a multiple of 16")
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--venv", default=PEERS_VENV, help="Mitsuba's venv (benchmarks/peers_setup.sh)")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    if args.spp % LANES:
        parser.error("--spp must be a multiple of 16 (one pixel's samples fill whole packets)")
    runtime.tune_process()
    it = Integrator(sphere_scene(), RenderSettings(width=args.size, height=args.size, spp=args.spp,
                                                              sampler="jittered", threads=1, seed=0))
    inputs = floor_inputs(it)
    variants = {"float32": make_floor(np.float32), "float64": make_floor(np.float64)}
    samples = args.size * args.size * args.spp
    rates = counter_rate()
    times = {name: [] for name in (*variants, "rtmesh")}
    ticks = {name: np.zeros(2, np.int64) for name in variants}
    images = {}
    reference = it.render().image  # warm-up
    for run in range(args.runs + 1):
        for name, render in variants.items():
            image = np.zeros((args.size, args.size), np.float64 if name == "float64" else np.float32)
            counts = np.zeros(2, np.int64)
            start = time.perf_counter()
            render(*inputs, image, counts)
            elapsed = time.perf_counter() - start
            if run:  # the first run compiles
                times[name].append(elapsed)
                ticks[name] += counts
            images[name] = image
        start = time.perf_counter()
        reference = it.render().image
        if run:
            times["rtmesh"].append(time.perf_counter() - start)
    grey = reference[..., 0]
    errors = {name: relative_rmse(image.astype(np.float64), grey) for name, image in images.items()}
    for name, error in errors.items():
        if not error < 0.02:
            raise SystemExit(f"bench_floor: the {name} floor image differs from rtmesh's by {error:.2%} "
                             "relative RMSE: not the same picture")
    per_sample = {name: float(np.median(t)) / samples * 1e9 for name, t in times.items()}
    lines = [f"## {SECTION}", "", f"`python -m benchmarks.bench_floor --spp {args.spp} --runs {args.runs}`", "",
             f"Peer scene ({args.size}x{args.size}, {args.spp} spp, jittered), 1 thread, medians of {args.runs} "
             f"interleaved runs; {machine()}; the cycle counter ticks {rates:.2f} times a ns.", "",
             "| kernel | ns a sample | x float32 floor | inside the intersect queries | inside the occlusion queries | "
             "rest | image vs rtmesh (rel. RMSE) |", "|---|---:|---:|---:|---:|---:|---:|"]
    floor = per_sample["float32"]
    for name in (*variants, "rtmesh"):
        if name in ticks:
            inside = ticks[name] / (args.runs * samples * rates)
            cells = f"{inside[0]:.1f} | {inside[1]:.1f} | {per_sample[name] - inside.sum():.1f} | {errors[name]:.2%}"
        else:
            cells = "see benchmarks/profile_direct_stage.py | | | (reference)"
        label = f"floor, {name} arithmetic" if name in variants else "rtmesh (fused stage)"
        lines.append(f"| {label} | {per_sample[name]:.1f} | {per_sample[name] / floor:.2f} | {cells} |")
    mitsuba = mitsuba_per_sample(args.size, args.spp, args.runs, args.venv)
    if mitsuba is None:
        lines += ["", f"Mitsuba skipped: no venv at {args.venv} (run `sh benchmarks/peers_setup.sh`), or it failed."]
    else:
        ns, threads = mitsuba
        lines.append(f"| Mitsuba 3 llvm_ad_rgb, {threads} threads, per sample and thread | {ns:.1f} | "
                     f"{ns / floor:.2f} | | | | (its own samples) |")
    text = "\n".join(lines)
    publish(text, SECTION, write=not args.no_write)


if __name__ == "__main__":
    main()
