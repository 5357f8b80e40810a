"""The batch ledger: which images are finished, so a re-run skips them.

The ledger is a JSON-lines file in the output folder, one record per image:
``{"key": ..., "fingerprint": ..., "status": "done" | "failed", ...}``; the last record of
a key wins.  Two rules make it safe to kill the batch at any moment:

- A ``done`` record is appended only after every file of the image has been written
  atomically (temporary file, then ``os.replace``), so the ledger never claims an image
  that is not complete on disk.
- Each record is one ``write`` of one line on a file opened for appending, so a kill leaves
  either the whole record or none of it; a torn last line (power loss, full disk) is ignored
  when reading.  Appending keeps the cost per record constant for millions of assets; the
  whole file is rewritten (compacted) atomically, temporary file and ``os.replace``, only
  when a batch opens and closes it.

Only the process that runs the batch (the client, with Dask) writes the ledger, and a lock
stops two batches from sharing one output folder.
"""

import fcntl
import json
import os
import tempfile
import time

from rtmesh.core.errors import OutputError

LEDGER_NAME = "rtmesh-batch-ledger.jsonl"


class Ledger:
    """Finished and failed images of a batch, kept in ``OUTDIR/rtmesh-batch-ledger.jsonl``.

    Parameters
    ----------
    folder : str
        The batch's output folder (it must exist).

    Raises
    ------
    OutputError
        If the ledger cannot be written or another batch holds it.
    """

    def __init__(self, folder):
        self.folder = folder
        self.path = os.path.join(folder, LEDGER_NAME)
        self.records = self._read()
        try:
            self._lock = open(os.path.join(folder, ".rtmesh-batch.lock"), "a")
        except OSError as exc:
            raise OutputError(f"{folder}: cannot write the batch ledger: {exc.strerror}") from None
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            raise OutputError(f"{folder}: another rtmesh batch is writing to this folder") from None
        self.compact()
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)

    def _read(self):
        records = {}
        try:
            with open(self.path, encoding="utf-8") as f:
                for line in f:
                    try:
                        record = json.loads(line)
                    except ValueError:
                        continue  # a torn line: the image it described is redone
                    if isinstance(record, dict) and "key" in record:
                        records[record["key"]] = record
        except FileNotFoundError:
            pass
        except (OSError, UnicodeDecodeError) as exc:
            raise OutputError(f"{self.path}: cannot read the batch ledger: {exc}") from None
        return records

    def is_done(self, key, fingerprint):
        """True when ``key`` was finished with the same inputs and its files are all there.

        The files are checked too, so deleting an image makes the next run redo it.
        """
        record = self.records.get(key)
        if not record or record.get("status") != "done" or record.get("fingerprint") != fingerprint:
            return False
        return all(os.path.isfile(os.path.join(self.folder, f)) for f in record.get("files", ()))

    def record(self, key, fingerprint, status, **fields):
        """Append one record (after the image's files are safely on disk, for ``done``)."""
        record = {"key": key, "fingerprint": fingerprint, "status": status,
                  "time": round(time.time(), 3), **fields}
        self.records[key] = record
        line = (json.dumps(record, separators=(",", ":")) + "\n").encode("utf-8")
        os.write(self._fd, line)  # one write of one whole line: see the module docstring

    def compact(self):
        """Rewrite the ledger with one record per key, atomically."""
        fd, tmp = tempfile.mkstemp(prefix=".rtmesh-batch-ledger.", suffix=".tmp", dir=self.folder)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                for record in self.records.values():
                    f.write(json.dumps(record, separators=(",", ":")) + "\n")
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    def close(self):
        """Compact the ledger and release the folder for the next batch."""
        if self._fd is None:
            return
        os.close(self._fd)
        self._fd = None
        try:
            self.compact()
        finally:
            self._lock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
