#!/bin/sh
# Install the peer renderers for benchmarks/bench_peers.py, benchmarks/bench_pbr_peers.py and
# benchmarks/peers_mitsuba_cornell.py in a venv of their own.
#
# Mitsuba 3 is a benchmark peer, never a dependency of rtmesh: it goes into a separate
# virtual environment: the first argument, else $RTMESH_PEERS_VENV, else /tmp/peers-venv (the
# benchmarks look for it in the same places: benchmarks/_lib.py).
# Its llvm_ad_rgb variant aborts with the system's LLVM 15 ("Cannot select ... fminimum"),
# so LLVM 19 is installed from apt when it is missing; the benchmarks point Dr.Jit at it
# through DRJIT_LIBLLVM_PATH (benchmarks/_lib.py run_peer).
#
# Usage: sh benchmarks/peers_setup.sh [VENV]
set -eu
VENV="${1:-${RTMESH_PEERS_VENV:-/tmp/peers-venv}}"
LLVM=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1

if [ ! -e "$LLVM" ]; then
    if command -v apt-get >/dev/null 2>&1; then
        apt-get update -qq && apt-get install -y -qq libllvm19
    else
        echo "peers_setup: $LLVM missing and no apt-get; llvm_ad_rgb will be skipped" >&2
    fi
fi
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q mitsuba numpy
"$VENV/bin/python" -c "import mitsuba as mi; print('mitsuba', mi.__version__, mi.variants())"
