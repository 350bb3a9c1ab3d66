"""The line a run was simulated on, as a plug-in sees it.

A dataset keeps a copy of its line file in ``scenario/`` (a sweep also keeps its sweep file in
``sweep/``, whose ``set:`` and whose runs' axis values, ``runs.overrides_json``, may change
the line: ``line.web.thickness``). :func:`run_line_data` rebuilds each run's line from them,
and the harness attaches it to every frame it hands a plug-in, as YAML-free JSON text in
``frame.attrs[LINE_ATTR]`` (a string: pandas copies ``attrs`` with every frame operation, and
copying a string costs nothing). A plug-in reads it with :func:`frame_line`, which returns the
validated :class:`r2rsim.schema.line.Line` (every quantity in SI), or None for data without a
line (a frame built by hand, or a dataset without its ``scenario/`` copy).
"""

from __future__ import annotations

import copy
import json
from functools import lru_cache
from pathlib import Path

import pandas as pd

from ..errors import InputError
from ..schema import paths as _paths
from ..schema.loader import load_line, read_yaml

__all__ = ["LINE_ATTR", "attach_line", "frame_line", "named", "run_line_data"]

#: the key of a frame's ``attrs`` that holds its run's line (JSON text of the line mapping)
LINE_ATTR = "r2rsim.line"


@lru_cache(maxsize=64)
def _line_files(scenario_dir: str) -> tuple[tuple[str, str], ...]:
    """(name, JSON text) of every line file in a dataset's ``scenario/`` copy."""
    out = []
    for p in sorted(Path(scenario_dir).glob("*.yaml")):
        if p.name.endswith(".normalised.yaml"):
            continue
        data = read_yaml(p)
        if isinstance(data, dict) and "elements" in data:
            out.append((str(data.get("name", p.stem)), json.dumps(data, default=str)))
    return tuple(out)


@lru_cache(maxsize=64)
def _sweep_set(sweep_dir: str) -> tuple[tuple[str, str], ...]:
    """The ``line.`` keys of the ``set:`` of a dataset's sweep-file copy, as (path, JSON)."""
    files = sorted(Path(sweep_dir).glob("*.yaml"))
    if not files:
        return ()
    data = read_yaml(files[0])
    items = (data.get("set") or {}).items() if isinstance(data, dict) else ()
    return tuple(
        (k, json.dumps(v, default=str))
        for k, v in items
        if isinstance(k, str) and k.startswith("line.")
    )


@lru_cache(maxsize=256)
def _built(scenario_dir: str, sweep_dir: str, name: str | None, overrides: str) -> str | None:
    files = _line_files(scenario_dir)
    chosen = [t for n, t in files if n == name] or ([files[0][1]] if len(files) == 1 else [])
    if not chosen:
        return None
    line = json.loads(chosen[0])
    changes = [(k, json.loads(v)) for k, v in _sweep_set(sweep_dir)]
    changes += [(k, v) for k, v in json.loads(overrides or "{}").items() if k.startswith("line.")]
    for path, value in changes:  # in the order the sweep applied them: set:, then the axes
        _, parts = _paths.split_root(path)
        if value is None and not isinstance(parts[-1], int):
            _paths.remove(line, parts)
        else:
            _paths.set_value(line, parts, copy.deepcopy(value))
    return json.dumps(line, default=str, sort_keys=True)


def run_line_data(run) -> dict | None:
    """The mapping of the line a run was simulated on, as the dataset recorded it.

    Parameters
    ----------
    run : r2rsim.dataset.read.Run
        A run read from a dataset.

    Returns
    -------
    dict or None
        The line file's mapping (quantities as written, e.g. ``"50 um"``) with the sweep's
        ``set:`` and the run's own ``line.`` axis values applied; None when the dataset holds
        no copy of its line (or holds several and none is named ``runs.line_config``).
    """
    text = _run_line_text(run)
    return None if text is None else json.loads(text)


def _run_line_text(run) -> str | None:
    """:func:`run_line_data` as JSON text (cached per dataset, line and overrides)."""
    root = Path(run.path)
    scen = root / "scenario"
    if not scen.is_dir():
        return None
    info = run.info or {}
    overrides = info.get("overrides_json")
    return _built(
        str(scen),
        str(root / "sweep"),
        info.get("line_config"),
        overrides if isinstance(overrides, str) else "",
    )


def attach_line(frame: pd.DataFrame, run) -> pd.DataFrame:
    """Put the run's line (:func:`run_line_data`, as JSON text) in ``frame.attrs``; returns
    the frame. A run without a recorded line leaves the frame as it is."""
    text = _run_line_text(run)
    if text is not None:
        frame.attrs[LINE_ATTR] = text
    return frame


@lru_cache(maxsize=64)
def _validated(text: str):
    return load_line(json.loads(text), file="<the run's line>")


def frame_line(frame: pd.DataFrame):
    """The validated line of the run a frame comes from, or None.

    Parameters
    ----------
    frame : pandas.DataFrame
        A frame the harness handed the plug-in (or any frame: without the attribute the
        answer is None).

    Returns
    -------
    r2rsim.schema.line.Line or None
        Every quantity in SI (``line.web.modulus`` in Pa, ``line.spans[i].length`` in m).
    """
    text = getattr(frame, "attrs", {}).get(LINE_ATTR)
    return _validated(text) if isinstance(text, str) else None


def named(items, given: str, plugin: str, role: str, kind: str, plural: str):
    """The item of ``items`` (elements, spans or sensors of a line) whose id is ``given``: a
    role a plug-in's parameter names. Otherwise one :class:`InputError` naming the plug-in,
    the parameter and the line's candidates, e.g. ``parity: load_cell 'lc9' is not a load
    cell of the line (load cells: sensor_A, lc_unwind)``."""
    for x in items:
        if x.id == given:
            return x
    raise InputError(
        f"{plugin}: {role} '{given}' is not {kind} of the line ({plural}: "
        f"{', '.join(str(x.id) for x in items) or 'none'})"
    )
