"""``r2rsim sweep``: how a sweep file expands into runs, the bad sweep files it refuses (with
nothing written), resuming after Ctrl-C, SIGTERM or kill -9, failed runs, reopening a finished
sweep, the three executors (serial, process pool, Dask) writing the same bytes, and reading the
dataset without r2rsim."""

from __future__ import annotations

import concurrent.futures
import hashlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from r2rsim import limits
from r2rsim.cli import main
from r2rsim.dataset.validate import validate_dataset
from r2rsim.errors import InputError
from r2rsim.sweep import plan_sweep, run_sweep

REPO = Path(__file__).resolve().parents[1]
QUICK = REPO / "scenarios" / "quickstart.yaml"
LINE = REPO / "lines" / "pet_film_line.yaml"

#: the quick-start sweep, shortened: 2 speeds x 2 offsets x 2 seeds = 8 runs of 2 s, the
#: offset on the rewind load cell from t = 1 s
QS_BODY = """\
set:
  duration: 2 s
  faults:
    - {id: lc_offset, type: sensor.offset, target: lc_rewind, onset: 1 s, magnitude: 5 N}
axes:
  - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 2 m/s]}
  - {name: offset, path: faults.lc_offset.magnitude, values: [-10 N, 10 N]}
seeds: 2
"""

#: 16 speeds x 2 seeds = 32 short runs: long enough as a whole to interrupt it half-way
MANY_BODY = """\
set: {duration: 2 s}
axes:
  - {name: speed, path: 'programme[0].line_speed', range: {start: 1 m/s, stop: 2.5 m/s, num: 16}}
seeds: 2
"""


# helpers ------------------------------------------------------------------------------------


def sweep_file(
    where: Path,
    body: str,
    *,
    name: str = "t",
    scenario: Path | str = QUICK,
    file: str = "sweep.yaml",
) -> Path:
    where.mkdir(parents=True, exist_ok=True)
    path = where / file
    path.write_text(
        f"name: {name}\nscenario: {scenario}\n" + textwrap.dedent(body), encoding="utf-8"
    )
    return path


def plan_of(tmp_path: Path, body: str, **kw):
    return plan_sweep(sweep_file(tmp_path, body, **kw))


def scenario_copy(where: Path, **changes) -> Path:
    """The quick-start scenario in ``where`` (its line by absolute path), keys changed."""
    d = yaml.safe_load(QUICK.read_text())
    d["line"] = str(LINE)
    d.update(changes)
    where.mkdir(parents=True, exist_ok=True)
    path = where / "base.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False), encoding="utf-8")
    return path


def cli(capsys, *args) -> tuple[int, str, str]:
    code = main(["sweep", *map(str, args), "-q"])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def hashes(root: Path, under: str = "") -> dict[str, str]:
    """sha256 of every file under ``root`` (hidden ones too), by relative path."""
    base = root / under if under else root
    return {p.relative_to(root).as_posix(): sha(p) for p in sorted(base.rglob("*")) if p.is_file()}


def snapshot(root: Path) -> dict[str, tuple]:
    """Every file and directory under ``root`` with its bytes' hash, inode and mtime."""
    out = {}
    for p in sorted([root, *root.rglob("*")]):
        st = p.stat()
        out[p.relative_to(root).as_posix()] = (
            sha(p) if p.is_file() else "dir",
            st.st_ino,
            st.st_mtime_ns,
        )
    return out


def runs_table(out: Path) -> dict[str, list]:
    t = pq.read_table(out / "runs.parquet")
    return {c: t[c].to_pylist() for c in t.column_names}


def assert_same_dataset(a: Path, b: Path) -> None:
    """The same files; every samples file and faults/events/channels/failures byte-identical;
    runs.parquet equal in every column but the wall-clock time."""
    ha, hb = hashes(a), hashes(b)
    assert sorted(ha) == sorted(hb)
    samples = [f for f in ha if f.startswith("samples/")]
    assert samples and all(f.endswith("/part-0.parquet") for f in samples)
    for f in [*samples, "faults.parquet", "events.parquet", "channels.parquet", "failures.parquet"]:
        assert ha[f] == hb[f], f
    ra, rb = runs_table(a), runs_table(b)
    assert list(ra) == list(rb)
    assert pq.read_table(a / "runs.parquet").schema == pq.read_table(b / "runs.parquet").schema
    for c in ra:
        if c != "wallclock_s":
            assert ra[c] == rb[c], c
    assert all(w > 0 for w in rb["wallclock_s"])
    ma = json.loads((a / "manifest.json").read_text())
    mb = json.loads((b / "manifest.json").read_text())
    assert ma["run_ids"] == mb["run_ids"] and ma["sweep"] == mb["sweep"]


def finished_runs(out: Path) -> list[str]:
    """The runs whose data is complete in the .work/ directory of an unfinished sweep."""
    work = out / ".work"
    if not work.is_dir():
        return []
    return sorted(e.name for e in os.scandir(work) if not e.name.startswith(".") and e.is_dir())


def children(pid: int) -> list[int]:
    text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    return [int(x) for x in text.split()]


def gone(pid: int) -> bool:
    """The process has exited (a zombie nobody reaps counts as exited)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


@pytest.fixture
def sweep_process():
    """Start ``r2rsim sweep`` in a process group of its own; whatever of it is left when the
    test ends (a worker that did not exit: the test failed) is killed."""
    started: list[tuple[subprocess.Popen, list[int]]] = []

    def start(sweep: Path, out: Path, *args) -> subprocess.Popen:
        proc = subprocess.Popen(
            [sys.executable, "-m", "r2rsim.cli", "sweep", str(sweep), "-o", str(out), "-q", *args],
            cwd=sweep.parent,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        started.append((proc, []))
        return proc

    def track(proc: subprocess.Popen) -> list[int]:
        """The sweep's child processes (its workers), killed at the end if still there."""
        pids = children(proc.pid)
        next(t for p, t in started if p is proc).extend(pids)
        return pids

    start.children = track
    yield start
    for proc, pids in started:
        for pid in [proc.pid, *pids]:
            if not gone(pid):
                os.kill(pid, signal.SIGKILL)
        if proc.returncode is None:
            proc.communicate(timeout=10)


def wait_for_runs(proc: subprocess.Popen, out: Path, n: int, timeout: float = 120) -> int:
    t0 = time.monotonic()
    while len(finished_runs(out)) < n:
        assert proc.poll() is None, f"the sweep ended early: {proc.communicate()}"
        assert time.monotonic() - t0 < timeout, "no runs finished"
        time.sleep(0.005)
    return len(finished_runs(out))


# shared datasets ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def qs(tmp_path_factory):
    """The 8-run quick-start sweep file and its dataset, run serially (workers=0)."""
    where = tmp_path_factory.mktemp("qs")
    sw = sweep_file(where, QS_BODY, name="qs")
    summary = run_sweep(sw, output=where / "serial", workers=0)
    assert summary.ok and summary.done == 8
    return sw, where / "serial"


@pytest.fixture(scope="module")
def many(tmp_path_factory):
    """The 32-run sweep and its dataset, run serially and uninterrupted."""
    where = tmp_path_factory.mktemp("many")
    sw = sweep_file(where, MANY_BODY, name="many")
    summary = run_sweep(sw, output=where / "reference", workers=0)
    assert summary.ok and summary.done == 32
    return sw, where / "reference"


# 1. expansion -------------------------------------------------------------------------------


