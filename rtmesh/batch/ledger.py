"""The batch ledger: which images are finished or failed, so a re-run resumes.

The ledger is an SQLite database (Python's standard :mod:`sqlite3`) in the output folder,
``OUTDIR/rtmesh-batch-ledger.sqlite``, one row per image in table ``images``:

=============  ===================================================================
``key``        output path relative to OUTDIR, without extension (primary key)
``asset``      the asset's name (its path relative to its input root)
``fingerprint`` :func:`rtmesh.batch.identity.image_fingerprint`
``status``     ``done`` or ``failed``
``inputs``     input entries (mesh file, MTL, textures, buffers), see :func:`encode`
``outputs``    output entries (file, size, mtime_ns, checksum), see :func:`encode`
``attempts``   failed attempts in a row with these inputs (0 once done)
``stage``, ``message``  why it failed
``seconds``, ``time``, ``run``  render time, when recorded, run id (done: the run that put the files in place)
=============  ===================================================================

and a ``meta`` table holding ``format`` (:data:`FORMAT`).  Entries are described in
:mod:`rtmesh.batch.identity`.

Safety against a kill at any moment: a ``done`` row is written only after every file of the
image was written whole (at a temporary name) and checked from this process, and committed
before the files are renamed into place (:mod:`rtmesh.batch.publish`); other rows are
committed once per asset, in write-ahead-log mode, so a kill loses at most the uncommitted
asset (redone next time) and never corrupts the database.  There is
no compaction and no temporary copy: one row per key is replaced in place.  Only the
process that runs the batch writes the ledger, and a lock file stops two batches from
sharing one output folder (``flock``; on a file system without locks the batch runs with a
warning, and nothing keeps a second batch out).

A ledger of rtmesh 0.1 (``rtmesh-batch-ledger.jsonl``) recorded only the mesh file's path,
size and time, which cannot be checked against the rules above: a batch refuses such a
folder with one line rather than trusting or silently discarding it.
"""

import fcntl
import json
import logging
import os
import sqlite3
import time

from rtmesh.core.errors import OutputError

log = logging.getLogger(__name__)

LEDGER_NAME = "rtmesh-batch-ledger.sqlite"
OLD_LEDGER_NAME = "rtmesh-batch-ledger.jsonl"
LOCK_NAME = ".rtmesh-batch.lock"
FORMAT = "2"
# keys per query: SQLite >= 3.32 takes 32766 parameters, older builds 999
_LOOKUP_CHUNK = 10_000 if sqlite3.sqlite_version_info >= (3, 32) else 900

# What a resume needs of an image's row, as the plain tuple SQLite returns (a named tuple
# would add a third to the time of a look-up): index it with these
KEY, FINGERPRINT, STATUS, INPUTS, OUTPUTS = range(5)
_ENTRY_COLUMNS = "key, fingerprint, status, inputs, outputs"


def encode(entries):
    """File entries ``[name, size, mtime_ns, checksum]`` as text: one line per entry, fields
    separated by tabs, empty for None (JSON, starting with ``[``, if a name holds a tab or
    a line break).  Much quicker to read back than JSON, which matters at a million rows."""
    if any("\t" in e[0] or "\n" in e[0] or e[0].startswith("[") for e in entries):
        return json.dumps(entries, separators=(",", ":"))
    return "\n".join("\t".join("" if v is None else str(v) for v in e) for e in entries)


def decode(text):
    """The entries :func:`encode` wrote."""
    if not text:
        return []
    if text[0] == "[":
        return json.loads(text)
    entries = []
    for line in text.split("\n"):
        name, size, mtime, digest = line.split("\t")
        entries.append([name, int(size) if size else None, int(mtime) if mtime else None,
                        digest or None])
    return entries

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS images (
    key TEXT PRIMARY KEY, asset TEXT, fingerprint TEXT, status TEXT, inputs TEXT,
    outputs TEXT, attempts INTEGER, stage TEXT, message TEXT, seconds REAL, time REAL,
    run TEXT) WITHOUT ROWID;
