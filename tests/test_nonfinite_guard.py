"""No dataset written with exit 0 holds a non-finite value (issue 36, item 7).

A line with a 1e300 m span used to run, exit 0 and write inf into `state.span1.length_m`: the
solver's states were finite, and so were the outputs in float64, but the samples are stored
as float32. Two guards now: absurd magnitudes are refused when the files load (with the
accepted range in the message), and the dataset writer checks every chunk of the `true.`,
`state.`, `act.` and `cmd.` columns as written, so that a run that still writes a value that
is not finite fails (exit 1, marked in runs.parquet `nonfinite_from_t_s`)."""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

import r2rsim
from r2rsim.cli import main
from r2rsim.dataset.validate import validate_dataset
from r2rsim.dataset.writer import DatasetWriter
from r2rsim.errors import InputError, PlausibilityWarning
from r2rsim.schema.loader import build_scenario

from conftest import REPO, SMALL_LINE, SMALL_SCENARIO, edited


def _write(tmp_path, line=SMALL_LINE, scenario=SMALL_SCENARIO):
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(line, sort_keys=False))
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(scenario, sort_keys=False))
    return tmp_path / "line.yaml", tmp_path / "scen.yaml"


# --- (a) the 1e300 m span is refused at load --------------------------------------------------


def test_a_1e300_m_span_is_refused_at_load_with_its_range(tmp_path, capsys):
    line, scen = _write(tmp_path, edited(SMALL_LINE, ["spans", 0, "length"], "1e300 m"))
    out = tmp_path / "out"
    assert main(["run", str(scen), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("error: ") and f"{line}: spans[0].length: " in err, err
    assert "span length 1e+300 m is outside 1 mm .. 10 km" in err, err
    assert not out.exists() and not any(p.name.startswith(".out") for p in tmp_path.iterdir())
    assert main(["validate", str(line)]) == 2
    err = capsys.readouterr().err
    assert "line.yaml: spans[0].length: span length 1e+300 m is outside 1 mm .. 10 km" in err


# --- (b) the writer checks every chunk ---------------------------------------------------------


def _chunk(t, **cols):
    n = len(t)
    data = {"k": np.arange(n, dtype=np.int64), "t_s": np.asarray(t, dtype=np.float64)}
    for name, values in cols.items():
        data[name.replace("__", ".")] = np.asarray(values, dtype=np.float64)
    return data


@pytest.fixture
def writer(tmp_path):
    w = DatasetWriter(tmp_path / "ds", "r1", {})
    yield w
    w.abort()


FINE = [1.0, 2.0, 3.0, 4.0]
T = [0.0, 0.1, 0.2, 0.3]


def _cols(**changes):
    cols = {
        "meas__lc__tension_N": FINE,
        "true__lc__tension_N": FINE,
        "state__span1__length_m": FINE,
        "state__idler1__tension_ratio": FINE,
        "state__splice_joint1__lead_m": FINE,
        "act__pull__torque_N_m": FINE,
        "cmd__pull__torque_N_m": FINE,
        "ctrl__speed__error_rad_s": FINE,
        "sp__line_speed_m_s": FINE,
    }
    cols.update(changes)
    return cols


def test_the_writer_finds_a_float64_value_that_overflows_float32(writer):
    writer.write_chunk(_chunk(T, **_cols(state__span1__length_m=[1.0, 1.0, 1e300, 1.0])))
    assert writer.first_nonfinite == (0.2, "state.span1.length_m")


def test_the_writer_ignores_meas_ctrl_and_sp_columns(writer):
    # NaN marks a dropout in a meas. column; sp. and ctrl. columns are not checked
    writer.write_chunk(
        _chunk(
            T,
            **_cols(
                meas__lc__tension_N=[1e300, math.nan, 1.0, math.inf],
                ctrl__speed__error_rad_s=[math.inf] * 4,
                sp__line_speed_m_s=[1e300] * 4,
            ),
        )
    )
    assert writer.first_nonfinite is None


def test_the_first_chunk_with_a_bad_value_gives_the_time(writer):
    writer.write_chunk(_chunk(T, **_cols()))
    assert writer.first_nonfinite is None
    writer.write_chunk(
        _chunk(
            [0.4, 0.5, 0.6, 0.7],
            **_cols(
                act__pull__torque_N_m=[1.0, 1.0, 1.0, math.nan],
                true__lc__tension_N=[1.0, 1.0, -1e39, 1.0],
            ),
        )
    )
    assert writer.first_nonfinite == (0.6, "true.lc.tension_N")
    writer.write_chunk(_chunk([0.8, 0.9, 1.0, 1.1], **_cols(cmd__pull__torque_N_m=[math.inf] * 4)))
    assert writer.first_nonfinite == (0.6, "true.lc.tension_N")  # the earliest stays
    assert writer.n_rows == 12


@pytest.mark.parametrize(
    "column, values, found",
    [
        # float32's largest is 3.4028235e38: just below is written as it is, just above is inf
        ("state__span1__length_m", [3.4e38] * 4, False),
        ("state__span1__length_m", [3.5e38] * 4, True),
        ("act__pull__torque_N_m", [-3.5e38] * 4, True),
        ("cmd__pull__torque_N_m", [math.nan] * 4, True),
        # not defined, written as null: the tension ratio next to a slack span (T_hi/0), the
        # lead of an absent joint
        ("state__idler1__tension_ratio", [math.inf] * 4, False),
        ("state__idler1__tension_ratio", [math.nan] * 4, False),
        ("state__splice_joint1__lead_m", [math.nan] * 4, False),
        ("state__splice_joint1__lead_m", [math.inf] * 4, False),
    ],
)
def test_which_values_count(writer, column, values, found):
    writer.write_chunk(_chunk(T, **_cols(**{column: values})))
    assert writer.first_nonfinite == ((0.0, column.replace("__", ".")) if found else None)


def test_undefined_values_are_written_as_null_never_as_nan_or_inf(writer):
    import pyarrow.parquet as pq

    writer.write_chunk(
        _chunk(
            T,
            **_cols(
                state__idler1__tension_ratio=[2.0, math.inf, 3.0, math.nan],
                state__splice_joint1__lead_m=[math.nan] * 4,
            ),
        )
    )
    writer._flush_row_group()
    writer._writer.close()
    writer._writer = None
    table = pq.read_table(writer._samples)
    assert table["state.idler1.tension_ratio"].to_pylist() == [2.0, None, 3.0, None]
    assert table["state.splice_joint1.lead_m"].null_count == 4
    for name in table.column_names:
        if name.startswith(("true.", "state.", "act.", "cmd.")):
            values = table[name].drop_null().to_numpy()
            assert np.isfinite(values).all(), name


def test_a_column_given_as_float32_is_checked_too(writer):
    data = _chunk(T, **_cols())
    data["state.span1.length_m"] = np.array([1.0, np.inf, 1.0, 1.0], dtype=np.float32)
    writer.write_chunk(data)
    assert writer.first_nonfinite == (0.1, "state.span1.length_m")


# --- (c) a run writing a value that is not finite fails ---------------------------------------

POISON_T = 0.5  # from this sample on, state.span1.length_m is 1e300 (inf in float32)


@pytest.fixture
def poisoned(monkeypatch):
    """Every run of this test writes 1e300 into state.span1.length_m from t = 0.5 s, as the
    1e300 m span did before it was refused (no valid input is known to do it now)."""
    import r2rsim.run as run_module

    flush = run_module._ChunkSink._flush

    def poisoned_flush(self, terminated):
        data = self.held[-1]
        col = "state.span1.length_m"
        data[col] = np.where(data["t_s"] >= POISON_T - 1e-9, 1e300, data[col])
        flush(self, terminated)

    monkeypatch.setattr(run_module._ChunkSink, "_flush", poisoned_flush)


def _short_quickstart(tmp_path):
    d = yaml.safe_load((REPO / "scenarios" / "quickstart.yaml").read_text())
    d["line"] = str((REPO / "lines" / "pet_film_line.yaml").resolve())
    d["duration"] = "1 s"
    path = tmp_path / "qs.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def test_a_run_writing_inf_exits_1_with_its_dataset_marked(tmp_path, capsys, poisoned):
    scen = _short_quickstart(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(scen), "-o", str(out), "-q"]) == 1
    cap = capsys.readouterr()
    assert f"error: {scen}: states not finite from t = 0.5 s; the dataset is written" in cap.err, (
        cap.err
    )
    assert "the samples column state.span1.length_m is not finite from t = 0.5 s" in cap.err
    assert "FAILED       states not finite (nan or inf) from t = 0.5000 s" in cap.out
    runs = pq.read_table(out / "runs.parquet").to_pylist()[0]
    assert runs["nonfinite_from_t_s"] == pytest.approx(POISON_T)
    assert runs["ended_as_expected"] is False and runs["terminated"] is False
    samples = pq.read_table(next((out / "samples").glob("*/part-0.parquet")))
    t = samples["t_s"].to_numpy()
    x = samples["state.span1.length_m"].to_numpy()
    assert np.isfinite(x[t < POISON_T - 1e-9]).all() and np.isinf(x[t >= POISON_T - 1e-9]).all()
    assert validate_dataset(out) == []  # written, marked, and a valid dataset

    summary = r2rsim.run_scenario(scen, output=tmp_path / "api")
    assert not summary.ok and summary.nonfinite_t == pytest.approx(POISON_T)


def test_such_a_run_counts_as_failed_in_a_sweep(tmp_path, poisoned):
    from r2rsim.sweep import run_sweep

    scen = _short_quickstart(tmp_path)
    sw = tmp_path / "sweep.yaml"
    sw.write_text(f"name: t\nscenario: {scen}\nseeds: 1\n")
    s = run_sweep(sw, output=tmp_path / "sw", workers=0)
    assert s.failed == 1 and s.done == 0 and not s.ok
    assert s.failures == [(s.failures[0][0], "states not finite from t = 0.5 s")]
    runs = pq.read_table(tmp_path / "sw" / "runs.parquet").to_pylist()
    assert [r["nonfinite_from_t_s"] for r in runs] == [pytest.approx(POISON_T)]


def test_a_clean_run_is_not_marked(tmp_path, capsys):
    scen = _short_quickstart(tmp_path)
    assert main(["run", str(scen), "-o", str(tmp_path / "out"), "-q"]) == 0
    assert "not finite" not in capsys.readouterr().err
    runs = pq.read_table(tmp_path / "out" / "runs.parquet").to_pylist()[0]
    assert runs["nonfinite_from_t_s"] is None and runs["ended_as_expected"] is True


# --- (d) every new bound: just inside passes, just outside fails -----------------------------


def _line(name: str) -> dict:
    return yaml.safe_load((REPO / "lines" / f"{name}.yaml").read_text(encoding="utf-8"))


def _index(items, key, value) -> int:
    return next(i for i, x in enumerate(items) if x.get(key) == value)


NEWS, DANCER, TESTBED, REG = (
    _line("newsprint_line"),
    _line("pet_film_line_dancer"),
    _line("thesis_testbed"),
    _line("second_registration_line"),
)
FEST = _index(NEWS["spans"], "id", "festoon")
DAN = _index(DANCER["elements"], "type", "dancer")
PIVOT = _index(TESTBED["elements"], "type", "pivot_dancer")
LOOP = _index(DANCER["controllers"], "type", "dancer_pi")
PITCH = _index(REG["sensors"], "type", "pitch_length")


def _thick(thickness: float) -> dict:
    """SMALL_LINE with every radius at least 0.15 m, so that a web up to 0.1 m thick wraps."""
    d = edited(SMALL_LINE, ["web", "thickness"], thickness)
    for i, r in (
        (0, {"core_radius": 0.15, "outer_radius": 0.5, "core_inertia": 0.5}),
        (3, {"core_radius": 0.15, "outer_radius": 0.3, "core_inertia": 0.5}),
    ):
        d["elements"][i]["roll"] = r
    d["elements"][1]["radius"] = d["elements"][2]["radius"] = 0.15
    return d


def _encoder(window: float) -> dict:
    d = copy.deepcopy(SMALL_LINE)
    d["sensors"].append(
        {
            "id": "enc",
            "type": "encoder",
            "element": "pull",
            "counts_per_rev": 1024,
            "window": window,
        }
    )
    return d


def _pitch_q1(scale: float) -> dict:
    """The registration line with q1 making L0(R) = q0 + q1·R³ reach 100 m x ``scale`` at the
    largest radius of its unwind's rolls."""
    d = copy.deepcopy(REG)
    law = d["sensors"][PITCH]["relaxed_pitch_law"]
    line = r2rsim.load_line(REG)
    u = line.elements[0]
    r_max = max(r.outer_radius for r in [u.roll] + ([u.spare_roll] if u.spare_roll else []))
    q0 = line.sensors[PITCH].relaxed_pitch_law.q0
    law["q1"] = (100.0 * scale - q0) / r_max**3
    return d


def _scen_step(**step) -> dict:
    return edited(
        SMALL_SCENARIO, ["programme"], [{"at": 0, "line_speed": "1 m/s"}, {"at": 0.1, **step}]
    )


# (name, which, build(value), inside, outside, yaml path, words of the message)
BOUNDS = [
    # named bounds
    (
        "span length",
        "line",
        lambda v: edited(SMALL_LINE, ["spans", 0, "length"], v),
        1e4,
        1.01e4,
        "spans[0].length",
        "span length 10100 m is outside 1 mm .. 10 km",
    ),
    (
        "roller radius, upper",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 1, "radius"], v),
        10.0,
        10.1,
        "elements[1].radius",
        "radius 10.1 m is outside 1 mm .. 10 m",
    ),
    (
        "roller radius, lower",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 1, "radius"], v),
        1e-3,
        0.99e-3,
        "elements[1].radius",
        "radius 0.00099 m is outside 1 mm .. 10 m",
    ),
    (
        "core radius, lower",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 0, "roll", "core_radius"], v),
        1e-3,
        0.99e-3,
        "elements[0].roll.core_radius",
        "is outside 1 mm .. 10 m",
    ),
    (
        "roll radius, upper",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 0, "roll", "outer_radius"], v),
        10.0,
        10.1,
        "elements[0].roll.outer_radius",
        "radius 10.1 m is outside 1 mm .. 10 m",
    ),
    (
        "thickness, lower",
        "line",
        lambda v: edited(SMALL_LINE, ["web", "thickness"], v),
        1e-8,
        0.99e-8,
        "web.thickness",
        "thickness 9.9e-09 m is outside 10 nm .. 100 mm",
    ),
    (
        "thickness, upper",
        "line",
        _thick,
        0.1,
        0.101,
        "web.thickness",
        "thickness 0.101 m is outside 10 nm .. 100 mm",
    ),
    (
        "build per wrap, lower",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 0, "roll", "build_per_wrap"], v),
        1e-8,
        0.99e-8,
        "elements[0].roll.build_per_wrap",
        "is outside 10 nm .. 100 mm",
    ),
    (
        "build per wrap, upper",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 0, "roll", "build_per_wrap"], v),
        0.1,
        0.101,
        "elements[0].roll.build_per_wrap",
        "is outside 10 nm .. 100 mm",
    ),
    (
        "width",
        "line",
        lambda v: edited(SMALL_LINE, ["web", "width"], v),
        100.0,
        101.0,
        "web.width",
        "width 101 m is outside 0 m .. 100 m",
    ),
    (
        "friction coefficient",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 1, "friction_coefficient"], v),
        10.0,
        10.1,
        "elements[1].friction_coefficient",
        "friction coefficient 10.1 is outside 0 .. 10",
    ),
    (
        "festoon stroke",
        "line",
        lambda v: edited(NEWS, ["spans", FEST, "festoon", "stroke"], [0.0, v]),
        1e4,
        1.01e4,
        f"spans[{FEST}].festoon.stroke",
        "travel 10100 m is outside -10 km .. 10 km",
    ),
    (
        "dancer travel",
        "line",
        lambda v: edited(
            DANCER,
            ["elements", DAN, "travel_range"],
            [DANCER["elements"][DAN]["travel_range"][0], v],
        ),
        1e4,
        1.01e4,
        f"elements[{DAN}].travel_range",
        "is outside -10 km .. 10 km",
    ),
    (
        "festoon rollers",
        "line",
        lambda v: edited(NEWS, ["spans", FEST, "festoon", "moving_rollers"], v),
        1000,
        1001,
        f"spans[{FEST}].festoon.moving_rollers",
        "moving_rollers 1001 is outside 1 .. 1000",
    ),
    (
        "encoder window",
        "line",
        _encoder,
        1e-6,
        0.99e-6,
        "sensors[1].window",
        "counting window 9.9e-07 s is outside 1e-06 s .. 1e+06 s",
    ),
    (
        "dancer direction",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "direction"], [0.0, -v]),
        1e3,
        1.01e3,
        f"elements[{DAN}].direction",
        "direction component -1010 is outside -1000 .. 1000",
    ),
    (
        "dancer set-point",
        "line",
        lambda v: edited(DANCER, ["controllers", LOOP, "setpoint"], v),
        1e4,
        1.01e4,
        f"controllers[{LOOP}].setpoint",
        "position set-point 10100 m is outside -10 km .. 10 km",
    ),
    (
        "tension set-point",
        "line",
        lambda v: edited(SMALL_LINE, ["controllers", 1, "setpoint"], v),
        1e7,
        1.01e7,
        "controllers[1].setpoint",
        "tension 1.01e+07 N is outside 0 N .. 1e+07 N",
    ),
    (
        "pitch law",
        "line",
        _pitch_q1,
        0.999,
        1.001,
        f"sensors[{PITCH}].relaxed_pitch_law.q1",
        "is longer than any span (100 m)",
    ),
    (
        "line speed",
        "scen",
        lambda v: edited(SMALL_SCENARIO, ["programme", 0, "line_speed"], v),
        1e3,
        1.01e3,
        "programme[0].line_speed",
        "line speed 1010 m/s is outside -1000 m/s .. 1000 m/s",
    ),
    (
        "programme tension",
        "scen",
        lambda v: edited(SMALL_SCENARIO, ["programme", 0, "tension"], {"tens": v}),
        1e7,
        1.01e7,
        "programme[0].tension.tens",
        "tension 1.01e+07 N is outside 0 N .. 1e+07 N",
    ),
    (
        "initial tension",
        "scen",
        lambda v: edited(SMALL_SCENARIO, ["initial"], {"state": "nominal", "tension": v}),
        1e7,
        1.01e7,
        "initial.tension",
        "tension 1.01e+07 N is outside 0 N .. 1e+07 N",
    ),
    # MAGNITUDE_MAX, one field of each dimension
    (
        "length",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 1, "position"], [v, 0.0]),
        1e5,
        1.01e5,
        "elements[1].position",
        "length 101000 m is outside -100 km .. 100 km",
    ),
    (
        "speed",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "smoothing_speed"], v),
        1e3,
        1.01e3,
        f"elements[{DAN}].smoothing_speed",
        "speed 1010 m/s is outside 0 m/s .. 1000",
    ),
    (
        "acceleration",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "gravity"], [0.0, -v]),
        1e3,
        1.01e3,
        f"elements[{DAN}].gravity",
        "acceleration -1010 m/s^2 is outside -1000 m/s^2 .. 1000 m/s^2",
    ),
    (
        "time",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 2, "drive"], {"torque_lag": v}),
        1e6,
        1.01e6,
        "elements[2].drive.torque_lag",
        "time 1.01e+06 s is outside 0 s .. 1e+06 s",
    ),
    (
        "frequency",
        "line",
        lambda v: edited(SMALL_LINE, ["sensors", 0, "rate"], v),
        1e6,
        1.01e6,
        "sensors[0].rate",
        "frequency 1.01e+06 Hz is outside 0 Hz .. 1e+06 Hz",
    ),
    (
        "force",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "load_force"], v),
        1e7,
        1.01e7,
        f"elements[{DAN}].load_force",
        "force 1.01e+07 N is outside -1e+07 N .. 1e+07 N",
    ),
    (
        "stiffness",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "spring_stiffness"], v),
        1e9,
        1.01e9,
        f"elements[{DAN}].spring_stiffness",
        "is outside 0 N/m .. 1e+09 N/m",
    ),
    (
        "damping",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "damping"], v),
        1e9,
        1.01e9,
        f"elements[{DAN}].damping",
        "is outside 0 N*s/m .. 1e+09 N*s/m",
    ),
    (
        "mass",
        "line",
        lambda v: edited(DANCER, ["elements", DAN, "mass"], v),
        1e6,
        1.01e6,
        f"elements[{DAN}].mass",
        "mass 1.01e+06 kg is outside 0 kg .. 1e+06 kg",
    ),
    (
        "inertia",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 1, "inertia"], v),
        1e10,
        1.01e10,
        "elements[1].inertia",
        "inertia 1.01e+10 kg*m^2 is outside 0 kg*m^2 .. 1e+10",
    ),
    (
        "torque",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 2, "drive"], {"torque_max": v}),
        1e7,
        1.01e7,
        "elements[2].drive.torque_max",
        "torque 1.01e+07 N*m is outside 0 N*m ..",
    ),
    (
        "viscous torque",
        "line",
        lambda v: edited(TESTBED, ["elements", PIVOT, "damping"], v),
        1e6,
        1.01e6,
        f"elements[{PIVOT}].damping",
        "is outside 0 N*m*s .. 1e+06 N*m*s",
    ),
    (
        "angle",
        "line",
        lambda v: edited(
            TESTBED, ["elements", PIVOT, "torsion_spring"], {"stiffness": 0.0, "free_angle": v}
        ),
        100.0,
        101.0,
        f"elements[{PIVOT}].torsion_spring.free_angle",
        "angle 101 rad is outside -100 rad .. 100 rad",
    ),
    (
        "angular speed",
        "line",
        lambda v: edited(SMALL_LINE, ["elements", 1, "friction"], {"smoothing_speed": v}),
        1e6,
        1.01e6,
        "elements[1].friction.smoothing_speed",
        "is outside 0 rad/s .. 1e+06 rad/s",
    ),
    (
        "dimensionless",
        "line",
        lambda v: edited(NEWS, ["elements", 0, "splicer", "joint"], {"stiffness_ratio": v}),
        1e3,
        1.01e3,
        "elements[0].splicer.joint.stiffness_ratio",
        "dimensionless 1010 is outside 0 .. 1000",
    ),
    (
        "a scenario's acceleration",
        "scen",
        lambda v: _scen_step(line_speed="2 m/s", rate=v),
        1e3,
        1.01e3,
        "programme[1].rate",
        "acceleration 1010 m/s^2 is outside 0 m/s^2 ..",
    ),
]


def _load(which, data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlausibilityWarning)  # a value at a bound may warn
        if which == "line":
            r2rsim.load_line(data, file="line.yaml")
        else:
            build_scenario(data, SMALL_LINE, "scen.yaml", "line.yaml")


@pytest.mark.parametrize("case", BOUNDS, ids=[c[0] for c in BOUNDS])
def test_each_bound_inside_passes_and_outside_fails(case):
    _, which, build, inside, outside, ypath, words = case
    _load(which, build(inside))
    with pytest.raises(InputError) as exc:
        _load(which, build(outside))
    msg = str(exc.value)
    assert f"{which if which == 'line' else 'scen'}.yaml: {ypath}: " in msg, msg
    assert words in msg, msg


def test_the_bounds_do_not_touch_the_shipped_files():
    """Every shipped line and scenario loads without a plausibility error or warning (the
    full check, with sweeps, is tests/test_input_robustness.py)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        for p in sorted((REPO / "lines").glob("*.yaml")):
            r2rsim.load_line(p)
        for p in sorted((REPO / "scenarios").rglob("*.yaml")):
            if "scenario" not in yaml.safe_load(p.read_text(encoding="utf-8")):
                r2rsim.load_scenario(p)