def test_grid_crosses_axes_and_seeds_in_order(tmp_path):
    plan = plan_of(
        tmp_path,
        """\
        set: {duration: 2 s}
        axes:
          - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 2 m/s]}
          - {name: rate, path: 'programme[1].rate', values: [0.25 m/s^2, 0.5 m/s^2, 1 m/s^2]}
        seed: 7
        seeds: 2
        """,
    )
    assert plan.n_combinations == 6 and plan.seeds == [7, 8] and len(plan.runs) == 12
    got = [
        (r.combination, r.seed, r.columns["axis.speed"], r.columns["axis.rate"]) for r in plan.runs
    ]
    want = [
        (k, s, v, a)
        for k, (v, a) in enumerate([(v, a) for v in (1.0, 2.0) for a in (0.25, 0.5, 1.0)])
        for s in (7, 8)
    ]
    assert got == want
    # the values reach the scenario each run simulates
    r = plan.runs[11]
    assert r.scenario_data["programme"][0]["line_speed"] == "2 m/s"
    assert r.scenario_data["programme"][1]["rate"] == "1 m/s^2"
    assert r.scenario_data["duration"] == "2 s"  # set: applies to every run
    assert all(s.scenario_data["duration"] == "2 s" for s in plan.runs)
    ids = [r.run_id for r in plan.runs]
    assert len(set(ids)) == 12
    assert all(
        i.startswith("t__") and i.endswith(f"__s{r.seed}")
        for i, r in zip(ids, plan.runs, strict=True)
    )
    assert [a["column"] for a in plan.axes] == ["axis.speed", "axis.rate"]


def test_zip_takes_the_ith_values_together(tmp_path):
    plan = plan_of(
        tmp_path,
        """\
        set: {duration: 2 s}
        combine: zip
        axes:
          - {path: 'programme[0].line_speed', values: [1 m/s, 120 m/min, 3 m/s]}
          - {path: 'programme[1].line_speed', values: [4 m/s, 5 m/s, 6 m/s]}
        """,
    )
    # one seed: the base scenario's (1); default column names from the paths
    assert plan.seeds == [1] and plan.n_combinations == 3
    assert [
        (r.columns["axis.programme.0.line_speed"], r.columns["axis.programme.1.line_speed"])
        for r in plan.runs
    ] == [(1.0, 4.0), (2.0, 5.0), (3.0, 6.0)]


def test_random_draws_are_seeded(tmp_path):
    body = """\
        set: {duration: 2 s}
        combine: random
        n: 6
        seed: {seed}
        axes:
          - {name: speed, path: 'programme[0].line_speed', uniform: [1 m/s, 2 m/s]}
          - {name: rtol, path: solver.rtol, loguniform: [1.0e-7, 1.0e-5]}
          - {name: top, path: 'programme[1].line_speed', values: [3 m/s, 5 m/s]}
        """

    def draws(seed, where):
        plan = plan_of(tmp_path / where, body.replace("{seed}", str(seed)))
        assert len(plan.runs) == 6 and plan.seeds == [1]  # seed: seeds the draws only
        return [
            (r.columns["axis.speed"], r.columns["axis.rtol"], r.columns["axis.top"])
            for r in plan.runs
        ]

    a, b, c = draws(3, "a"), draws(3, "b"), draws(4, "c")
    more = plan_of(tmp_path / "f", body.replace("{seed}", "3").replace("n: 6", "n: 9"))
    first = plan_of(tmp_path / "g", body.replace("{seed}", "3"))
    # drawing more keeps the first draws (and their run ids): a reopened sweep adds runs
    assert [r.run_id for r in more.runs[:6]] == [r.run_id for r in first.runs]
    assert a == b  # the same seed draws the same values
    assert a != c
    for speed, rtol, top in a + c:
        assert 1.0 <= speed <= 2.0 and 1e-7 <= rtol <= 1e-5 and top in (3.0, 5.0)
    assert len({x[0] for x in a}) == 6  # continuous draws differ
    # log-uniform: spread over decades, not crowded near the top as a uniform draw would be
    logs = np.log10([x[1] for x in a + c + draws(5, "d") + draws(6, "e")])
    assert logs.min() < -6.3 and logs.max() > -5.7


@pytest.mark.parametrize(
    "rng,want",
    [
        ("{start: 1 m/s, stop: 2 m/s, num: 5}", [1.0, 1.25, 1.5, 1.75, 2.0]),
        ("{start: 60 m/min, stop: 180 m/min, step: 30 m/min}", [1.0, 1.5, 2.0, 2.5, 3.0]),
        ("{start: 1 m/s, stop: 2 m/s, step: 0.3 m/s}", [1.0, 1.3, 1.6, 1.9]),
        ("{start: 3, stop: 1, step: -1}", [3.0, 2.0, 1.0]),
        ("{start: 2 m/s, stop: 2 m/s, num: 1}", [2.0]),
    ],
)
def test_range(tmp_path, rng, want):
    plan = plan_of(
        tmp_path,
        f"""\
        set: {{duration: 2 s}}
        axes:
          - {{name: v, path: 'programme[0].line_speed', range: {rng}}}
        """,
    )
    got = [r.columns["axis.v"] for r in plan.runs]
    assert got == pytest.approx(want, abs=1e-12)
    # the values are set as SI numbers: the scenario reads them as m/s
    assert [r.scenario_data["programme"][0]["line_speed"] for r in plan.runs] == pytest.approx(
        want, abs=1e-12
    )


def test_seeds_as_a_count_a_list_or_the_base_scenario_seed(tmp_path):
    base = "set: {duration: 2 s}\n"
    assert plan_of(tmp_path / "a", base + "seeds: 3\nseed: 5\n").seeds == [5, 6, 7]
    assert plan_of(tmp_path / "b", base + "seeds: 3\n").seeds == [0, 1, 2]
    p = plan_of(tmp_path / "c", base + "seeds: [11, 3]\n")
    assert p.seeds == [11, 3] and [r.seed for r in p.runs] == [11, 3]
    p = plan_of(tmp_path / "d", base)  # no axes, no seeds: one run, the scenario's seed
    assert p.seeds == [1] and len(p.runs) == 1 and p.runs[0].run_id.endswith("__s1")


def test_run_ids_depend_on_the_overrides_and_seed_not_on_the_axes_order(tmp_path):
    a = plan_of(
        tmp_path / "a",
        """\
        set: {duration: 2 s}
        axes:
          - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 2 m/s]}
          - {name: rtol, path: solver.rtol, values: [1.0e-6, 1.0e-5]}
        seeds: 2
        """,
    )
    b = plan_of(
        tmp_path / "b",
        """\
        set: {duration: 3 s}
        axes:
          - {name: tol, path: solver.rtol, values: [1.0e-5, 1.0e-6]}
          - {name: v, path: 'programme[0].line_speed', values: [2 m/s, 1 m/s]}
        seeds: [1, 0]
        """,
    )
    ka = {r.run_id: (r.columns["axis.speed"], r.columns["axis.rtol"], r.seed) for r in a.runs}
    kb = {r.run_id: (r.columns["axis.v"], r.columns["axis.tol"], r.seed) for r in b.runs}
    assert len(ka) == len(kb) == 8
    assert ka == kb  # same overrides and seed: same id
    assert [r.run_id for r in a.runs] != [r.run_id for r in b.runs]  # other order
    # the configuration (duration 2 s vs 3 s) differs, and is what a resumed sweep checks
    ca = {r.run_id: r.config_sha256 for r in a.runs}
    assert all(ca[r.run_id] != r.config_sha256 for r in b.runs)


def test_null_removes_a_list_element_by_id_and_its_axes_do_not_apply(tmp_path):
    # a grid of [no fault, the fault] x 3 magnitudes: 1 healthy run and 3 faulty ones
    plan = plan_of(
        tmp_path,
        """\
        set:
          duration: 2 s
          faults: [{id: f, type: sensor.offset, target: lc_rewind, onset: 1 s, magnitude: 5 N}]
        axes:
          - {name: fault, path: faults.f, values: [null, {id: f, type: sensor.offset,
              target: lc_rewind, onset: 1 s, magnitude: 1 N}]}
          - {name: magnitude, path: faults.f.magnitude, values: [-10 N, 3 N, 10 N]}
        """,
    )
    assert plan.n_combinations == 4 and len(plan.runs) == 4
    healthy, *faulty = plan.runs
    assert healthy.scenario_data["faults"] == []
    assert healthy.columns["axis.fault"] is None and healthy.columns["axis.magnitude"] is None
    assert json.loads(healthy.columns["overrides_json"]) == {"faults.f": None}
    assert [r.columns["axis.magnitude"] for r in faulty] == [-10.0, 3.0, 10.0]
    # each faulty run has its own magnitude (the element given as a value is not shared)
    assert [r.scenario_data["faults"][0]["magnitude"] for r in faulty] == ["-10 N", "3 N", "10 N"]
    assert [r.combination for r in plan.runs] == [0, 1, 2, 3]


