"""Progress of a batch on the terminal: a bar, or one JSON line per finished asset (for
cluster logs).
"""


import json
import sys
import time


class BatchProgress:
    """Assets done / total with an ETA, on stderr: a bar on a terminal, a line every few
    seconds in a log."""

    def __init__(self, total, skipped, enabled=True, stream=None, log_every=10.0):
        self.stream = stream or sys.stderr
        self.enabled = enabled and total > skipped
        self.tty = self.stream.isatty()
        self.total, self.done, self.failed, self.skipped = total, skipped, 0, skipped
        self.start = time.perf_counter()
        self.log_every, self.last_log = log_every, self.start
        self.shown = False

    def update(self, record):
        self.done += 1
        self.failed += record["status"] == "failed"
        if not self.enabled:
            return
        now = time.perf_counter()
        if not self.tty and now - self.last_log < self.log_every and self.done < self.total:
            return
        self.last_log = now
        elapsed = now - self.start
        ran = self.done - self.skipped
        eta = elapsed / ran * (self.total - self.done) if ran else 0.0
        width = 30
        filled = int(width * self.done / self.total)
        failed = f", {self.failed} failed" if self.failed else ""
        text = (f"[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} assets{failed}, "
                f"{_duration(elapsed)} elapsed, {_duration(eta)} left")
        if self.tty:
            self.stream.write("\r" + text + "\033[K")
            self.shown = True
        else:
            self.stream.write("rtmesh batch: " + text + "\n")
        self.stream.flush()

    def note(self, text):
        """One line for a user watching the bar (``text``); nothing in a log or without a bar."""
        if self.enabled and self.tty:
            self.stream.write(text + "\n")
            self.stream.flush()

    def close(self):
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


class JsonProgress:
    """Machine-readable progress: one JSON line per finished asset (``--progress jsonl``).

    Each line: ``time`` (Unix seconds), ``asset``, ``status``, ``seconds``, ``images``
    (written), ``errors``, ``finished`` and ``total`` assets.  Written to ``stream``,
    flushed line by line for cluster logs.
    """

    def __init__(self, total, finished, stream):
        self.total, self.finished, self.stream = total, finished, stream

    def update(self, record):
        self.finished += 1
        line = {"time": round(time.time(), 3), "asset": record["asset"], "status": record["status"],
                "seconds": record["seconds"],
                "images": sum(i["status"] == "done" for i in record["images"]),
                "errors": record["errors"], "finished": self.finished, "total": self.total}
        self.stream.write(json.dumps(line, separators=(",", ":")) + "\n")
        self.stream.flush()

    def note(self, text):
        """Nothing: the lines are one JSON object per finished asset, for programs."""

    def close(self):
        pass


def _duration(seconds):
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    if seconds < 3600:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds // 3600}h{seconds // 60 % 60:02d}m"
