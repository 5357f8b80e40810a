"""Which memory after an ``RTCRay16`` packet Embree's ``rtcOccluded16`` touches.

The library embreex ships reads the nine rows that follow a ray packet of 16 (where an
``RTCRayHit16`` keeps its hit: Ng, u, v and the ids) during an occlusion query and writes
them back as it read them.  No single-threaded check sees it (the words come back
unchanged), but a second thread that writes those words while a query runs sees some of
its writes undone.  That is what this probe measures: one thread traces occlusion packets
through ctypes (the GIL released, as rtmesh's kernels trace) while a compiled loop on
another thread writes an increasing counter into a range of rows after the packet and
counts the words it finds changed by someone else.

Rows 12-20 (the hit part) are the ones the query rewrites; rows 21-29 (beyond an
``RTCRayHit16``) are a control and must stay 0.  This is why
:func:`rtmesh.geometry.embree_packets.packet_buffers` gives every group of a packet a whole
``RTCRayHitN`` (:data:`~rtmesh.geometry.embree_packets.PACKET_WORDS`): without room after
the last packet two render threads corrupted the heap.  Needs two free cores to see the race.

Usage::

    python -m benchmarks.probe_occlusion_rows [--queries 20000]
"""

import argparse
import threading

import numba
import numpy as np
import trimesh

from rtmesh.geometry import embree_packets as ep
from rtmesh.geometry.accel import Accel
from rtmesh.geometry.embree_library import aligned_array, packet_library


@numba.njit(nogil=True)
def _write_and_count(words, stop, lo, hi):
    """Write 1, 2, 3, ... into ``words[lo:hi]`` until ``stop[0]``; count the words found
    holding neither the last value written nor the current one."""
    value, undone = 0, 0
    while stop[0] == 0:
        value += 1
        for q in range(lo, hi):
            if words[q] != value - 1 and words[q] != value:
                undone += 1
            words[q] = value
    return undone, value


def probe(first_row, last_row, queries, seed=0):
    """Undone writes and rounds of the writer on rows ``first_row .. last_row - 1``."""
    sphere, box = trimesh.creation.icosphere(3), trimesh.creation.box((4, 4, 4))
    accel = Accel(np.vstack([sphere.vertices, box.vertices]),
                  np.vstack([sphere.faces, box.faces + len(sphere.vertices)]), packets=True)
    lanes = 16  # rtcOccluded16, whatever width the kernels' packets use here
    occluded16 = packet_library().packet_query("Occluded", 16)
    words = aligned_array(40 * lanes, np.int32)
    rays = words.view(np.float32)
    valid, args = aligned_array(lanes, np.int32), aligned_array(8, np.int32)
    args[0], args[1] = ep.RTC_RAY_QUERY_FLAG_INCOHERENT, ep.RTC_FEATURE_FLAG_ALL
    stop, result = np.zeros(1, np.int64), {}
    rng = np.random.default_rng(seed)

    def trace():
        for _ in range(queries):
            origins = rng.uniform(-1.9, 1.9, (3, lanes))
            directions = rng.normal(size=(3, lanes))
            directions /= np.linalg.norm(directions, axis=0)
            rays[ep.ORG * lanes:(ep.ORG + 3) * lanes] = origins.ravel()
            rays[ep.DIR * lanes:(ep.DIR + 3) * lanes] = directions.ravel()
            rays[ep.TNEAR * lanes:(ep.TNEAR + 1) * lanes] = 0.0
            rays[ep.TIME * lanes:(ep.TIME + 1) * lanes] = 0.0
            rays[ep.TFAR * lanes:(ep.TFAR + 1) * lanes] = rng.uniform(0.0, 10.0, lanes)
            words[ep.MASK * lanes:(ep.FLAGS + 1) * lanes] = 0
            words[ep.MASK * lanes:(ep.MASK + 1) * lanes] = -1
            valid[:] = -1
            occluded16(valid.ctypes.data, accel._shared.handle, rays.ctypes.data, args.ctypes.data)
        stop[0] = 1

    def write():
        result["counts"] = _write_and_count(words, stop, first_row * lanes, last_row * lanes)

    _write_and_count(np.zeros(1, np.int32), np.ones(1, np.int64), 0, 0)  # compile first
    threads = [threading.Thread(target=write), threading.Thread(target=trace)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return result["counts"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--queries", type=int, default=20000)
    options = parser.parse_args()
    for first, last, what in ((ep.RAY_WORDS, ep.RAYHIT_WORDS, "hit part of an RTCRayHit16"),
                              (ep.RAYHIT_WORDS, ep.RAYHIT_WORDS + 9, "beyond it (control)")):
        undone, rounds = probe(first, last, options.queries)
        print(f"rows {first}-{last - 1} ({what}): {undone} words undone in {rounds} rounds "
              f"of {(last - first) * ep.LANES} words ({undone / max(rounds * (last - first) * ep.LANES, 1):.2%})")


if __name__ == "__main__":
    main()