def test_null_keeps_healthy_runs_in_the_dataset(tmp_path):
    sw = sweep_file(
        tmp_path,
        """\
        set:
          duration: 2 s
          faults: [{id: f, type: sensor.offset, target: lc_rewind, onset: 1 s, magnitude: 5 N}]
        combine: zip
        axes:
          - {name: fault, path: faults.f, values: [null, {id: f, type: sensor.offset,
              target: lc_rewind, onset: 1 s, magnitude: 1 N}]}
          - {name: magnitude, path: faults.f.magnitude, values: [-7 N, 7 N]}
        """,
    )
    s = run_sweep(sw, output=tmp_path / "out", workers=0)
    assert s.ok and s.done == 2
    runs = runs_table(tmp_path / "out")
    assert runs["n_faults"] == [0, 1] and runs["has_fault"] == [False, True]
    assert runs["axis.magnitude"] == [None, 7.0]
    faults = pq.read_table(tmp_path / "out" / "faults.parquet").to_pylist()
    assert [(f["run_id"], f["magnitude"], f["magnitude_unit"]) for f in faults] == [
        (runs["run_id"][1], 7.0, "N")
    ]
    assert validate_dataset(tmp_path / "out") == []


def test_axis_columns_hold_si_values_and_reach_the_simulation(qs):
    _, out = qs
    runs = runs_table(out)
    assert runs["axis.speed"] == [1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0]
    assert runs["axis.offset"] == [-10.0, -10.0, 10.0, 10.0] * 2
    assert runs["seed"] == [0, 1] * 4
    assert runs["combination"] == [0, 0, 1, 1, 2, 2, 3, 3]
    assert runs["n_samples"] == [401] * 8 and runs["duration_s"] == [2.0] * 8
    assert json.loads(runs["overrides_json"][0]) == {
        "faults.lc_offset.magnitude": "-10 N",
        "programme[0].line_speed": "1 m/s",
    }
    faults = {f["run_id"]: f for f in pq.read_table(out / "faults.parquet").to_pylist()}
    for rid, offset in zip(runs["run_id"], runs["axis.offset"], strict=True):
        assert faults[rid]["magnitude"] == offset and faults[rid]["magnitude_unit"] == "N"
        t = pq.read_table(out / "samples" / f"run_id={rid}" / "part-0.parquet")
        ts = t["t_s"].to_numpy()
        err = t["meas.lc_rewind.tension_N"].to_numpy().astype(float) - t[
            "true.lc_rewind.tension_N"
        ].to_numpy().astype(float)
        # the offset shows in the measurement from its onset (1 s), not before
        assert abs(err[ts < 0.95].mean()) < 1.0
        assert err[ts > 1.1].mean() == pytest.approx(offset, abs=1.0)
    # the speed axis changes the line speed: faster rollers at 2 m/s
    enc = {
        rid: pq.read_table(
            out / "samples" / f"run_id={rid}" / "part-0.parquet",
            columns=["true.enc_pull.speed_rad_s"],
        )[0]
        .to_numpy()
        .mean()
        for rid in runs["run_id"]
    }
    slow = [enc[r] for r, v in zip(runs["run_id"], runs["axis.speed"], strict=True) if v == 1]
    fast = [enc[r] for r, v in zip(runs["run_id"], runs["axis.speed"], strict=True) if v == 2]
    assert min(fast) / max(slow) == pytest.approx(2.0, rel=0.02)
    # seeds: the measurement noise differs between seeds of one combination
    a, b = (
        pq.read_table(
            out / "samples" / f"run_id={r}" / "part-0.parquet", columns=["meas.lc_unwind.tension_N"]
        )[0].to_numpy()
        for r in runs["run_id"][:2]
    )
    assert not np.array_equal(a, b)


def test_line_paths_change_the_line(tmp_path):
    sw = sweep_file(
        tmp_path,
        """\
        set: {duration: 2 s, 'line.sensors.lc_rewind.noise': 0.1 N}
        axes:
          - {name: noise, path: line.sensors.lc_unwind.noise, values: [0.1 N, 4 N]}
        """,
    )
    plan = plan_sweep(sw)
    assert [r.columns["axis.noise"] for r in plan.runs] == [0.1, 4.0]
    assert [
        next(s for s in r.line_data["sensors"] if s["id"] == "lc_unwind")["noise"]
        for r in plan.runs
    ] == ["0.1 N", "4 N"]
    assert all(
        next(s for s in r.line_data["sensors"] if s["id"] == "lc_rewind")["noise"] == "0.1 N"
        for r in plan.runs
    )
    s = run_sweep(sw, output=tmp_path / "out", workers=0)
    assert s.ok
    runs = runs_table(tmp_path / "out")
    spread = []
    for rid in runs["run_id"]:
        t = pq.read_table(tmp_path / "out" / "samples" / f"run_id={rid}" / "part-0.parquet")
        spread.append(
            np.std(
                t["meas.lc_unwind.tension_N"].to_numpy().astype(float)
                - t["true.lc_unwind.tension_N"].to_numpy().astype(float)
            )
        )
    assert spread[1] > 10 * spread[0] > 0
    # the dataset keeps the base line file, not 2 versions of it
    assert (tmp_path / "out" / "scenario" / "pet_film_line.yaml").read_text() == LINE.read_text()


# 2. bad sweep files -------------------------------------------------------------------------

