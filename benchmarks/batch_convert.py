#!/usr/bin/env python3
"""Batch conversion without the installed ``rtmesh`` command: same options as ``rtmesh batch``.

From the repository root (the checkout's rtmesh, not installed)::

    python -m benchmarks.batch_convert models/ -o thumbs/ --width 256 --height 256
    python -m benchmarks.batch_convert list.csv -o out/ --turntable 36 --scheduler tcp://host:8786
"""

import sys

from rtmesh.cli import main

if __name__ == "__main__":
    sys.exit(main(["batch", *sys.argv[1:]]))
