"""Checking a dataset against its manifest.json while it is read: the one verifier of every
reader (:func:`r2rsim.dataset.read.read_runs`, so ``r2rsim diagnose``, ``bench`` and
``report``, and the figures of ``r2rsim plot``).

What it checks (docs/dataset.md, "What every reader checks"):

* the directory is not an unfinished sweep (:data:`~r2rsim.dataset.paths.SWEEP_MARKER`);
* manifest.json is there and readable, and every file it lists exists with its size (all
  of them, when the dataset is opened: a ``stat`` each);
* a file that is read is listed in the manifest (a file added later is never read) and has
  its sha256, hashed over the whole file once per :class:`Verifier`, however little of it
  the reader parses.

A file read whole is hashed from the same bytes that are parsed (:meth:`Verifier.read`). A
file read in part (the footer, a column, some row groups of a run's samples) is hashed by
:meth:`Verifier.start` in a background thread while the reader parses it (hashlib releases
the GIL), and :meth:`Verifier.check` waits for the result: call it before anything read is
returned. Every refusal is one :class:`~r2rsim.errors.InputError` line naming the dataset,
the file (and run) and the problem, and saying that ``--no-verify`` reads it anyway.
"""

from __future__ import annotations

import hashlib
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from ..errors import InputError
from .paths import SWEEP_MARKER, read_json

#: the override every refusal names
NO_VERIFY = "--no-verify reads it anyway"
#: hash files read in part in a background thread (False: hash them in the caller's thread
#: when :meth:`Verifier.start` is called; benchmarks/bench_verify.py compares the two)
HASH_IN_THREAD = True
_BLOCK = 1 << 20


def refuse_unfinished(path: Path) -> None:
    """An unfinished sweep's directory (interrupted, or still running) is not a dataset."""
    if (Path(path) / SWEEP_MARKER).is_file():
        raise InputError(
            f"dataset {path}: an unfinished sweep (interrupted, or still "
            f"running): run the same `r2rsim sweep` command again to finish it"
        )


def run_of(rel: str) -> str | None:
    """The run a dataset file belongs to (``samples/run_id=<id>/...``), else None."""
    part = rel.split("/")
    if len(part) > 2 and part[0] == "samples" and part[1].startswith("run_id="):
        return part[1][len("run_id=") :]
    return None


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(_BLOCK), b""):
            h.update(block)
    return h.hexdigest()


class Verifier:
    """The files of one dataset checked against its manifest.json as they are read.

    With ``verify`` false every method reads without checking (the files must still exist).
    Use it as a context manager, or call :meth:`close`: it stops the hashing thread.

    Parameters
    ----------
    root : Path
        The dataset directory.
    verify : bool
        Check; when true, manifest.json is read and every listed file's size compared here.
    """

    def __init__(self, root: Path, verify: bool = True):
        self.root = Path(root)
        self.verify = verify
        self.files: dict[str, tuple[str, int | None]] = {}
        self._hashed: set[str] = set()  # files whose sha256 matched
        self._pending: dict[str, tuple[Future, str | None]] = {}
        self._pool: ThreadPoolExecutor | None = None
        if verify:
            self._check_manifest()

    def __enter__(self) -> Verifier:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop the hashing thread (a hash still running is waited for, not checked)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        self._pending.clear()

    def fail(self, msg: str, run: str | None = None) -> InputError:
        """The refusal: one line naming the dataset, the run if any, and ``msg``."""
        return InputError(f"dataset {self.root}: {f'run {run}: ' if run else ''}{msg}")

    def _check_manifest(self) -> None:
        mf = self.root / "manifest.json"
        if not mf.is_file():
            raise self.fail(
                "no manifest.json, so its files cannot be checked: not a "
                f"complete r2rsim dataset ({NO_VERIFY})"
            )
        try:
            manifest: Any = read_json(mf)  # whatever the file holds: checked by using it
            files = manifest["files"]
            items = [
                (str(rel), str(info["sha256"]), info.get("bytes")) for rel, info in files.items()
            ]
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise self.fail(
                f"manifest.json is not readable ({type(exc).__name__}: "
                f"{str(exc).splitlines()[0] if str(exc) else ''}); "
                f"{NO_VERIFY}"
            ) from None
        self.files = {rel: (sha, size) for rel, sha, size in items}
        for rel, (_, size) in self.files.items():
            f = self.root / rel
            if not f.is_file():
                raise self.fail(
                    f"{rel} is missing (listed in manifest.json): the directory "
                    f"is not a complete r2rsim dataset ({NO_VERIFY})",
                    run_of(rel),
                )
            if size is not None and f.stat().st_size != size:
                raise self.fail(
                    f"{rel} has {f.stat().st_size} bytes, manifest.json says "
                    f"{size}: the file was changed or truncated after it was "
                    f"written; refusing to use it (`r2rsim validate "
                    f"{self.root}` lists every problem; {NO_VERIFY})",
                    run_of(rel),
                )

    def listed(self, rel: str, run: str | None = None) -> None:
        """Refuse a file manifest.json does not list (it was added after the writing)."""
        if self.verify and rel not in self.files:
            raise self.fail(
                f"{rel} is not listed in manifest.json: it was added after the "
                f"dataset was written; refusing to use it ({NO_VERIFY})",
                run or run_of(rel),
            )

    def _compare(self, rel: str, digest: str, run: str | None) -> None:
        if digest != self.files[rel][0]:
            raise self.fail(
                f"{rel}: checksum differs from manifest.json: the file was "
                f"changed after it was written; refusing to use it (`r2rsim "
                f"validate {self.root}` lists every problem; {NO_VERIFY})",
                run or run_of(rel),
            )
        self._hashed.add(rel)

    def read(self, rel: str, run: str | None = None) -> bytes:
        """The whole file, checked: its sha256 is computed from the bytes returned, so what
        is parsed is what was hashed (a file already checked is not hashed again)."""
        self.listed(rel, run)
        data = (self.root / rel).read_bytes()
        if self.verify and rel not in self._hashed:
            self._compare(rel, hashlib.sha256(data).hexdigest(), run)
        return data

    def start(self, rel: str, run: str | None = None, data: bytes | None = None) -> None:
        """Begin checking a file that is read in part (or ``data``, its bytes as read): its
        sha256 is computed in a background thread; :meth:`check` waits for it."""
        self.listed(rel, run)
        if not self.verify or rel in self._hashed or rel in self._pending:
            return
        if not HASH_IN_THREAD:
            digest = (
                hashlib.sha256(data).hexdigest()
                if data is not None
                else _sha256_file(self.root / rel)
            )
            self._compare(rel, digest, run)
            return
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="r2rsim-hash")
        job = (
            (lambda: hashlib.sha256(data).hexdigest())
            if data is not None
            else (lambda: _sha256_file(self.root / rel))
        )
        self._pending[rel] = (self._pool.submit(job), run)

    def check(self, rel: str | None = None) -> None:
        """Wait for the checksum of ``rel`` (default: of every file begun), and refuse the
        first that differs from manifest.json (in the order they were begun)."""
        names = [rel] if rel is not None else list(self._pending)
        for name in names:
            if name not in self._pending:
                continue
            fut, run = self._pending.pop(name)
            try:
                digest = fut.result()
            except OSError as exc:
                raise self.fail(
                    f"{name} cannot be read ({exc.strerror or exc})", run or run_of(name)
                ) from None
            self._compare(name, digest, run)
