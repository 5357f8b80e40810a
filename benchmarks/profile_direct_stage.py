"""Where the fused direct-lighting kernel spends its time, step by step, in CPU cycles.

perf cannot name numba's functions, and timing the kernel from Python shows only the
whole.  This tool makes an instrumented copy of
:func:`rtmesh.rendering.direct_stage.direct_samples`: the kernel's own source with a read of
the CPU's cycle counter (``llvm.readcyclecounter``, through a numba intrinsic) at each step
boundary, the cycles between two reads added to that step's total.  The copy is compiled
in a temporary folder, put in the stage's place, and renders the scene of
``benchmarks/bench_peers.py`` (``--scene peer``: Lambert, one point light, jittered samples) or of
``benchmarks/bench_core.py`` (``--scene core``: a highlight on the sphere, ambient light,
regular samples) on 1 thread.  It prints the cycles per sample of each step and checks
that the instrumented copy renders the image the stage renders.

The step boundaries are found by lines of the kernel's source (``STEPS``): a change of
the kernel that moves or rewords one of them stops the tool with the line it could not
find, to be updated here.  The reads cost a few cycles each (about 15 a block of 64
samples); the counter ticks at a constant rate (printed), not at the core's clock.

Usage::

    python -m benchmarks.profile_direct_stage [--scene peer|core] [--spp 16] [--runs 5] [--size 512]
"""

import argparse
import importlib.util
import inspect
import os
import tempfile
import time

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from benchmarks._lib import sphere_scene
from rtmesh.core import runtime
from rtmesh.rendering import direct_stage
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

# (a line of direct_samples, the step that ends where it begins), in source order; a step
# may end at several lines (the light loop's steps run once per light)
STEPS = [
    ("        # camera rays (rtmesh.scene.camera_rays", "pixels of the block"),
    ("        for b in range(BLOCK):\n            valid[b] = -1 if b < count else 0", "camera rays"),
    ("        for q in range((count + LANES - 1) // LANES):\n            ep.query_packet(intersect", "hit fields cleared"),
    ("        # surface records (rtmesh.shading.surfaces", "intersect queries"),
    ("        srf = surface_block(", "hit ids and materials"),
    ("        # each light in turn", "surface records"),
    ("            lit, values, shadow_ray = light_block(", "Blinn-Phong sums"),
    ("            write_rays(shadow_ray, shadow)", "light samples"),
    ("            for b in range(BLOCK):\n                on = (b < count) & receives[b]", "shadow rays into packets"),
    ("            for q in range((count + LANES - 1) // LANES):\n                ep.query_packet(occluded", "lit test"),
    ("            for group in range(BLOCK // ep.GROUP):\n                at = group * ep.GROUP_WORDS + ep.TFAR * ep.GROUP",
     "occlusion queries"),
    ("            # the highlights (pow is", "occlusion results"),
    ("            for b in range(count):\n                mat_b = mat[b]\n                d0, d1, d2", "highlight powers"),
    ("        # emission and ambient light plus", "Blinn-Phong sums"),
]
# the last line of the block loop: the radiance of each sample, added to its pixel's sums
FILM_END = "                       first_pixel, counts, total, total_sq, film_count, image, sums, state)\n"
SIGNATURE_END = "visible_from, scale, shorten, highlights):"


@intrinsic
def cycle_counter(typingctx):
    """The CPU's cycle counter (``llvm.readcyclecounter``: ``rdtsc`` on x86-64)."""

    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
        return builder.call(fn, [])

    return types.int64(), codegen


@numba.njit
def read_counter():
    return cycle_counter()


def step_names():
    """The steps in the order they are first met."""
    names = []
    for _, name in STEPS:
        if name not in names:
            names.append(name)
    return names + ["radiance and film"]


