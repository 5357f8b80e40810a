#!/bin/sh
# Install the peer renderers for tools/bench_peers.py, tools/bench_pbr_peers.py and
# tools/peers_mitsuba_cornell.py in a venv of their own.
#
# Mitsuba 3 is a benchmark peer, never a dependency of rtmesh: it goes into a separate
# virtual environment (default /tmp/peers-venv; pass another path as the first argument).
# Its llvm_ad_rgb variant aborts with the system's LLVM 15 ("Cannot select ... fminimum"),
# so LLVM 19 is installed from apt when it is missing; bench_peers.py points Dr.Jit at it
# through DRJIT_LIBLLVM_PATH.
#
# Usage: sh tools/peers_setup.sh [VENV]
set -eu
VENV="${1:-/tmp/peers-venv}"
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