"""


class Ledger:
    """The ledger of one output folder; a context manager.

    Parameters
    ----------
    folder : str
        The batch's output folder (it must exist).

    Raises
    ------
    OutputError
        The ledger cannot be opened or written, is of an older or unknown format, or another
        batch holds the folder.
    """

    def __init__(self, folder):
        self.folder = folder
        self.path = os.path.join(folder, LEDGER_NAME)
        old = os.path.join(folder, OLD_LEDGER_NAME)
        if os.path.exists(old):
            raise OutputError(
                f"{old}: ledger of rtmesh 0.1, whose fingerprints cannot be checked: delete it "
                f"(every image in {folder} is then redone once) or choose another output folder")
        self._db = None
        try:
            self._lock = open(os.path.join(folder, LOCK_NAME), "a")
        except OSError as exc:
            raise OutputError(f"{folder}: cannot write the batch ledger: {exc.strerror}") from None
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            raise OutputError(f"{folder}: another rtmesh batch is writing to this folder") from None
        except OSError as exc:
            # no locks on this file system (NFS without its lock service, some FUSE
            # mounts): refusing would make the folder unusable, and a killed batch needs no
            # lock to be resumed safely (rtmesh.batch.publish); only two live batches in one
            # folder are then not kept apart
            log.warning("%s: cannot lock the output folder (%s): make sure no other batch "
                        "writes to it at the same time", folder, exc.strerror)
        try:
            self._open()
        except BaseException:
            self.close()
            raise

    def _open(self):
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
            # write-ahead log: commits append to OUTDIR/...-wal, crash-safe, no copy of the file
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            # look-ups read the file through memory mapping, not a read call per page: a
            # resume over a million rows asks for every page of the table
            self._db.execute("PRAGMA mmap_size=4294967296")
            self._db.executescript(_SCHEMA)
            row = self._db.execute("SELECT value FROM meta WHERE name='format'").fetchone()
            if row is None:
                self._db.execute("INSERT INTO meta VALUES ('format', ?)", (FORMAT,))
            elif row[0] != FORMAT:
                raise OutputError(f"{self.path}: batch ledger format {row[0]}, this rtmesh "
                                  f"reads format {FORMAT}: use a newer rtmesh or another folder")
        except sqlite3.DatabaseError as exc:
            raise OutputError(f"{self.path}: cannot use the batch ledger: {exc}") from None
        self._db.execute("BEGIN")

    def lookup(self, keys):
        """The rows of ``keys`` that the ledger has.

        Parameters
        ----------
        keys : sequence of str
            Any order; a batch asks for a few thousand at a time, in the order it found its
            assets, which for folders is mostly the ledger's own (sorted) order.

        Returns
        -------
        dict of str to tuple
            ``(key, fingerprint, status, inputs, outputs)``, indexed with :data:`KEY`,
            :data:`FINGERPRINT`, :data:`STATUS`, :data:`INPUTS`, :data:`OUTPUTS` (inputs and
            outputs still encoded, see :func:`decode`).  Failure details (``attempts``,
            ``stage``, ``message``) come from :meth:`failure`.
        """
        found = {}
        for start in range(0, len(keys), _LOOKUP_CHUNK):
            chunk = sorted(keys[start:start + _LOOKUP_CHUNK])
            if not chunk:
                continue
            want = set(chunk)
            # one sequential read of the key range, when the range holds little else...
            limit = 2 * len(chunk) + 100
            rows = self._db.execute(f"SELECT {_ENTRY_COLUMNS} FROM images WHERE key BETWEEN ? "
                                    "AND ? LIMIT ?", (chunk[0], chunk[-1], limit)).fetchall()
            found.update((row[0], row) for row in rows if row[0] in want)
            if len(rows) == limit:
                # ...else an index look-up of each key not found yet
                rest = [k for k in chunk if k not in found and k > rows[-1][0]]
                query = (f"SELECT {_ENTRY_COLUMNS} FROM images WHERE key IN "
                         f"({','.join('?' * len(rest))})")
                found.update((row[0], row) for row in self._db.execute(query, rest))
        return found

    def failure(self, key):
        """``(attempts, stage, message)`` of a failed image's row (None if not failed)."""
        return self._db.execute("SELECT attempts, stage, message FROM images WHERE key=? AND "
                                "status='failed'", (key,)).fetchone()

    def record(self, key, asset, fingerprint, status, inputs=(), outputs=(), seconds=0.0,
               run="", stage=None, message=None):
        """Write one image's row (after its files are safely on disk, for ``done``).

        A failure with the same fingerprint as the row's earlier failure counts one more
        attempt; the row becomes durable at the next :meth:`commit`.
        """
        attempts = 0
        if status != "done":
            row = self._db.execute("SELECT attempts FROM images WHERE key=? AND status='failed' "
                                   "AND fingerprint=?", (key, fingerprint)).fetchone()
            attempts = (row[0] if row else 0) + 1
        self._db.execute("INSERT OR REPLACE INTO images VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                         (key, asset, fingerprint, status,
                          encode(inputs), encode(outputs), attempts, stage, message,
                          round(seconds, 4), round(time.time(), 3), run))

    def set_run(self, key, run):
        """Name ``run`` as the run that put ``key``'s files in place (a run that finishes
        what a killed run recorded, see :class:`rtmesh.batch.publish.Leftovers`)."""
        self._db.execute("UPDATE images SET run=? WHERE key=?", (run, key))

    def commit(self):
        """Make the rows written so far durable (called once per finished asset, and for each
        done image before its files are put in place)."""
        self._db.execute("COMMIT")
        self._db.execute("BEGIN")

    def count(self):
        """Rows in the ledger."""
        return self._db.execute("SELECT COUNT(*) FROM images").fetchone()[0]

    def close(self):
        """Commit, and release the folder for the next batch."""
        if self._db is not None:
            try:
                if self._db.in_transaction:
                    self._db.execute("COMMIT")
            finally:
                self._db.close()
                self._db = None
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
