"""A campaign folder on disk: its layout, its lock, and what each point has finished.

Layout::

    campaign/
      plan.toml                  the plan as given (a byte copy), for the record
      .lock                      held (flock) while a 'campaign run' works here
      points/01_180rpm/
        recording.h5             acquire
        measured.nc              process
        report.html  summary.json  cycles.nc      compare
        point.json               what is finished, with the inputs it was made from
      campaign.html  campaign.json  campaign.csv  the cross-point page and table

``point.json`` lists, per finished step, the sha256 of its inputs (the plan's part it depends on
and the files it read) and of each output file. A step counts as finished only when that record
exists, its inputs are today's and every output still has its recorded sha256; the record is
written (atomically) after the outputs, so a kill at any moment leaves either a finished step or
one that is redone.
"""
from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
from pathlib import Path

from labtool.common.errors import FileFormatError, InputError
from labtool.common.files import atomic_write
from labtool.common.names import shown

POINT_FORMAT = "labtool.campaign.point"
STEPS = ("acquire", "process", "compare")
OUTPUTS = {"acquire": ("recording.h5",), "process": ("measured.nc",),
           "compare": ("report.html", "summary.json", "cycles.nc")}


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def sha256_json(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def write_json(path: Path, obj) -> None:
    text = json.dumps(obj, indent=1, sort_keys=True, allow_nan=False)
    atomic_write(Path(path), lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))


class CampaignLock:
    """An exclusive lock on a campaign folder (fcntl.flock on ``.lock``): a second 'campaign run'
    on the same folder is refused with one line instead of both writing the same points."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / ".lock"
        self.fd = None

    def __enter__(self):
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EACCES):
                raise
            try:
                other = self.path.read_text().strip()[:20]
            except OSError:
                other = "?"
            os.close(self.fd)
            self.fd = None
            raise InputError(f"{shown(self.path.parent)} is being run by another 'labtool campaign run' (pid {other or '?'}); "
                             "wait for it to finish, or use another output folder") from None
        os.ftruncate(self.fd, 0)
        os.write(self.fd, str(os.getpid()).encode())
        return self

    def __exit__(self, *exc):
        if self.fd is not None:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = None
        return False


class PointState:
    """The finished steps of one point (``point.json``)."""

    def __init__(self, folder: Path, name: str, spec: dict):
        self.folder = Path(folder)
        self.name = name
        self.spec = spec
        self.steps: dict[str, dict] = {}
        # the acquisition under way: its inputs and the token its recording carries, so that a run
        # killed between the recording's end and its record finds that recording its own
        self.acquiring: dict | None = None
        self.file = self.folder / "point.json"

    @classmethod
    def load(cls, folder: Path, name: str, spec: dict) -> "PointState":
        st = cls(folder, name, spec)
        if not st.file.exists():
            return st
        if not st.file.is_file():              # a FIFO would block its reading for ever
            raise FileFormatError(f"{shown(st.file)} is not a regular file (a folder, a FIFO, a device); move the "
                                  "point's folder away to redo it")
        try:
            doc = json.loads(st.file.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError) as exc:
            raise FileFormatError(f"{shown(st.file)} is not readable JSON ({shown(str(exc))}); move the point's folder "
                                  "away to redo it") from None
        if not isinstance(doc, dict) or doc.get("format") != POINT_FORMAT or not isinstance(doc.get("steps"), dict):
            raise FileFormatError(f"{shown(st.file)} is not a labtool campaign point record")
        for step, rec in doc["steps"].items():
            if step in STEPS and not (isinstance(rec, dict) and isinstance(rec.get("inputs"), str)
                                      and isinstance(rec.get("outputs"), dict)
                                      and all(isinstance(v, str) for v in rec["outputs"].values())):
                raise FileFormatError(f"{shown(st.file)} is not a labtool campaign point record (its {step} step is "
                                      "not an inputs digest and a table of output digests); move the point's folder "
                                      "away to redo it")
        st.recorded_spec = doc.get("spec")
        st.steps = {k: v for k, v in doc["steps"].items() if k in STEPS and isinstance(v, dict)}
        started = doc.get("acquiring")
        if isinstance(started, dict) and all(isinstance(started.get(k), str) for k in ("inputs", "token")):
            st.acquiring = {"inputs": started["inputs"], "token": started["token"]}
        return st

    recorded_spec: dict | None = None

    def changed_keys(self) -> list[str]:
        """Keys of the point's spec that differ from the recorded one ([] if none recorded)."""
        old = self.recorded_spec
        if not isinstance(old, dict):
            return []
        return sorted(k for k in set(old) | set(self.spec) if old.get(k) != self.spec.get(k))

    def finished(self, step: str, inputs: str) -> bool:
        rec = self.steps.get(step)
        if not rec or rec.get("inputs") != inputs:
            return False
        outs = rec.get("outputs", {})
        if set(outs) != set(OUTPUTS[step]):
            return False
        for name, digest in outs.items():
            p = self.folder / name
            if not p.is_file() or sha256_file(p) != digest:
                return False
        return True

    def output_digest(self, step: str, name: str) -> str:
        return self.steps[step]["outputs"][name]

    def record(self, step: str, inputs: str, info: dict) -> None:
        """Mark ``step`` finished (its outputs hashed now) and forget the steps after it."""
        outs = {n: sha256_file(self.folder / n) for n in OUTPUTS[step]}
        later = STEPS[STEPS.index(step) + 1:]
        for s in later:
            self.steps.pop(s, None)
        self.steps[step] = {"inputs": inputs, "outputs": outs, "info": info}
        if step == "acquire":
            self.acquiring = None
        self.save()

    def begin_acquisition(self, inputs: str, token: str) -> None:
        """Say (in point.json, before the recording starts) which acquisition is under way."""
        self.acquiring = {"inputs": inputs, "token": token}
        self.save()

    def forget_from(self, step: str) -> None:
        for s in STEPS[STEPS.index(step):]:
            self.steps.pop(s, None)
        self.save()

    def done(self) -> bool:
        return all(s in self.steps for s in STEPS)

    def save(self) -> None:
        doc = {"format": POINT_FORMAT, "format_version": 1, "name": self.name, "spec": self.spec, "steps": self.steps}
        if self.acquiring is not None:
            doc["acquiring"] = self.acquiring
        write_json(self.file, doc)


def clean_partials(folder: Path) -> list[str]:
    """Remove the hidden ``.NAME.xxxx.part`` files a killed atomic write leaves; their names."""
    gone = []
    for p in Path(folder).glob(".*.part"):
        try:
            p.unlink()
            gone.append(p.name)
        except OSError:
            pass
    return gone
