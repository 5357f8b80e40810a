"""Putting a batch's images in place: one writer per image, and only after it is recorded.

A batch worker (a local worker process or a Dask task) writes each image's files under
hidden temporary names (:func:`rtmesh.io.atomic_files.staged`) and reports those names.
The submitting process, which alone holds the output folder (the ledger's lock,
:class:`rtmesh.batch.ledger.Ledger`), checks the files, commits the image's ledger row and
only then renames them into place (:func:`publish`).  It follows that:

- **no task of an earlier run writes an image**: after a ``kill -9`` of the submitting
  process its tasks may go on rendering on a cluster, but nothing renames what they write;
  a resumed run (which can take the folder only once the killed process is gone) removes
  their temporaries and renders those images itself;
- **no image is in place without its ledger row**, so a resume never renders an image
  again because its row was lost: a kill between the commit and the renames leaves the
  temporaries, which the next run renames into place after checking their content against
  the row (:meth:`Leftovers.roll_forward`) instead of rendering the image again.

Together, each image file is put in place once, by one run; there is no lock for the
workers to take and nothing they must check before writing (they still stop early when
their run is superseded, to free the cluster: :func:`rtmesh.batch.worker.run_job`).
"""

import os
import re

from rtmesh.batch.identity import unchanged
from rtmesh.io.atomic_files import target_of

# the batch's own temporaries: half-written or unpublished images (".NAME.XXXX.tmp.EXT"),
# camera, metadata and dataset files and movies (".NAME.json.XXXX.tmp"), and the
# temporary files of the summary, the run file, storage probes and rtmesh 0.1's ledger
# compaction; a user's own hidden files are left alone
_STALE = re.compile(r"^\.(.+\.tmp\.(png|exr|jpe?g)|.+\.(json|txt|webp|gif|mp4|png)\.[^.]+\.tmp|"
                    r"rtmesh-batch-.+\.tmp)$", re.IGNORECASE)


def publish(outdir, pairs):
    """Rename staged files into place, in order.

    Parameters
    ----------
    outdir : str
    pairs : iterable of (str, str)
        ``(temporary, name)``, both relative to ``outdir``.

    Raises
    ------
    OSError
        A rename failed (its ``filename`` is the ``name``); the pairs before it are in
        place, the rest are not.
    """
    for temporary, name in pairs:
        try:
            os.replace(os.path.join(outdir, temporary), os.path.join(outdir, name))
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, name) from None


def discard(outdir, temporaries):
    """Remove staged files that will not be published (a missing one is no error)."""
    for temporary in temporaries:
        try:
            os.unlink(os.path.join(outdir, temporary))
        except OSError:
            pass  # hidden, never taken for an image, and removed by the next run


class Leftovers:
    """The temporaries a killed run left in an output folder.

    Found when a batch takes the folder (holding its lock, so no other submitting process
    is publishing), before the plan; those the plan does not roll forward are removed
    after it (:meth:`remove`).

    Parameters
    ----------
    outdir : str
    """

    def __init__(self, outdir):
        self.paths = []
        self._by_target = {}  # absolute path of the file a temporary stands for -> temporaries
        for here, _, files in os.walk(outdir):
            for name in files:
                if _STALE.match(name):
                    path = os.path.join(here, name)
                    self.paths.append(path)
                    target = target_of(name)
                    if target:
                        self._by_target.setdefault(os.path.join(here, target), []).append(path)

    def roll_forward(self, entry, path):
        """Put in place a temporary holding exactly what ``entry`` recorded for ``path``.

        Parameters
        ----------
        entry : list
            The output entry ``[name, size, mtime_ns, checksum]`` of a committed ledger row
            whose file at ``path`` is missing or different.
        path : str

        Returns
        -------
        bool
            True when such a temporary was found (compared by content, whatever
            ``--trust-mtime`` says) and renamed to ``path``.
        """
        for temporary in self._by_target.get(path, ()):
            if unchanged(entry, temporary):
                try:
                    os.replace(temporary, path)
                except OSError:
                    return False
                self._by_target[path].remove(temporary)
                self.paths.remove(temporary)
                return True
        return False

    def remove(self):
        """Delete the temporaries not rolled forward."""
        for path in self.paths:
            try:
                os.unlink(path)
            except OSError:
                pass  # harmless: it is hidden and never taken for an image
        self.paths, self._by_target = [], {}