SPEED = "'programme[0].line_speed'"
BAD = {
    "unknown key": (
        f"axes:\n  - {{path: {SPEED}, values: [1 m/s], colour: red}}\n",
        ["axes[0].colour: unknown key 'colour'"],
    ),
    "unknown top-level key": ("sweeps: 3\n", ["sweeps: unknown key 'sweeps'"]),
    "a path that is not a path": (
        "axes:\n  - {path: '../x', values: [1]}\n",
        ["axes[0].path: '../x' is not a YAML path"],
    ),
    "a column name that is not one": (
        f"axes:\n  - {{path: {SPEED}, name: 'a b', values: [1 m/s]}}\n",
        ["axes[0].name: 'a b' is not a column name"],
    ),
    "missing scenario": (
        "__scenario__: nope.yaml\n",
        ["scenario: scenario file 'nope.yaml' not found"],
    ),
    "fault id that is not there": (
        "set:\n  faults: [{id: f, type: sensor.offset, target: lc_rewind, onset: 1 s, "
        "magnitude: 5 N}]\naxes:\n  - {path: faults.nope.magnitude, values: [1 N]}\n",
        [
            "1 of 1 combination is invalid",
            "axes[0] (faults.nope.magnitude) = '1 N'",
            "faults has no entry with id 'nope' (ids: f)",
        ],
    ),
    "list without the fault key": (
        "axes:\n  - {path: faults.nope.magnitude, values: [1 N]}\n",
        [
            "axes[0] (faults.nope.magnitude) = '1 N'",
            "leads nowhere in the base scenario",
            "no key 'faults'",
        ],
    ),
    "index past the end": (
        "axes:\n  - {path: 'programme[9].line_speed', values: [1 m/s]}\n",
        [
            "axes[0] (programme[9].line_speed) = '1 m/s'",
            "programme has 4 entries; [9] is past the end",
        ],
    ),
    "unknown scenario key": (
        "axes:\n  - {path: solvr.rtol, values: [1.0e-3]}\n",
        ["axes[0] (solvr.rtol) = 0.001", "unknown key 'solvr'"],
    ),
    "zip of unequal lengths": (
        f"combine: zip\naxes:\n  - {{path: {SPEED}, values: [1 m/s, 2 m/s]}}\n"
        "  - {path: solver.rtol, values: [1.0e-6]}\n",
        [
            "axes: combine: zip needs axes of equal length",
            "programme[0].line_speed: 2, solver.rtol: 1",
        ],
    ),
    "distribution in a grid": (
        f"axes:\n  - {{path: {SPEED}, uniform: [1 m/s, 2 m/s]}}\n",
        ["axes[0]: a distribution (uniform, loguniform) is drawn by combine: random"],
    ),
    "random without n": (
        f"combine: random\naxes:\n  - {{path: {SPEED}, uniform: [1 m/s, 2 m/s]}}\n",
        ["n: combine: random needs n"],
    ),
    "n without random": (
        f"n: 3\naxes:\n  - {{path: {SPEED}, values: [1 m/s]}}\n",
        ["n: n applies to combine: random (this sweep combines by grid)"],
    ),
    "reserved seed": (
        "axes:\n  - {path: seed, values: [1, 2]}\n",
        ["axes[0].path: 'seed' is not swept: give the sweep's seeds: instead"],
    ),
    "reserved name": ("set: {name: other}\n", ["set.name: 'name' is not swept"]),
    "reserved output": (
        "axes:\n  - {path: output, values: [a]}\n",
        ["axes[0].path: 'output' is not swept"],
    ),
    "reserved line": (
        "axes:\n  - {path: line, values: [other.yaml]}\n",
        ["axes[0].path: 'line' is not swept: one sweep runs one line file"],
    ),
    "too many runs": (
        f"axes:\n  - {{path: {SPEED}, range: {{start: 1 m/s, stop: 2 m/s, num: 10000}}}}\n"
        "seeds: 11\n",
        [f"axes: the sweep makes 110000 runs; at most {limits.MAX_SWEEP_RUNS}"],
    ),
    "two axes on one path": (
        f"axes:\n  - {{path: {SPEED}, values: [1 m/s]}}\n"
        f"  - {{name: again, path: {SPEED}, values: [2 m/s]}}\n",
        ["axes[1].path: the path 'programme[0].line_speed' is swept by two axes"],
    ),
    "two axes on one column": (
        f"axes:\n  - {{name: a, path: {SPEED}, values: [1 m/s]}}\n"
        "  - {name: a, path: solver.rtol, values: [1.0e-6]}\n",
        ["axes[1]: two axes have the column 'axis.a'; give one a different name"],
    ),
    "a value listed twice": (
        f"axes:\n  - {{path: {SPEED}, values: [1 m/s, 2 m/s, 1 m/s]}}\n",
        [
            "1 of 3 combinations is invalid",
            "combinations 0 and 2 make the same run "
            "(programme[0].line_speed = '1 m/s'): a value is listed twice",
        ],
    ),
    "random draws that repeat": (
        f"combine: random\nn: 5\naxes:\n  - {{path: {SPEED}, values: [1 m/s, 2 m/s]}}\n",
        [
            "of 5 combinations are invalid",
            "of combine: random make the same run",
            "draw from uniform or loguniform",
        ],
    ),
    "range step of the wrong sign": (
        f"axes:\n  - {{path: {SPEED}, range: {{start: 1 m/s, stop: 2 m/s, step: -0.5 m/s}}}}\n",
        ["axes[0].range.step: step -0.5 does not lead from 1 to 2"],
    ),
    "range in two dimensions": (
        f"axes:\n  - {{path: {SPEED}, range: {{start: 1 m/s, stop: 2 s, num: 3}}}}\n",
        ["axes[0].range: the values have different dimensions"],
    ),
    "range with num and step": (
        f"axes:\n  - {{path: {SPEED}, range: {{start: 1, stop: 2, num: 3, step: 1}}}}\n",
        ["axes[0].range", "give either num (how many values) or step (their spacing)"],
    ),
    "loguniform from zero": (
        f"combine: random\nn: 2\naxes:\n  - {{path: {SPEED}, loguniform: [0 m/s, 2 m/s]}}\n",
        ["axes[0].loguniform: loguniform needs low > 0"],
    ),
    "a seed listed twice": ("seeds: [1, 2, 1]\n", ["seeds: a seed is listed twice"]),
    "the last seed too large": (
        f"seed: {limits.MAX_SEED}\nseeds: 2\n",
        ["seeds: the last seed 18446744073709551616 is above 2**64 - 1"],
    ),
    "invalid YAML": ("axes: [\n", ["invalid YAML"]),
    # numbers at the ends of floating point (OverflowError tracebacks before)
    "a range step near 1e-320": (
        "axes:\n  - {path: solver.rtol, range: {start: 0, stop: 1, step: 1.0e-320}}\n",
        ["axes[0].range: the range from 0 to 1 in steps of", "has more than 10000 values"],
    ),
    "a range wider than floating point": (
        "axes:\n  - {path: solver.rtol, range: {start: -1.0e+308, stop: 1.0e+308, "
        "step: 1.0e+307}}\n",
        ["axes[0].range: the range from -1e+308 to 1e+308 is wider than floating point can hold"],
    ),
    "a uniform wider than floating point": (
        "combine: random\nn: 2\naxes:\n  - {path: solver.rtol, uniform: [-1.0e+308, 1.0e+308]}\n",
        ["axes[0].uniform: the interval from -1e+308 to 1e+308 is wider than floating point"],
    ),
    # one value spelled two ways: the second axis overwrote the first (duplicate runs)
    "one value swept by two axes under two spellings": (
        "axes:\n  - {name: a, path: line.sensors.lc_rewind.noise, values: [1 N, 2 N]}\n"
        "  - {name: b, path: 'line.sensors[1].noise', values: [3 N, 4 N]}\n",
        [
            "axes[1].path: 'line.sensors[1].noise' is the value axes[0] sweeps "
            "('line.sensors.lc_rewind.noise'); sweep it once"
        ],
    ),
    "a scenario that is not a regular file": (
        "__scenario__: /dev/null\n",
        ["scenario: scenario file '/dev/null' is not a regular file"],
    ),
}


@pytest.mark.parametrize("kind", list(BAD))
def test_bad_sweep_file(tmp_path, capsys, kind):
    body, expected = BAD[kind]
    scenario = QUICK
    if body.startswith("__scenario__: "):
        scenario, body = body.split("\n", 1)[0].split(": ", 1)[1], body.split("\n", 1)[1]
    sw = sweep_file(
        tmp_path, "set: {duration: 2 s}\n" + body if "set:" not in body else body, scenario=scenario
    )
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = cli(capsys, sw, "-o", tmp_path / "out", "--workers", "0")
    assert code == 2 and out == ""
    assert err.startswith(f"error: {sw}: ") and err.count("error:") == 1
    for text in expected:
        assert text in err, (text, err)
    lines = err.rstrip("\n").split("\n")
    if " invalid (nothing was run)" in err:  # a line per invalid combination, each located
        assert len(lines) >= 2 and all(
            line.startswith("  ") and f"{sw}" not in line for line in lines[1:]
        )
    elif "unknown key" in err:  # located by its line, and that line of the file quoted
        assert len(lines) == 2 and lines[1].startswith("    ") and " line " in lines[0]
    else:
        assert len(lines) == 1
    assert not (tmp_path / "out").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    with pytest.raises(InputError):  # the API refuses it the same way
        plan_sweep(sw)


def test_every_invalid_combination_is_listed_at_once(tmp_path, capsys):
    # 3 x 2 combinations: a wrong unit in one axis, values out of range in the other
    sw = sweep_file(
        tmp_path,
        f"""\
        set: {{duration: 2 s}}
        axes:
          - {{name: tol, path: solver.rtol, values: [1.0e-6, 2, 5]}}
          - {{name: v, path: {SPEED}, values: [3 kg, 2 m/s]}}
        """,
    )
    code, _, err = cli(capsys, sw, "-o", tmp_path / "out")
    assert code == 2 and not (tmp_path / "out").exists()
    lines = err.rstrip("\n").split("\n")
    assert lines[0] == f"error: {sw}: 5 of 6 combinations are invalid (nothing was run):"
    scen = str(QUICK)
    assert lines[1:] == [
        f"  axes[1] ({SPEED[1:-1]}) = '3 kg': {scen}: programme[0].line_speed: '3 kg' "
        "has dimension [mass], expected a speed (e.g. '300 m/min') (in 3 combinations)",
        f"  axes[0] (solver.rtol) = 2: {scen}: solver.rtol: must be < 1.0, got 2 "
        "(in 2 combinations)",
        f"  axes[0] (solver.rtol) = 5: {scen}: solver.rtol: must be < 1.0, got 5 "
        "(in 2 combinations)",
    ]


