"""The books of a batch: the ledger entries of finished and failed images as they arrive, the
per-asset files written beside them, the report (JSON lines and a summary) and the exit
status (:attr:`BatchReport.exit_code`: 0 every asset done, 1 some failed in this run, 2
bad invocation, 3 the Dask cluster was lost).
"""


import json
import os
import sys
import time
from dataclasses import dataclass, field

from rtmesh import __version__
from rtmesh.batch.datasets import write_dataset
from rtmesh.batch.identity import unchanged
from rtmesh.batch.movies import movie_frames, write_movie
from rtmesh.batch.progress import BatchProgress, JsonProgress
from rtmesh.batch.publish import discard, publish

REPORT_NAME = "rtmesh-batch-report.jsonl"


SUMMARY_NAME = "rtmesh-batch-summary.json"


EXIT_DONE, EXIT_FAILED, EXIT_USAGE, EXIT_CLUSTER_LOST = 0, 1, 2, 3


@dataclass
class BatchReport:
    """What a batch did.

    Also written to the output folder: ``rtmesh-batch-summary.json`` (this object without
    the per-asset list) and ``rtmesh-batch-report.jsonl`` (one JSON line per asset this run
    attempted or left as a known failure; assets finished by earlier runs are counted only).

    Attributes
    ----------
    counts : dict of str to int
        ``assets``; each one is ``done`` (by this run), ``skipped`` (finished by an earlier
        run, unchanged), ``failed`` (in this run), ``known_failed`` (failed in an earlier run
        with the same inputs and not retried: ``retry_failed=False``) or ``not_attempted``
        (the cluster was lost first).  ``retried``: assets that had failed before and were
        tried again by this run (whatever the outcome); ``images``: images written.
    assets : list of dict
        Per attempted or known-failed asset: ``asset``, ``path``, ``status``, ``seconds``,
        ``images``, ``errors`` (``image``, ``stage``, ``message``), ``retried``.
    wall_seconds : float
    assets_per_minute : float
        Assets converted by this run per minute of wall time.
    runner : str
    path : str
        Where the summary JSON was written.
    """

    counts: dict
    assets: list
    wall_seconds: float
    assets_per_minute: float
    runner: str
    path: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def failed(self):
        """Assets that failed in this run."""
        return [a for a in self.assets if a["status"] == "failed"]

    @property
    def exit_code(self):
        """:data:`EXIT_CLUSTER_LOST`, :data:`EXIT_FAILED` or :data:`EXIT_DONE`."""
        if self.counts["not_attempted"]:
            return EXIT_CLUSTER_LOST
        return EXIT_FAILED if self.counts["failed"] else EXIT_DONE

    def to_dict(self):
        """The summary document (without the per-asset list)."""
        return {"rtmesh_version": __version__, "counts": self.counts,
                "wall_seconds": round(self.wall_seconds, 3),
                "assets_per_minute": round(self.assets_per_minute, 2), "runner": self.runner,
                "exit_code": self.exit_code, **self.extra}

    def summary(self, max_lines=12):
        """A one-screen summary: counts, throughput, failures with reasons, slowest assets."""
        c = self.counts
        known = f", {c['known_failed']} known failures not retried" if c["known_failed"] else ""
        retried = f" ({c['retried']} retried)" if c["retried"] else ""
        lost = f", {c['not_attempted']} not attempted" if c["not_attempted"] else ""
        lines = [f"rtmesh batch: {c['assets']} assets: {c['done']} done, {c['skipped']} skipped, "
                 f"{c['failed']} failed{retried}{known}{lost}; {c['images']} images in "
                 f"{self.wall_seconds:.1f} s ({self.assets_per_minute:.1f} assets/min, {self.runner})"]
        failed = self.failed
        if failed:
            lines.append("failed:")
            for a in failed[:max_lines]:
                e = a["errors"][0]
                more = f" (+{len(a['errors']) - 1} more)" if len(a["errors"]) > 1 else ""
                lines.append(f"  {a['asset']}: {e['stage']}: {e['message']}{more}")
            if len(failed) > max_lines:
                lines.append(f"  ... and {len(failed) - max_lines} more (see the report)")
        timed = sorted((a for a in self.assets if a["seconds"] > 0),
                       key=lambda a: -a["seconds"])[:3]
        if timed:
            lines.append("slowest: " + ", ".join(f"{a['asset']} {a['seconds']:.2f} s" for a in timed))
        if self.path:
            lines.append(f"report: {self.path}")
        return "\n".join(lines)