def instrumented_source():
    """Source of a module with ``direct_samples`` taking one more argument, the (steps,)
    int64 array its cycles are added to."""
    source = inspect.getsource(direct_stage)
    body = source[source.index("@kernel\ndef direct_samples"):]
    head = source[:source.index("@kernel\ndef direct_samples")]
    # the copy uses the stage's kernel group rather than declaring it a second time
    group = head.index("FUSED_KERNELS = KernelGroup(")
    head = (head[:group] + "from rtmesh.rendering.direct_stage import FUSED_KERNELS  # noqa: E402\n"
            + head[head.index("\n])\n", group) + 4:])
    names = step_names()
    for text, name in STEPS:
        if body.count(text) != 1:
            raise SystemExit(f"profile_direct_stage: the kernel no longer has this line once; update STEPS:\n{text}")
        indent = text[:len(text) - len(text.lstrip())]
        body = body.replace(text, f"{indent}t1 = cycle_counter(); cycles[{names.index(name)}] += t1 - t0; t0 = t1\n"
                            + text)
    for text in (FILM_END, SIGNATURE_END, "    for start in range(0, n, BLOCK):"):
        if body.count(text) != 1:
            raise SystemExit(f"profile_direct_stage: the kernel no longer has this line once:\n{text}")
    body = body.replace(FILM_END, FILM_END + f"        t1 = cycle_counter(); cycles[{names.index('radiance and film')}] += t1 - t0; "
                        "t0 = t1\n")
    body = body.replace(SIGNATURE_END, SIGNATURE_END.replace("):", ", cycles):"))
    body = body.replace("    for start in range(0, n, BLOCK):", "    t0 = cycle_counter()\n    for start in range(0, n, BLOCK):")
    return head + "from benchmarks.profile_direct_stage import cycle_counter\n\n" + body


def load_instrumented(folder):
    """The instrumented module, compiled from ``folder``."""
    path = os.path.join(folder, "instrumented_direct_stage.py")
    with open(path, "w") as f:
        f.write(instrumented_source())
    spec = importlib.util.spec_from_file_location("instrumented_direct_stage", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def counter_rate():
    """Counter ticks per nanosecond, over 0.3 s of wall time."""
    read_counter()
    c0, t0 = read_counter(), time.perf_counter()
    time.sleep(0.3)
    c1, t1 = read_counter(), time.perf_counter()
    return (c1 - c0) / ((t1 - t0) * 1e9)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", choices=("peer", "core"), default="peer")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--size", type=int, default=512)
    args = parser.parse_args()
    runtime.tune_process()
    scene = sphere_scene(peer=args.scene == "peer")
    settings = RenderSettings(width=args.size, height=args.size, spp=args.spp, threads=1, seed=0,
                              sampler="jittered" if args.scene == "peer" else "regular")
    integrator = Integrator(scene, settings)
    if integrator.direct_stage is None:
        raise SystemExit("profile_direct_stage: this render does not take the fused stage")
    reference = integrator.render().image
    names = step_names()
    cycles = np.zeros(len(names), np.int64)
    with tempfile.TemporaryDirectory() as folder:
        module = load_instrumented(folder)
        original = direct_stage.direct_samples
        direct_stage.direct_samples = lambda *a: module.direct_samples(*a, cycles)
        try:
            image = integrator.render().image  # compiles the copy
            cycles[:] = 0
            start = time.perf_counter()
            for _ in range(args.runs):
                image = integrator.render().image
            seconds = (time.perf_counter() - start) / args.runs
        finally:
            direct_stage.direct_samples = original
    samples = args.size * args.size * args.spp * args.runs
    rate = counter_rate()
    print(f"{args.scene} scene, {args.size}x{args.size}, {args.spp} spp, 1 thread, {args.runs} renders: "
          f"{seconds * 1e9 / (samples / args.runs):.1f} ns a sample (instrumented); the counter ticks "
          f"{rate:.2f} times a ns; image {'identical to' if np.array_equal(image, reference) else 'DIFFERENT from'}"
          " the stage's")
    print("\n| step | cycles a sample | share |\n|---|---:|---:|")
    for name, value in zip(names, cycles):
        print(f"| {name} | {value / samples:.1f} | {100 * value / cycles.sum():.1f} % |")
    print(f"| **all** | **{cycles.sum() / samples:.1f}** | |")


if __name__ == "__main__":
    main()