def test_runs_with_other_sample_columns_are_refused(tmp_path, capsys):
    # the encoder enc_pull removed in one combination: its columns differ
    sw = sweep_file(
        tmp_path,
        """\
        set: {duration: 2 s}
        axes:
          - {name: enc, path: line.sensors.enc_pull, values: [null, {id: enc_pull,
              type: encoder, element: pull, counts_per_rev: 1024}]}
        """,
    )
    code, _, err = cli(capsys, sw, "-o", tmp_path / "out")
    assert code == 2 and not (tmp_path / "out").exists()
    assert "1 of 2 combinations is invalid" in err
    assert (
        "the runs of this combination have other sample columns than those of "
        "combination 0 (ctrl.enc_pull.speed_seen_rad_s, meas.enc_pull.speed_rad_s" in err
    )
    assert "make two sweeps" in err
    # removing a sensor a controller reads is invalid, and says so
    sw = sweep_file(
        tmp_path,
        """\
        set: {duration: 2 s}
        axes:
          - {path: line.sensors.lc_rewind, values: [null]}
        """,
    )
    code, _, err = cli(capsys, sw, "-o", tmp_path / "out")
    assert code == 2 and not (tmp_path / "out").exists()
    assert (
        f"line.sensors.lc_rewind = null: {LINE}: controllers[4].sensor: no load_cell or "
        "pitch_length sensor with id 'lc_rewind'" in err
    )