class Books:
    """The batch's bookkeeping, in the submitting process: ledger rows, the JSON-lines
    report, counts and progress, one asset at a time.

    Parameters
    ----------
    ledger : Ledger
    outdir : str
    opts : BatchOptions
    total : int
        Assets in the batch.
    progress_file : file, optional
        Where ``jsonl`` progress goes (default stderr); closed with the books.
    """

    def __init__(self, ledger, outdir, opts, total, progress_file=None):
        self.ledger, self.outdir, self.opts, self.total = ledger, outdir, opts, total
        self.progress_file = progress_file
        self.counts = {"assets": total, "done": 0, "skipped": 0, "failed": 0, "known_failed": 0,
                       "retried": 0, "not_attempted": 0, "images": 0}
        self.assets, self.pending, self.finished_jobs = [], {}, 0
        # (key, files) of every finished image, for --contact-sheet and --annotations
        self.sheet = []
        self.check_content = opts.scheduler is not None
        self._report = open(os.path.join(outdir, REPORT_NAME), "w", encoding="utf-8")
        self.progress = None

    def planned(self, asset, skipped, known, retried, has_job):
        """Enter an asset as planned: its skipped images, known failures, and whether a job
        will run for it."""
        if self.opts.contact_sheet or self.opts.annotations:
            self.sheet.extend((t.key, list(t.files)) for t in skipped)
        record = {"asset": asset.name, "path": asset.path, "status": None, "seconds": 0.0,
                  "retried": retried,
                  "images": [{"key": t.key, "status": "skipped", "files": list(t.files)}
                             for t in skipped]}
        for task in known:
            attempts, stage, message = self.ledger.failure(task.key)
            record["images"].append({"key": task.key, "status": "known-failed",
                                     "files": list(task.files), "stage": stage,
                                     "message": message, "attempts": attempts})
        self.counts["retried"] += bool(retried)
        if has_job:
            self.pending[asset.name] = record
        elif known:
            self._finish(record, "known_failed")
        else:
            self.counts["skipped"] += 1
            self._write_asset_files(record)

    def start_progress(self):
        done = self.counts["skipped"] + self.counts["known_failed"]
        mode = "none" if self.opts.quiet else self.opts.progress
        if mode == "jsonl":
            self.progress = JsonProgress(self.total, done, self.progress_file or sys.stderr)
        else:
            self.progress = BatchProgress(self.total, done, enabled=mode == "bar")

    def on_image(self, image):
        """Record one image's result and put its files in place (called as each image
        finishes or fails).

        A done image's staged files (``staged``: temporary names, see
        :mod:`rtmesh.batch.publish`) are checked, its ledger row is committed, and only
        then are they renamed into place; those of an image not recorded as done are
        removed.  ``side_files`` (the asset's metadata file) are put in place first, so
        that an asset with a recorded image has them.
        """
        record = self.pending.get(image.get("asset")) if "asset" in image else None
        staged = image.get("staged") or []
        try:
            publish(self.outdir, image.get("side_files") or ())
        except OSError as exc:
            image = _failed(image, "write", f"cannot put {exc.filename} in place: {exc.strerror}")
        if image["status"] == "done":
            problem = self._not_visible(image, staged)
            if problem:
                image = _failed(image, "storage", f"output not visible to the submitting machine: {problem}")
        self._record(image)
        if image["status"] == "done" and staged:
            # the row is durable before the files appear: a kill in between leaves their
            # temporaries, which the next run rolls forward, never an image without its row
            self.ledger.commit()
            try:
                publish(self.outdir, zip(staged, image["files"]))
            except OSError as exc:
                image = _failed(image, "write", f"cannot put {exc.filename} in place: {exc.strerror}")
                self._record(image)
        if image["status"] != "done":
            discard(self.outdir, staged)
        if (self.opts.contact_sheet or self.opts.annotations) and image["status"] == "done":
            self.sheet.append((image["key"], image["files"]))
        if record is not None:
            record["images"].append({k: image[k] for k in ("key", "status", "files", "seconds",
                                                          "stage", "message") if k in image})

    def _record(self, image):
        self.ledger.record(image["key"], image.get("asset", ""), image["fingerprint"],
                           image["status"], inputs=image.get("inputs", ()),
                           outputs=image.get("outputs", ()), seconds=image["seconds"],
                           run=image.get("run", ""), stage=image.get("stage"),
                           message=image.get("message"))

    def _not_visible(self, image, staged):
        """Why the image's files (at their ``staged`` names, if given) do not match what the
        worker reported, or ""."""
        outputs = image.get("outputs") or []
        for i, entry in enumerate(outputs):
            path = os.path.join(self.outdir, staged[i] if staged else entry[0])
            try:
                size = os.stat(path).st_size
            except OSError:
                return f"{entry[0]} is missing"
            if size != entry[1]:
                return f"{entry[0]} has {size} bytes, the worker wrote {entry[1]}"
            if self.check_content and not unchanged(entry, path):
                return f"{entry[0]} differs from what the worker wrote"
            # record this machine's view of the file (its time, for --trust-mtime resumes;
            # a rename keeps it)
            entry[2] = os.stat(path).st_mtime_ns
        if len(outputs) != len(image["files"]) or (staged and len(staged) != len(outputs)):
            return "the worker reported no file"
        return ""

    def on_job(self, result):
        """Close one asset (after its images): count it, commit, report, show progress."""
        record = self.pending.pop(result["asset"], None)
        if record is None:
            return
        self.finished_jobs += 1
        record["seconds"] = result["seconds"]
        failed = any(i["status"] == "failed" for i in record["images"])
        self.counts["images"] += sum(i["status"] == "done" for i in record["images"])
        self._finish(record, "failed" if failed else "done")

    def _write_asset_files(self, record):
        """The asset's dataset files and turntable movie, once all its images are there
        (done or skipped)."""
        images = record["images"]
        if not images or any(i["status"] not in ("done", "skipped") for i in images):
            return
        if self.opts.dataset:
            # by image key: the views of a set and the frames of a turntable in order
            write_dataset(self.opts.dataset, self.outdir, record["asset"], sorted(images, key=lambda i: i["key"]),
                          source=record["path"], units=self.opts.units)
        frames = movie_frames(self.outdir, images)
        if self.opts.movie and len(frames) > 1 and all(".turn" in i["key"] for i in images):
            write_movie(os.path.join(self.outdir, f"{record['asset']}.turntable.{self.opts.movie}"), frames,
                        self.opts.movie)

    def _finish(self, record, status):
        record["status"] = status.replace("_", "-")
        record["errors"] = [{"image": i["key"], "stage": i.get("stage"), "message": i.get("message")}
                            for i in record["images"] if i["status"] in ("failed", "known-failed")]
        self.counts[status] += 1
        if status == "done":
            self._write_asset_files(record)
        self.ledger.commit()
        self.assets.append(record)
        self._report.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._report.flush()
        if self.progress is not None:
            self.progress.update(record)

    def close(self):
        if self.progress is not None:
            self.progress.close()
        if self.progress_file is not None:
            self.progress_file.close()
        self._report.close()

    def report(self, wall_seconds, runner, run):
        per_minute = 60.0 * self.counts["done"] / wall_seconds if wall_seconds > 0 else 0.0
        extra = {"outdir": self.outdir, "run": run, "report": os.path.join(self.outdir, REPORT_NAME),
                 "started": time.strftime("%Y-%m-%dT%H:%M:%S%z",
                                          time.localtime(time.time() - wall_seconds))}
        return BatchReport(dict(self.counts), self.assets, wall_seconds, per_minute, runner,
                           extra=extra)


def _failed(image, stage, message):
    """``image`` turned into a failure (its files are not recorded)."""
    return {**image, "status": "failed", "stage": stage, "outputs": [], "message": message}
