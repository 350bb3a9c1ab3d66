"""Where ``r2rsim diagnose -o`` and ``r2rsim bench -o`` write their results, and what they
may replace.

The rules of the dataset writer (:func:`r2rsim.dataset.writer.check_output`) and of
``r2rsim report``: a directory that does not exist, or an empty one, is filled; a directory
holding only results r2rsim wrote is replaced, and only when asked (``overwrite``); anything
else is refused and left as it is. A results directory has no manifest, so each file is
recognised by its name and its content: a Parquet file or CSV header with the columns r2rsim
writes, a ``datasets.json`` of test datasets, a report that starts with the report's marker.
The files are written into a temporary directory next to the output and moved in when every
one is complete, so a failure leaves no partial results.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from ..dataset.paths import occupied_output, read_json
from ..errors import InputError

#: first line of every ``r2rsim report`` page (an existing file without it is not replaced)
REPORT_MARKER = "<!-- written by r2rsim report -->"
#: the report ``r2rsim report RESULTS_DIR`` writes into a results directory by default
REPORT_FILE = "report.html"
#: the file of a diagnose results directory that names the test datasets
DATASETS_FILE = "datasets.json"
#: largest datasets.json read (a list of absolute paths; 16 MiB holds over 100 000)
DATASETS_FILE_MAX_BYTES = 16 << 20

_TABLE = {"condition", "fault", "magnitude", "metric", "value"}
#: the files each command writes into its results directory, with the columns that mark a
#: table as its own (None: not a table)
FILES: dict[str, dict[str, set[str] | None]] = {
    "diagnose": {
        "predictions.parquet": {"run_id", "k", "t_s", "statistic", "alarm", "method"},
        "metrics.parquet": _TABLE | {"method"},
        "metrics.csv": _TABLE | {"method"},
        DATASETS_FILE: None,
    },
    "bench": {
        "results.parquet": _TABLE | {"study", "label"},
        "results.csv": _TABLE | {"study", "label"},
    },
}


def _columns(path: Path) -> set[str]:
    """The column names of a Parquet file or of a CSV's first line (empty: not readable)."""
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        try:
            return set(pq.read_schema(path).names)
        except Exception:  # noqa: BLE001 - pyarrow raises several types on bad files
            return set()
    try:
        with open(path, "rb") as f:
            first = f.readline(1 << 16).decode("utf-8", "replace")
    except OSError:
        return set()
    return set(first.strip().split(","))


def _is_own(path: Path, kind: str) -> bool:
    """Whether ``path`` is a file r2rsim ``kind`` (or ``r2rsim report``) writes there."""
    if path.is_symlink() or not path.is_file():
        return False
    if path.name == REPORT_FILE:
        try:
            with open(path, "rb") as f:
                return f.read(len(REPORT_MARKER)) == REPORT_MARKER.encode()
        except OSError:
            return False
    if path.name not in FILES[kind]:
        return False
    if path.name == DATASETS_FILE:
        try:
            data = read_json(path, DATASETS_FILE_MAX_BYTES)
        except (OSError, ValueError):
            return False
        return isinstance(data, dict) and isinstance(data.get("test"), list)
    columns = FILES[kind][path.name]
    return columns is not None and columns <= _columns(path)


def check_results_output(output: str | Path, kind: str, overwrite: bool = False) -> None:
    """Refuse an output directory that the results of ``r2rsim diagnose`` or ``r2rsim bench``
    must not be written to (the rules of the module docstring).

    Parameters
    ----------
    output : str or Path
        The results directory.
    kind : {"diagnose", "bench"}
        The command writing it.
    overwrite : bool
        Replace a directory that holds only that command's results.

    Raises
    ------
    InputError
        Saying why and what to do.
    """
    out = Path(output)
    if not occupied_output(out):
        return  # absent or empty: filled
    foreign = [p.name for p in sorted(out.iterdir()) if not _is_own(p, kind)]
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise InputError(
            f"output directory '{out}' exists and holds files r2rsim {kind} did "
            f"not write ({foreign[0]}{more}); r2rsim replaces only a directory "
            f"holding its own {kind} results: choose another directory with -o"
        )
    if not overwrite:
        raise InputError(
            f"output directory '{out}' holds earlier r2rsim {kind} results; pass "
            f"--overwrite to replace them"
        )


def write_results(
    output: str | Path,
    kind: str,
    files: dict[str, Callable[[Path], object]],
    overwrite: bool = False,
) -> Path:
    """Write a results directory: check it (:func:`check_results_output`), write every file
    into a temporary directory next to it, then move them in, replacing the earlier results
    (and their report, which described them).

    Parameters
    ----------
    output : str or Path
        The results directory; its parent directories are made if needed.
    kind : {"diagnose", "bench"}
    files : dict
        File name -> a function writing that file at the path it is given.
    overwrite : bool
        Replace earlier results of the same command.

    Returns
    -------
    Path
        The results directory.
    """
    out = Path(output)
    check_results_output(out, kind, overwrite)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.results-"))
    try:
        for name, write in files.items():
            write(tmp / name)
        if not out.exists():
            os.chmod(tmp, 0o755)  # mkdtemp's 0700 is for the temporary directory only
            os.rename(tmp, out)
            return out
        check_results_output(out, kind, overwrite)  # still only ours
        for name in [*FILES[kind], REPORT_FILE]:
            (out / name).unlink(missing_ok=True)
        for name in files:
            os.replace(tmp / name, out / name)
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