def test_output_key_outside_the_sweep_directory(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    sw = sweep_file(tmp_path / "proj", "set: {duration: 2 s}\noutput: ../elsewhere\n")
    code, _, err = cli(capsys, sw)
    assert code == 2 and "output: '../elsewhere' is outside the sweep's directory" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["proj"]
    assert main(["validate", str(sw)]) == 2  # validate refuses it too
    assert "output: '../elsewhere' is outside the sweep's directory" in capsys.readouterr().err
    # inside it: relative to the sweep file, whatever the working directory
    sw = sweep_file(tmp_path / "proj", "set: {duration: 2 s}\noutput: data/t\n")
    code, out, _ = cli(capsys, sw, "--workers", "0")
    assert code == 0 and validate_dataset(tmp_path / "proj" / "data" / "t") == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["proj"]


# 3. resume and fault tolerance --------------------------------------------------------------


@pytest.mark.parametrize("how", ["SIGINT to the process group", "SIGTERM to the sweep"])
def test_interrupted_sweep_resumes_to_the_same_bytes(many, tmp_path, how, sweep_process):
    sw, reference = many
    out = tmp_path / "out"
    proc = sweep_process(sw, out, "--workers", "1")
    wait_for_runs(proc, out, 2)
    workers = sweep_process.children(proc)
    if how.startswith("SIGINT"):  # Ctrl-C: the terminal signals every process of the group
        os.killpg(proc.pid, signal.SIGINT)
    else:
        os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    if how.startswith("SIGINT"):
        assert proc.returncode == 130
        assert err == (
            "interrupted; the finished runs are kept: run the same command again to continue\n"
        )
    else:
        assert proc.returncode == 143 and err.startswith("terminated (SIGTERM)")
    deadline = time.monotonic() + 10
    while not all(gone(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(gone(p) for p in workers)
    done = finished_runs(out)
    assert 2 <= len(done) < 32, "the sweep was not interrupted half-way"
    assert (out / ".r2rsim-sweep.json").is_file() and not (out / "manifest.json").exists()
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "r2rsim.cli",
            "sweep",
            str(sw),
            "-o",
            str(out),
            "-q",
            "--workers",
            "0",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert f"runs         32: {32 - len(done)} done, 0 failed, {len(done)} skipped" in r.stdout
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in reference.iterdir())
    assert_same_dataset(reference, out)
    assert validate_dataset(out) == []


def test_sweep_killed_with_sigkill_resumes_and_its_workers_exit(many, tmp_path, sweep_process):
    sw, reference = many
    out = tmp_path / "out"
    proc = sweep_process(sw, out, "--workers", "1")
    wait_for_runs(proc, out, 2)
    workers = sweep_process.children(proc)
    assert workers  # the worker (and the multiprocessing resource tracker)
    os.kill(proc.pid, signal.SIGKILL)
    # orphaned, the worker notices and exits: it would otherwise wait for tasks for ever,
    # holding the pipes (communicate would hang) and its memory
    proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    deadline = time.monotonic() + 15
    while not all(gone(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(gone(p) for p in workers)
    done = finished_runs(out)
    assert 2 <= len(done) < 32
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "r2rsim.cli",
            "sweep",
            str(sw),
            "-o",
            str(out),
            "-q",
            "--workers",
            "0",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert f"{len(done)} skipped" in r.stdout
    assert_same_dataset(reference, out)
    assert validate_dataset(out) == []
    assert not any(p.name.startswith(".") for p in out.rglob("*"))  # no temporaries left


def test_a_killed_worker_is_replaced_and_its_run_run_again(many, tmp_path, sweep_process):
    sw, reference = many
    out = tmp_path / "out"
    proc = sweep_process(sw, out, "--workers", "1")
    wait_for_runs(proc, out, 2)
    workers = [
        p
        for p in sweep_process.children(proc)
        if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()
    ]
    assert len(workers) == 1
    os.kill(workers[0], signal.SIGKILL)  # the OOM killer, say
    stdout, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "runs         32: 32 done, 0 failed, 0 skipped" in stdout
    assert_same_dataset(reference, out)
    assert validate_dataset(out) == []


def test_failed_runs_are_recorded_kept_and_retried(tmp_path, capsys, monkeypatch):
    # a step budget of 2 steps per simulated second makes a solver failure (with data up to
    # there); a run that raises in the worker fails without data
    sw = sweep_file(
        tmp_path,
        """\
        set: {duration: 3 s}
        axes:
          - {name: budget, path: solver.max_steps_per_s, values: [50000, 2]}
          - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 1.5 m/s]}
        """,
    )
    out = tmp_path / "out"
    plan = plan_sweep(sw)
    ok, ok2, budget, budget2 = (r.run_id for r in plan.runs)
    import r2rsim.run

    real = r2rsim.run.execute

    def boom(run_plan, path, **kw):
        if kw.get("run_id") == ok2:
            raise RuntimeError("boom")
        return real(run_plan, path, **kw)

    monkeypatch.setattr(r2rsim.run, "execute", boom)
    code, stdout, err = cli(capsys, sw, "-o", out, "--workers", "0")
    assert code == 1
    assert "runs         4: 1 done, 3 failed, 0 skipped" in stdout
    assert f"FAILED       {ok2}: RuntimeError: boom" in stdout
    assert f"FAILED       {budget}: solver_failure: step budget" in stdout
    assert err.startswith("error: 3 runs of the sweep failed") and err.count("\n") == 1
    assert validate_dataset(out) == []
    runs = runs_table(out)
    assert runs["run_id"] == [ok, budget, budget2]  # the runs with data
    assert runs["termination_reason"][0] is None
    assert all(r.startswith("solver_failure: step budget") for r in runs["termination_reason"][1:])
    assert runs["axis.budget"] == [50000.0, 2.0, 2.0]
    failures = pq.read_table(out / "failures.parquet").to_pylist()
    assert [(f["run_id"], f["error"], f["axis.speed"]) for f in failures] == [
        (ok2, "RuntimeError: boom", 1.5)
    ]
    assert not (out / "samples" / f"run_id={ok2}").exists()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["sweep"]["failed_without_data"] == [ok2]
    assert manifest["sweep"]["failed"] == [ok2, budget, budget2]
    assert manifest["run_ids"] == [ok, budget, budget2]
    # never taken for a complete sweep: the summary, the tables and validate say so
    assert f"dataset      {out} (incomplete: 3 of 4 runs failed)" in stdout
    meta = pq.read_schema(out / "runs.parquet").metadata
    assert (meta[b"r2rsim.sweep.n_runs"], meta[b"r2rsim.sweep.n_failed"]) == (b"4", b"3")
    assert main(["validate", str(out)]) == 0
    said = capsys.readouterr().out
    assert "valid dataset; an INCOMPLETE sweep: 3 of 4 runs failed" in said

    monkeypatch.setattr(r2rsim.run, "execute", real)
    before = snapshot(out)
    code, stdout, err = cli(capsys, sw, "-o", out, "--workers", "0")  # failures are kept
    assert code == 1 and "0 done, 0 failed, 4 skipped (already done, 3 of them failed" in stdout
    assert "error: 3 runs of the sweep failed" in err
    assert snapshot(out) == before  # nothing written

    code, stdout, err = cli(capsys, sw, "-o", out, "--workers", "0", "--retry-failed")
    assert code == 1  # the step budget fails again; the other one runs now
    assert "runs         4: 1 done, 2 failed, 1 skipped" in stdout
    assert "error: 2 runs of the sweep failed" in err
    runs = runs_table(out)
    assert runs["run_id"] == [ok, ok2, budget, budget2]
    assert runs["termination_reason"][:2] == [None, None]
    assert pq.read_table(out / "failures.parquet").num_rows == 0
    assert json.loads((out / "manifest.json").read_text())["sweep"]["failed_without_data"] == []
    # the run that succeeded first was not run again
    assert (
        snapshot(out)[f"samples/run_id={ok}/part-0.parquet"]
        == before[f"samples/run_id={ok}/part-0.parquet"]
    )
    assert validate_dataset(out) == []


def test_finished_sweep_is_left_alone_reopened_for_new_seeds_and_guarded(tmp_path, capsys):
    base = scenario_copy(tmp_path / "proj")
    sw = sweep_file(
        tmp_path / "proj",
        """\
        set: {duration: 2 s}
        axes:
          - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 2 m/s]}
        seeds: 2
        """,
        scenario="base.yaml",
    )
    out = tmp_path / "out"
    assert cli(capsys, sw, "-o", out, "--workers", "0")[0] == 0
    before = snapshot(out)
    time.sleep(0.01)
    code, stdout, err = cli(capsys, sw, "-o", out, "--workers", "0")
    assert code == 0 and err == ""
    assert "runs         4: 0 done, 0 failed, 4 skipped (already done)" in stdout
    assert snapshot(out) == before  # nothing written, not even the marker

    # one seed more: only its runs are simulated, the others stay as they are
    sw.write_text(sw.read_text().replace("seeds: 2", "seeds: 3"))
    code, stdout, _ = cli(capsys, sw, "-o", out, "--workers", "0")
    assert code == 0 and "runs         6: 2 done, 0 failed, 4 skipped" in stdout
    after = snapshot(out)
    old_samples = [k for k in before if k.endswith("part-0.parquet")]
    assert len(old_samples) == 4 and all(after[k] == before[k] for k in old_samples)
    assert sorted(k for k in after if k.endswith("part-0.parquet")) == sorted(
        old_samples + [k.replace("__s1/", "__s2/") for k in old_samples if "__s1/" in k]
    )
    runs = runs_table(out)
    assert runs["seed"] == [0, 1, 2, 0, 1, 2]
    assert validate_dataset(out) == []
    assert "seeds: 3" in (out / "sweep" / "sweep.yaml").read_text()

    def refused(*extra, match):
        state = snapshot(out)
        code, _, err = cli(capsys, sw, "-o", out, "--workers", "0", *extra)
        assert code == 2 and match in err and err.count("\n") == 1, err
        assert snapshot(out) == state

    # the sweep file no longer makes some of its runs
    sw.write_text(sw.read_text().replace("seeds: 3", "seeds: 2"))
    refused(match=f"output directory '{out}' holds 2 run(s) this sweep file does not make")
    sw.write_text(sw.read_text().replace("seeds: 2", "seeds: 3"))
    # the base scenario changed: its runs would not be those in the dataset
    base.write_text(base.read_text().replace("warmup: 2 s", "warmup: 1 s"))
    refused(
        match=f"6 run(s) in '{out}' were made from another base scenario, line, sweep "
        f"file `set:` or r2rsim version"
    )
    # --overwrite starts it again
    code, stdout, _ = cli(capsys, sw, "-o", out, "--workers", "0", "--overwrite")
    assert code == 0 and "6 done" in stdout
    assert runs_table(out)["warmup_s"] == [1.0] * 6


def test_output_holding_other_data(tmp_path, capsys, qs):
    sw, _ = qs
    # a run's dataset: replaced only with --overwrite
    ds = tmp_path / "ds"
    assert main(["run", str(QUICK), "-o", str(ds), "--duration", "1", "-q"]) == 0
    capsys.readouterr()
    before = snapshot(ds)
    code, _, err = cli(capsys, sw, "-o", ds, "--workers", "0")
    assert code == 2 and err == (
        f"error: output directory '{ds}' holds a run's dataset; pass "
        f"--overwrite to replace it, or choose another directory "
        f"with -o\n"
    )
    assert snapshot(ds) == before
    code, _, _ = cli(capsys, sw, "-o", ds, "--workers", "0", "--overwrite")
    assert code == 0 and len(runs_table(ds)["run_id"]) == 8 and validate_dataset(ds) == []
    # another sweep's dataset
    other = sweep_file(tmp_path / "o", "set: {duration: 1 s}\n", name="other")
    code, _, err = cli(capsys, other, "-o", ds, "--workers", "0")
    assert code == 2 and "holds sweep 'qs'; pass --overwrite" in err
    # a directory with someone's files: never, --overwrite or not
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    (mine / "manifest.json").write_text("{}")
    before = snapshot(mine)
    for extra in ((), ("--overwrite",)):
        code, _, err = cli(capsys, sw, "-o", mine, "--workers", "0", *extra)
        assert code == 2 and "is not an r2rsim dataset" in err and err.count("\n") == 1
        assert snapshot(mine) == before


def test_files_put_into_an_unfinished_sweep_are_not_adopted(many, tmp_path, capsys, sweep_process):
    sw, reference = many
    out = tmp_path / "out"
    proc = sweep_process(sw, out, "--workers", "1")
    wait_for_runs(proc, out, 1)
    # a second sweep into the directory while the first writes it: refused, nothing written
    state = hashes(out, "sweep"), sorted(p.name for p in out.iterdir())
    assert main(["sweep", str(sw), "-o", str(out), "-q", "--workers", "0"]) == 2
    assert f"another r2rsim sweep is writing '{out}'" in capsys.readouterr().err
    assert (hashes(out, "sweep"), sorted(p.name for p in out.iterdir())) == state
    os.killpg(proc.pid, signal.SIGINT)
    proc.communicate(timeout=60)
    assert proc.returncode == 130
    (out / "notes.txt").write_text("mine")
    (out / "samples").mkdir(exist_ok=True)
    (out / "samples" / "README").write_text("mine too")

    def resume():
        return subprocess.run(
            [
                sys.executable,
                "-m",
                "r2rsim.cli",
                "sweep",
                str(sw),
                "-o",
                str(out),
                "-q",
                "--workers",
                "0",
            ],
            capture_output=True,
            text=True,
        )

    r = resume()
    assert r.returncode == 2 and r.stderr == (
        f"error: output directory '{out}' holds an unfinished sweep and 2 file(s) r2rsim did "
        f"not write (notes.txt, samples/README): move them out of it, then run the sweep "
        f"again to finish it\n"
    )
    assert (out / "notes.txt").read_text() == "mine"
    (out / "notes.txt").unlink()
    (out / "samples" / "README").unlink()
    # another sweep does not take over the unfinished one, --overwrite or not
    other = sweep_file(tmp_path / "other", "set: {duration: 1 s}\n", name="other")
    state = snapshot(out)
    for extra in ((), ("--overwrite",)):
        assert main(["sweep", str(other), "-o", str(out), "-q", *extra]) == 2
        assert capsys.readouterr().err == (
            f"error: output directory '{out}' holds an unfinished sweep 'many', not 'other': "
            f"choose another directory with -o\n"
        )
    assert snapshot(out) == state
    r = resume()
    assert r.returncode == 0, r.stderr
    assert_same_dataset(reference, out)


@pytest.mark.parametrize("marker", ["[1, 2]", "not json", '{"sweep": 3}'])
def test_a_damaged_sweep_marker_is_one_error(qs, tmp_path, capsys, marker):
    sw, _ = qs
    out = tmp_path / "out"
    out.mkdir()
    (out / ".r2rsim-sweep.json").write_text(marker)
    assert main(["sweep", str(sw), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: output directory '{out}' holds an unfinished sweep")
    assert "Traceback" not in err and err.count("\n") == 1
    assert sorted(p.name for p in out.iterdir()) == [".r2rsim-sweep.json"]


def test_interrupted_finalisation_is_finished_by_running_again(qs, tmp_path, monkeypatch):
    from r2rsim.sweep import _store

    sw, serial = qs
    out = tmp_path / "out"
    real = _store.SweepStore._write_manifest

    def interrupted(self, *args):
        raise KeyboardInterrupt

    monkeypatch.setattr(_store.SweepStore, "_write_manifest", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(sw, output=out, workers=0)
    # the tables and samples are in place, the manifest is not: not a dataset yet
    assert (out / "runs.parquet").is_file() and (out / "samples").is_dir()
    assert (out / ".r2rsim-sweep.json").is_file() and not (out / "manifest.json").exists()
    assert validate_dataset(out) != []
    monkeypatch.setattr(_store.SweepStore, "_write_manifest", real)
    s = run_sweep(sw, output=out, workers=0)
    assert s.ok and s.done == 0 and s.skipped == 8  # nothing run again
    assert_same_dataset(serial, out)
    assert validate_dataset(out) == []


def test_channels_of_runs_with_other_rates(tmp_path):
    # the record rate and a sensor's range swept: channels.parquet says what differs
    sw = sweep_file(
        tmp_path,
        """\
        set: {duration: 1 s}
        axes:
          - {name: rate, path: record_rate, values: [100 Hz, 200 Hz]}
          - {name: range, path: line.sensors.lc_unwind.range, values: [[0, 1000], [0, 2000]]}
        """,
    )
    s = run_sweep(sw, output=tmp_path / "out", workers=0)
    assert s.ok and s.done == 4
    assert runs_table(tmp_path / "out")["sample_period_s"] == [0.01, 0.01, 0.005, 0.005]
    ch = {r["channel"]: r for r in pq.read_table(tmp_path / "out" / "channels.parquet").to_pylist()}
    assert ch["t_s"]["rate_hz"] is None and ch["meas.lc_unwind.tension_N"]["rate_hz"] is None
    assert ch["meas.dia_unwind.diameter_m"]["rate_hz"] == 10.0  # its own rate, in every run
    assert ch["flag.lc_unwind.clipped"]["description"].endswith(
        "(differs between the runs of this sweep; see each run's configuration)"
    )
    assert ch["t_s"]["description"] == "simulation time"
    assert validate_dataset(tmp_path / "out") == []
    # a sweep where nothing of it differs keeps every run's rates
    one = run_sweep(
        sweep_file(tmp_path / "one", "set: {duration: 1 s}\nseeds: 2\n"),
        output=tmp_path / "one" / "out",
        workers=0,
    )
    assert one.ok
    ch = {
        r["channel"]: r
        for r in pq.read_table(tmp_path / "one" / "out" / "channels.parquet").to_pylist()
    }
    assert ch["t_s"]["rate_hz"] == 200.0 and ch["meas.dia_unwind.diameter_m"]["rate_hz"] == 10.0


def test_bad_worker_counts(tmp_path, capsys, qs):
    sw, _ = qs
    code, _, err = cli(capsys, sw, "-o", tmp_path / "out", "--workers", "-1")
    assert code == 2 and err == "error: --workers must be >= 0, got -1\n"
    code, _, err = cli(capsys, sw, "-o", tmp_path / "out", "--workers", "0", "--scheduler", "local")
    assert code == 2 and err == "error: --workers must be >= 1, got 0\n"
    # one machine: a bounded number of processes (each loads the kernels, ~300 MB)
    for extra in ([], ["--scheduler", "local"]):
        code, _, err = cli(capsys, sw, "-o", tmp_path / "out", "--workers", "100000", *extra)
        assert code == 2 and err == (
            "error: --workers 100000: at most 1024 worker processes "
            "on one machine (docs/security.md)\n"
        )
    assert not (tmp_path / "out").exists()


# 4. executors -------------------------------------------------------------------------------


def test_process_pool_writes_the_serial_bytes(qs, tmp_path):
    sw, serial = qs
    s = run_sweep(sw, output=tmp_path / "pool", workers=2)
    assert s.ok and s.done == 8 and s.executor == "2 local worker processes"
    assert_same_dataset(serial, tmp_path / "pool")


def test_dask_local_cluster_writes_the_serial_bytes(qs, tmp_path):
    sw, serial = qs
    environ = dict(os.environ)
    s = run_sweep(sw, output=tmp_path / "dask", workers=2, scheduler="local")
    assert s.ok and s.done == 8 and s.executor == "Dask LocalCluster, 2 worker processes"
    assert_same_dataset(serial, tmp_path / "dask")
    assert validate_dataset(tmp_path / "dask") == []
    # a LocalCluster's nannies set MALLOC_TRIM_THRESHOLD_ & co. in this process: put back,
    # or every process started later (a local sweep's workers) runs ~35 % slower
    assert dict(os.environ) == environ


# 5. readers ---------------------------------------------------------------------------------


def test_readers_without_r2rsim(qs, capsys):
    import duckdb
    import pandas as pd
    import pyarrow.dataset as pds

    _, out = qs
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 8 and runs["run_id"].is_unique
    assert runs["axis.speed"].dtype == np.float64 and runs["seed"].dtype == np.uint64
    assert sorted(runs["axis.offset"].unique()) == [-10.0, 10.0]
    n = int(runs["n_samples"].sum())
    assert n == 8 * 401

    samples = pd.read_parquet(out / "samples")
    assert len(samples) == n and set(samples["run_id"].astype(str)) == set(runs["run_id"])
    samples["run_id"] = samples["run_id"].astype(str)
    joined = samples.merge(runs[["run_id", "axis.offset"]], on="run_id")
    assert len(joined) == n and (joined["axis.offset"] == 10.0).sum() == n // 2

    rows = duckdb.sql(f"""
        select r."axis.offset", count(*), max(s.t_s)
        from read_parquet('{out}/samples/*/*.parquet', hive_partitioning=true) s
        join read_parquet('{out}/runs.parquet') r using (run_id)
        group by 1 order by 1""").fetchall()
    assert rows == [(-10.0, 4 * 401, 2.0), (10.0, 4 * 401, 2.0)]

    table = pds.dataset(out / "samples", format="parquet", partitioning="hive").to_table()
    assert table.num_rows == n and set(table["run_id"].to_pylist()) == set(runs["run_id"])

    assert validate_dataset(out) == []
    assert main(["validate", str(out)]) == 0
    capsys.readouterr()


def finished_speed_sweep(tmp_path: Path, capsys) -> tuple[Path, Path]:
    """A finished serial sweep of two 1 s runs on axis ``v`` (1 and 3 m/s): (file, output)."""
    sw = sweep_file(
        tmp_path,
        f"""\
        set: {{duration: 1 s}}
        axes:
          - {{name: v, path: {SPEED}, values: [1 m/s, 3 m/s]}}
        """,
    )
    out = tmp_path / "out"
    assert cli(capsys, sw, "-o", out, "--workers", "0")[0] == 0
    return sw, out


def test_reopened_sweep_renumbers_its_combinations_and_drops_stale_copies(tmp_path, capsys):
    """A value added to an axis keeps the old runs (same ids and data) but numbers the
    combinations anew: the old rows get the plan's numbers, not their old ones; and the
    copy of a renamed sweep file does not stay behind."""
    sw, out = finished_speed_sweep(tmp_path, capsys)
    old_ids = runs_table(out)["run_id"]
    renamed = tmp_path / "sweep2.yaml"
    renamed.write_text(sw.read_text().replace("[1 m/s, 3 m/s]", "[1 m/s, 2 m/s, 3 m/s]"))
    sw.unlink()
    code, stdout, _ = cli(capsys, renamed, "-o", out, "--workers", "0")
    assert code == 0 and "1 done, 0 failed, 2 skipped" in stdout
    runs = runs_table(out)
    assert runs["axis.v"] == [1.0, 2.0, 3.0] and runs["combination"] == [0, 1, 2]
    assert runs["run_id"][0] == old_ids[0] and runs["run_id"][2] == old_ids[1]
    assert sorted(p.name for p in (out / "sweep").iterdir()) == ["sweep2.yaml"]
    assert validate_dataset(out) == []


def test_a_renamed_axis_is_applied_with_nothing_new_to_run(tmp_path, capsys):
    """Renaming an axis of a finished sweep runs nothing but renames its column and replaces
    the copy of the sweep file (before, the dataset was left as it was, under exit 0)."""
    sw, out = finished_speed_sweep(tmp_path, capsys)
    before = snapshot(out)
    sw.write_text(sw.read_text().replace("name: v,", "name: speed,"))
    code, stdout, _ = cli(capsys, sw, "-o", out, "--workers", "0")
    assert code == 0 and "0 done, 0 failed, 2 skipped" in stdout
    assert "nothing to run; the changed sweep file applied" in stdout
    runs = runs_table(out)
    assert runs["axis.speed"] == [1.0, 3.0] and "axis.v" not in runs
    assert "name: speed," in (out / "sweep" / "sweep.yaml").read_text()
    after = snapshot(out)
    samples = [k for k in before if k.endswith("part-0.parquet")]
    assert len(samples) == 2 and all(after[k] == before[k] for k in samples)
    assert validate_dataset(out) == []
    # and once applied, running it again writes nothing
    code, stdout, _ = cli(capsys, sw, "-o", out, "--workers", "0")
    assert code == 0 and "executor     none (nothing to run)\n" in stdout
    assert snapshot(out) == after


def test_a_pool_worker_skips_the_collector_at_exit():
    """Each worker freezes the collector at exit (its shutdown otherwise took ~0.3 s of
    passes over numba's objects, which the sweep waited for); its runs are committed by then
    (the process sweeps above compare their datasets with serial ones)."""
    probe = (
        "import atexit, gc, os\n"
        "atexit.register(lambda: print('frozen at exit:', gc.get_freeze_count() > 0))\n"
        "from r2rsim.sweep._execute import _worker_init\n"
        "_worker_init(os.getppid())\n"
    )
    p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "frozen at exit: True"


def test_a_run_that_kills_its_worker_fails_alone(tmp_path):
    # the OOM killer takes a worker: its pool breaks and every run in flight is lost. Each
    # then runs alone, so only the run that kills its worker is charged and recorded failed
    # (the runs beside it were recorded failed too, and one such run stopped the sweep with
    # advice about `if __name__ == "__main__"`)
    from _sweep_tasks import Spec, die_on_oom

    from r2rsim.sweep._execute import MAX_ATTEMPTS, run_processes

    specs = (
        [Spec(f"ok{i}") for i in range(3)] + [Spec("oom")] + [Spec(f"ok{i}") for i in range(3, 6)]
    )
    got: dict = {}
    run_processes(
        specs, str(tmp_path), lambda spec, rec: got.setdefault(spec.run_id, rec), 2, task=die_on_oom
    )
    assert set(got) == {s.run_id for s in specs}
    assert all(got[f"ok{i}"]["status"] == "done" for i in range(6))
    assert got["oom"]["status"] == "failed" and not got["oom"]["has_data"]
    assert f"died {MAX_ATTEMPTS} times" in got["oom"]["reason"]


class _FakeFuture:
    def __init__(self, key, outcome):
        self.key, self.outcome = key, outcome

    def result(self):
        if isinstance(self.outcome, BaseException):
            raise self.outcome
        return self.outcome

    def release(self):
        pass


class _FakeClient:
    """A Dask client whose runs end as ``outcomes`` says (None: never), with a status."""

    def __init__(self, outcomes, status="running"):
        self.outcomes, self.status = outcomes, status

    def submit(self, fn, spec, work, kinds, key, pure):
        return _FakeFuture(key, self.outcomes[spec.run_id])


def _fake_as_completed():
    class AsCompleted:
        def __init__(self):
            self.ready = []

        def add(self, f):
            if f.outcome is not None:
                self.ready.append(f)

        def has_ready(self):
            return bool(self.ready)

        def next_batch(self, block=True):
            out, self.ready = self.ready, []
            return out

    return AsCompleted


@pytest.mark.parametrize(
    "outcome, status",
    [
        (None, "closed"),  # the client gave up reconnecting: the loop waited for ever
        # the runs in flight were recorded as failed
        (concurrent.futures.CancelledError("scheduler-connection-lost"), "running"),
    ],
)
def test_a_lost_dask_scheduler_stops_the_sweep(outcome, status):
    from _sweep_tasks import Spec

    from r2rsim.errors import R2RError
    from r2rsim.sweep._execute import _dask_loop

    got = {}
    client = _FakeClient({"a": {"run_id": "a", "status": "done"}, "b": outcome}, status)
    with pytest.raises(R2RError, match="the Dask scheduler went away; the finished runs are kept"):
        _dask_loop(
            client,
            _fake_as_completed(),
            [Spec("a"), Spec("b")],
            "w",
            lambda spec, rec: got.setdefault(spec.run_id, rec),
            2,
        )
    assert set(got) == {"a"}  # b is not recorded as failed: it runs again next time


def test_a_run_lost_with_its_dask_worker_is_recorded_failed():
    from _sweep_tasks import Spec

    from r2rsim.sweep._execute import _dask_loop

    got = {}
    client = _FakeClient(
        {"a": {"run_id": "a", "status": "done"}, "b": RuntimeError("KilledWorker: b")}
    )
    _dask_loop(
        client,
        _fake_as_completed(),
        [Spec("a"), Spec("b")],
        "w",
        lambda spec, rec: got.setdefault(spec.run_id, rec),
        2,
    )
    assert got["a"]["status"] == "done" and got["b"]["status"] == "failed"
    assert got["b"]["reason"] == "RuntimeError: KilledWorker: b"


def test_a_sweep_finished_by_another_while_this_one_starts_is_left_finished(qs, tmp_path):
    # sweep B inspects an unfinished sweep, then A finishes it (its marker goes) before B
    # takes the lock: B used to re-create the marker and fail on A's removed runs, leaving a
    # finished dataset marked unfinished. B now stops and writes nothing.
    from r2rsim.sweep._store import MARKER, SweepStore

    sw, _ = qs
    out = tmp_path / "out"
    out.mkdir()
    plan = plan_sweep(sw)
    (out / MARKER).write_text(json.dumps({"sweep": plan.sweep.name}), encoding="utf-8")
    store = SweepStore(out, plan, False)
    store.inspect()
    assert store.mode == "resume"
    (out / MARKER).unlink()  # A finished in between
    with pytest.raises(
        InputError,
        match="another r2rsim sweep finished writing .* while "
        "this one was starting; run the command again",
    ):
        store.begin()
    assert not (out / MARKER).exists() and not (out / ".work").exists()


@pytest.mark.parametrize(
    "raised, code, words",
    [
        (
            OSError(28, "No space left on device", "out/.work/x.parquet"),
            1,
            "error: cannot write the sweep's files: No space left on device (out/.work/x.parquet). "
            "The finished runs are kept",
        ),
        (
            KeyboardInterrupt(),
            130,
            "interrupted before this sweep ran a run; runs it finished before, if any, are kept",
        ),
    ],
)
def test_sweep_exits_that_say_what_was_kept(qs, monkeypatch, capsys, raised, code, words):
    import r2rsim.sweep

    def fail(*args, progress=None, **kwargs):
        if isinstance(raised, OSError):
            progress(0, 8, None)  # the sweep began to write
        raise raised

    monkeypatch.setattr(r2rsim.sweep, "run_sweep", fail)
    assert main(["sweep", str(qs[0]), "-q"]) == code
    assert words in capsys.readouterr().err
