#!/usr/bin/env python3
"""Batch conversion without the installed ``rtmesh`` command: same options as ``rtmesh batch``.

    python tools/batch_convert.py models/ -o thumbs/ --width 256 --height 256
    python tools/batch_convert.py list.csv -o out/ --turntable 36 --scheduler tcp://host:8786
"""

import os
import sys

# run from a checkout without installing: the package sits beside this folder
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from rtmesh.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["batch", *sys.argv[1:]]))
