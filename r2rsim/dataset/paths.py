"""Where the dataset writer may write, what it may replace and what it may clean up.

Three rules keep ``r2rsim run`` from touching files it did not write:

* every path the writer builds stays inside its temporary dataset directory
  (:func:`inside`, :func:`safe_component`);
* an existing output directory is replaced only if it is verifiably an r2rsim dataset
  (:func:`dataset_problems` is empty: its ``manifest.json`` lists every file in it, with
  sizes and sha256, and nothing else is there), and only when asked (``overwrite``);
* a temporary directory ``.NAME.tmp-PID`` (or a dataset being replaced, ``.NAME.old-PID``)
  left by a process that no longer exists is cleaned up on the next write into the same
  parent directory (:func:`clean_stale`); nothing else is ever removed.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
from pathlib import Path, PurePosixPath

from ..errors import InputError, R2RError

MANIFEST = "manifest.json"
#: the marker of an unfinished sweep's directory (r2rsim.sweep): not a dataset until it is gone
SWEEP_MARKER = ".r2rsim-sweep.json"
#: largest JSON file r2rsim reads back: its manifests, sweep marker and failure records (the
#: manifest of a 100 000-run sweep is tens of MB); a bound so a planted file cannot exhaust
#: memory
MAX_JSON_BYTES = 256 << 20
#: r2rsim's own temporaries next to a dataset: ``.NAME.tmp-PID`` while a run writes,
#: ``.NAME.old-PID`` for the dataset an ``--overwrite`` run replaces, during the swap
TEMP_RE = re.compile(r"^\.(?P<name>.+)\.(?P<kind>tmp|old)-(?P<pid>[1-9][0-9]{0,9})$")
# ---------------------------------------------------------------- the dataset's layout
# One list of what a dataset holds (docs/dataset.md §1). The run's writer, the sweep's
# finalisation, the cleanup of dead processes' temporaries and `r2rsim validate` all use it,
# so a file added to the layout is known to every one of them.

#: ``<name>.parquet`` tables at the top of every dataset (a run's and a sweep's)
RUN_TABLES = ("runs", "channels", "faults", "events", "variability")
#: tables only a sweep's dataset holds
SWEEP_TABLES = ("failures",)
#: directory of the samples: ``samples/run_id=<id>/part-0.parquet``
SAMPLES = "samples"
#: directories of copies of the input files: a run's ``scenario/`` (the scenario and its
#: line), and a sweep's ``sweep/`` (the sweep file)
RUN_COPIES = ("scenario",)
SWEEP_COPIES = ("scenario", "sweep")
#: the files at the top of a dataset
TOP_FILES = frozenset({f"{t}.parquet" for t in RUN_TABLES + SWEEP_TABLES} | {MANIFEST})


def samples_file(run_id: str) -> str:
    """The samples file of a run, relative to the dataset."""
    return f"{SAMPLES}/run_id={run_id}/part-0.parquet"


def layout_problem(rel: str, *, sweep: bool) -> str | None:
    """Why ``rel`` (a path relative to a dataset, ``/``-separated) is not a file r2rsim
    writes there (None: it is). ``sweep``: the layout of a sweep's dataset, else a run's
    (the same, without ``failures.parquet`` and ``sweep/``)."""
    parts = rel.split("/")
    if len(parts) == 1:
        ok = rel in TOP_FILES and (sweep or rel[: -len(".parquet")] not in SWEEP_TABLES)
    elif parts[0] == SAMPLES:
        ok = (
            len(parts) == 3
            and parts[1].startswith("run_id=")
            and safe_component(parts[1][len("run_id=") :])
            and parts[2] == "part-0.parquet"
        )
    else:
        ok = (
            len(parts) == 2
            and parts[0] in (SWEEP_COPIES if sweep else RUN_COPIES)
            and safe_component(parts[1])
        )
    return None if ok else "not a file of the r2rsim dataset layout"


def _layout_dir(rel: str, *, sweep: bool) -> bool:
    """Whether ``rel`` is a directory of the dataset layout (one that holds its files)."""
    parts = rel.split("/")
    if parts[0] == SAMPLES:
        return len(parts) == 1 or (len(parts) == 2 and parts[1].startswith("run_id="))
    return len(parts) == 1 and rel in (SWEEP_COPIES if sweep else RUN_COPIES)


#: temporary directories in use by writers of this process (a process that reuses the PID
#: of a dead one, as the first process of a container does, must still clean its leftovers)
ACTIVE: set[Path] = set()


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def safe_component(name: str) -> bool:
    """Whether ``name`` can be used as one directory or file name: not empty, not ``.`` or
    ``..``, no path separator and no NUL."""
    return (
        isinstance(name, str)
        and name not in ("", ".", "..")
        and not any(c in name for c in "/\\\0")
    )


def inside(base: Path, rel: str | Path) -> Path:
    """``base / rel``, checked to stay inside ``base`` once resolved.

    Parameters
    ----------
    base : Path
        The directory everything must stay in (the writer's temporary directory).
    rel : str or Path
        A path relative to ``base``.

    Returns
    -------
    Path
        The resolved path.

    Raises
    ------
    R2RError
        If the path resolves to ``base`` itself or to anywhere outside it (``..``
        components, an absolute path, a symbolic link that leads out).
    """
    root = Path(base).resolve()
    path = (root / rel).resolve()
    if path == root or not path.is_relative_to(root):
        raise R2RError(
            f"refusing to write '{rel}': it resolves to {path}, outside the "
            f"dataset directory {base}"
        )
    return path


def _relpath_problem(rel: object) -> str | None:
    """Why a manifest key cannot be a file of the dataset (None: it can)."""
    if not isinstance(rel, str) or not rel:
        return "which is not a relative path"
    p = PurePosixPath(rel)
    if p.is_absolute():
        return "an absolute path outside the dataset"
    if any(part in ("", ".", "..") for part in rel.split("/")) or "\\" in rel or "\0" in rel:
        return "a path that leaves the dataset or is not normalised"
    if rel == MANIFEST:
        return "the manifest itself"
    return None


def occupied_output(out: Path) -> bool:
    """Whether an output directory of r2rsim already holds something: False when it does
    not exist or is empty (it is filled), True when it holds entries (the caller decides
    whether they may be replaced).

    Raises
    ------
    InputError
        For a symbolic link or something that is not a directory (never replaced).
    """
    if out.is_symlink():
        raise InputError(
            f"output directory '{out}' is a symbolic link; give the directory "
            f"it points to, or another one, with -o"
        )
    if not out.exists():
        return False
    if not out.is_dir():
        raise InputError(f"output '{out}' exists and is not a directory; choose another with -o")
    return any(out.iterdir())


def check_writable(out: str | Path, *, inside_out: bool) -> None:
    """Refuse, before any work, an output directory that cannot be written.

    Parameters
    ----------
    out : str or Path
        The dataset directory (it may not exist yet).
    inside_out : bool
        True for a sweep, which writes inside ``out``: ``out`` (or, when it does not exist,
        its nearest existing ancestor) must be writable. False for a run, which writes its
        temporary directory next to ``out`` and renames it onto ``out``: the parent must be
        writable, and ``out`` must not be a mount point (a rename cannot replace one).

    Raises
    ------
    InputError
        Naming the output and the problem: a path under a file, a read-only file system, no
        permission to write, a mount point.
    """
    out = Path(out)
    start = out if inside_out else out.parent
    anc = Path(os.path.abspath(start))
    while not os.path.lexists(anc) and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(
            f"output '{out}': '{anc}' is a file, not a directory, so nothing "
            f"can be written under it; choose another directory with -o"
        )
    if not inside_out and out.is_dir() and not out.is_symlink() and os.path.ismount(out):
        raise InputError(
            f"output '{out}' is a mount point: a run writes its dataset next to "
            f"the output and moves it into place, which cannot replace a mount "
            f"point; give a directory inside it (-o {out / 'NAME'})"
        )
    if os.access(anc, os.W_OK | os.X_OK):
        return
    read_only = hasattr(os, "statvfs") and bool(os.statvfs(anc).f_flag & os.ST_RDONLY)
    why = "is on a read-only file system" if read_only else "is not writable (no permission)"
    raise InputError(f"output '{out}': '{anc}' {why}; choose another directory with -o")


def read_json(path: str | Path, limit: int = MAX_JSON_BYTES) -> object:
    """A JSON file that r2rsim wrote, bounded in size (``limit`` bytes).

    Raises
    ------
    OSError
        When it cannot be read.
    ValueError
        When it is larger than the bound, not UTF-8 or not JSON.
    """
    path = Path(path)
    if path.stat().st_size > limit:
        raise ValueError(f"{path.name} is larger than {limit >> 20} MiB")
    return json.loads(path.read_text(encoding="utf-8"))


def read_parquet_file(path: str | Path):
    """One Parquet file as a ``pyarrow.Table``.

    Unlike ``pyarrow.parquet.read_table``, it does not go through ``pyarrow.dataset`` (an
    import, and a dataset discovery per call: a third of the time of reading back a small
    table, which a run does for its self-check and a sweep for every run); the table is the
    same, schema metadata included.
    """
    import pyarrow.parquet as pq

    with pq.ParquetFile(path) as f:
        return f.read()


def read_manifest(root: Path) -> tuple[dict | None, str | None]:
    """``(manifest, None)`` or ``(None, why it is not an r2rsim manifest)``."""
    mpath = Path(root) / MANIFEST
    if mpath.is_symlink() or not mpath.is_file():
        return None, "no manifest.json"
    try:
        manifest = read_json(mpath)
    except (OSError, ValueError) as exc:
        return None, f"manifest.json is not readable JSON ({exc})"
    if (
        not isinstance(manifest, dict)
        or not isinstance(manifest.get("files"), dict)
        or "schema_version" not in manifest
    ):
        return None, "manifest.json is not an r2rsim manifest (no schema_version and files)"
    return manifest, None


def dataset_problems(root: str | Path, *, hashes: bool = True) -> list[str]:
    """Why the directory ``root`` is not verifiably a dataset written by r2rsim.

    The rule: ``manifest.json`` is an r2rsim manifest; every regular file under ``root``
    except the manifest is listed in it with its size in bytes (and, with ``hashes``, its
    sha256); every listed file is there; there are no symbolic links, special files or
    directories without a listed file, and no listed path leaves ``root``.

    Parameters
    ----------
    root : str or Path
    hashes : bool
        Also compare each file's sha256 (reads every byte; the sizes are always compared).

    Returns
    -------
    list of str
        The problems, each naming the file relative to ``root``; empty when ``root`` is a
        dataset exactly as r2rsim wrote it.
    """
    root = Path(root)
    manifest, why = read_manifest(root)
    if manifest is None:
        return [str(why)]  # read_manifest gives the reason with every None
    problems: list[str] = []
    listed: dict[str, dict] = {}
    for rel, info in manifest["files"].items():
        bad = _relpath_problem(rel)
        if bad is None and not isinstance(info, dict):
            bad = "without its sha256 and size"
        if bad:
            problems.append(f"manifest.json lists '{rel}', {bad}")
        else:
            listed[rel] = info
    present: dict[str, Path] = {}
    dirs: list[str] = []
    # os.walk does not follow symbolic links to directories; they are reported below
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        for name in [*dirnames, *filenames]:
            p = here / name
            rel = p.relative_to(root).as_posix()
            if p.is_symlink():
                problems.append(f"{rel}: a symbolic link (r2rsim writes none)")
            elif p.is_dir():
                dirs.append(rel)
            elif rel == MANIFEST:
                continue
            elif not p.is_file():
                problems.append(f"{rel}: not a regular file")
            elif rel not in listed:
                problems.append(f"{rel}: not listed in manifest.json")
            else:
                present[rel] = p
    for d in dirs:
        if not any(rel.startswith(d + "/") for rel in present):
            problems.append(f"{d}/: a directory with no file listed in manifest.json")
    for rel, info in listed.items():
        found = present.get(rel)
        if found is None:
            if not (root / rel).is_symlink():
                problems.append(f"{rel}: listed in manifest.json but missing")
            continue
        size = found.stat().st_size
        if size != info.get("bytes"):
            problems.append(
                f"{rel}: checksum differs from manifest.json (so does its size: "
                f"{size} bytes, not {info.get('bytes')})"
            )
        elif hashes and sha256_file(found) != info.get("sha256"):
            problems.append(f"{rel}: checksum differs from manifest.json")
    return problems


def remove_dataset(root: Path) -> None:
    """Remove a dataset that :func:`dataset_problems` has just found clean: the files its
    manifest lists, the manifest, then the directories that are left empty. Anything that
    appeared in the meantime stays (with the directories holding it)."""
    root = Path(root)
    manifest, _ = read_manifest(root)
    for rel in (manifest or {}).get("files", {}):
        if _relpath_problem(rel) is None:
            (root / rel).unlink(missing_ok=True)
    (root / MANIFEST).unlink(missing_ok=True)
    for dirpath, _, _ in os.walk(root, topdown=False):
        try:
            os.rmdir(dirpath)
        except OSError:
            pass  # not empty: something r2rsim did not write


def pid_alive(pid: int) -> bool:
    """Whether a process with this id exists (one of another user counts).

    On POSIX, ``os.kill(pid, 0)`` asks without sending anything; on Windows the same call
    would *end* the process, so the Win32 API is asked instead (:func:`_pid_alive_windows`).
    When in doubt the answer is True: a live process's files are never removed.
    """
    if not isinstance(pid, int) or pid <= 0:
        return True
    if os.name == "nt":
        return _pid_alive_windows(pid)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError, OSError):
        return True  # exists but is not ours, or no valid pid: leave its files alone
    return True


def _pid_alive_windows(pid: int) -> bool:
    """Windows: open the process for a query and read its exit code (STILL_ACTIVE while it
    runs). A process that cannot be opened because access is denied exists."""
    if sys.platform != "win32":  # pid_alive asks only there (and mypy checks it as such)
        return True
    import ctypes
    from ctypes import wintypes

    kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)
    kernel32.OpenProcess.restype = wintypes.HANDLE
    query_limited_information, still_active, access_denied = 0x1000, 259, 5
    handle = kernel32.OpenProcess(query_limited_information, False, wintypes.DWORD(pid))
    if not handle:
        return ctypes.get_last_error() == access_denied
    try:
        code = wintypes.DWORD()
        if not kernel32.GetExitCodeProcess(handle, ctypes.byref(code)):
            return True
        return code.value == still_active
    finally:
        kernel32.CloseHandle(handle)


def _looks_like_tmp(path: Path) -> bool:
    """Whether a directory holds nothing but what the writer puts in its temporary
    directory (:func:`layout_problem` of a run's dataset), so a foreign ``.x.tmp-123``
    directory is never removed."""
    for dirpath, dirnames, filenames in os.walk(path):
        here = Path(dirpath)
        for name in dirnames:
            rel = (here / name).relative_to(path).as_posix()
            if (here / name).is_symlink() or not _layout_dir(rel, sweep=False):
                return False
        for name in filenames:
            p = here / name
            if (
                p.is_symlink()
                or not p.is_file()
                or layout_problem(p.relative_to(path).as_posix(), sweep=False) is not None
            ):
                return False
    return True


def _owner_gone(pid: int, path: Path) -> bool:
    if pid == os.getpid():  # this process: stale unless one of its writers uses it
        return path.resolve() not in ACTIVE
    return not pid_alive(pid)


def clean_stale(parent: str | Path) -> list[Path]:
    """Clean up after r2rsim runs in ``parent`` whose process is gone (killed, power cut).

    * ``.NAME.tmp-PID``: a run's unfinished dataset. Removed if it holds only what the
      writer writes there.
    * ``.NAME.old-PID``: a dataset that ``--overwrite`` was replacing. Moved back to
      ``NAME`` if ``NAME`` does not exist (the swap did not finish), else removed if it is
      verifiably an r2rsim dataset.

    Directories of live processes, and anything else, are left alone.

    Returns
    -------
    list of Path
        What was removed or restored.
    """
    parent = Path(parent)
    done: list[Path] = []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return done
    for e in entries:
        m = TEMP_RE.match(e.name)
        if m is None or not e.is_dir(follow_symlinks=False):
            continue
        path = Path(e.path)
        if not _owner_gone(int(m["pid"]), path):
            continue
        try:
            if m["kind"] == "tmp":
                if _looks_like_tmp(path):
                    shutil.rmtree(path)
                    done.append(path)
                continue
            target = parent / m["name"]
            if not target.exists() and not target.is_symlink():
                os.rename(path, target)
                done.append(target)
            elif not dataset_problems(path):
                remove_dataset(path)
                done.append(path)
        except OSError:
            pass  # another process got there first, or no permission: not ours to force
    return done
