"""Realistic sensors (issue 16): edge-counting encoders (unbiased), the relaxed-pitch law
L0(R) = q0 + q1·R³ and printing variation of a pitch_length sensor, speed-dependent noise."""

from __future__ import annotations

import copy
import math

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim
from r2rsim.cli import main
from r2rsim.compile import compile_line
from r2rsim.compile.disturbances import realise_pitch_variations
from r2rsim.measure.sensors import MeasurementModel
from r2rsim.schema.loader import load_line
from r2rsim.solve.initial import nominal_state

from conftest import REPO, SMALL_LINE, SMALL_SCENARIO

REG = yaml.safe_load((REPO / "lines" / "registration.yaml").read_text())
Q0, Q1 = 0.25, 0.02  # L0(R) = q0 + q1·R³ [m, 1/m²]
STD, ELL = 8e-6, 2.0  # printing variation: std [m], correlation length [m]


def _reg_line(pitch=None, extra_sensors=()):
    d = copy.deepcopy(REG)
    sb = next(s for s in d["sensors"] if s["id"] == "sensor_B")
    if pitch is not None:
        del sb["relaxed_pitch"]
        sb.update(pitch)
    d["sensors"] += list(extra_sensors)
    return d


def _encoder_model(speed, cpr=4096, rate=200.0, window=None, seed=3, duration=60.0):
    enc = {
        "id": "enc",
        "type": "encoder",
        "element": "reg_drive",
        "counts_per_rev": cpr,
        "rate": rate,
    }
    if window is not None:
        enc["window"] = window
    cl = compile_line(load_line(_reg_line(extra_sensors=[enc]), "line.yaml"))
    t = np.arange(int(round(duration * rate)) + 1) / rate
    aux = np.zeros((len(t), len(cl.aux_names)))
    w = speed(t)
    aux[:, cl.aux_index("enc.speed_rad_s")] = w
    aux[:, cl.aux_index("enc.speed_seen_rad_s")] = w
    return cl, t, aux, (lambda: MeasurementModel(cl, rate, np.random.SeedSequence(seed)))


def _chunked(model, t, aux, sizes):
    out, i = [], 0
    for n in sizes:
        out.append(model.measure(t[i : i + n], aux[i : i + n]))
        i += n
    out.append(model.measure(t[i:], aux[i:]))
    return {k: np.concatenate([o[k] for o in out]) for k in out[0]}


# ---------------------------------------------------------------------------- encoder
def test_encoder_counts_unbiased_at_constant_speed():
    """5.0 rad/s, 4096 counts/rev, 200 Hz: the old per-sample rounding read 4.909 rad/s
    (-1.8 %, zero variance); the count difference is unbiased to one count over the run."""
    cpr, rate, true = 4096, 200.0, 5.0
    _, t, aux, make = _encoder_model(lambda t: np.full_like(t, true), cpr, rate)
    m = make().measure(t, aux)["meas.enc.speed_rad_s"]
    q = 2 * math.pi / cpr * rate  # one count per window (window = 1/rate)
    old = np.round(true / q) * q
    assert abs(old - true) > 0.05  # the bias the old rounding had
    n = len(m)
    assert abs(m.mean() - true) < q / n + 1e-9
    assert np.abs(m - true).max() <= q + 1e-9  # within one count per window
    assert set(np.round(m / q).astype(int)) <= {16, 17}  # 16.30 counts per window
    assert m.std() > 0  # quantisation noise, not a fixed offset


def test_encoder_non_integer_ratio_and_random_phase():
    """Several seeds (initial angles): each unbiased; the reading is not the same sequence
    for every seed (the quantisation phase is drawn)."""
    cpr, rate = 4096, 200.0
    q = 2 * math.pi / cpr * rate
    seqs = []
    for seed in (1, 2, 3):
        _, t, aux, make = _encoder_model(
            lambda t: np.full_like(t, 5.0), cpr, rate, seed=seed, duration=10.0
        )
        m = make().measure(t, aux)["meas.enc.speed_rad_s"]
        assert abs(m.mean() - 5.0) < q / len(m) + 1e-9
        seqs.append(m[:50])
    assert not (np.array_equal(seqs[0], seqs[1]) and np.array_equal(seqs[1], seqs[2]))


def test_encoder_window_varying_speed_and_chunking():
    """A 50 ms counting window on a varying speed: the reading is the window's mean speed
    to one count; chunked measurement gives identical output."""
    cpr, rate, win = 1024, 200.0, 0.05

    def speed(t):
        return 8.0 + 2.0 * np.sin(2 * math.pi * 0.5 * t)

    _, t, aux, make = _encoder_model(speed, cpr, rate, window=win, duration=60.0)
    full = make().measure(t, aux)
    m = full["meas.enc.speed_rad_s"]
    # exact mean speed over [t - win, t]
    ang = lambda x: 8.0 * x - 2.0 / (2 * math.pi * 0.5) * np.cos(2 * math.pi * 0.5 * x)  # noqa: E731
    ref = (ang(t) - ang(t - win)) / win
    res = 2 * math.pi / cpr / win
    k = t >= win
    # trapezoid integration of the 200 Hz samples: error ~ dt²·|w''|/12 per unit time
    assert np.abs(m[k] - ref[k]).max() <= res + 1e-5
    assert abs((m[k] - ref[k]).mean()) < 0.02 * res
    chunked = _chunked(make(), t, aux, [1, 7, 333, 2, 1000, 4500])
    for key in full:
        np.testing.assert_array_equal(full[key], chunked[key])


def test_encoder_window_needs_counts(tmp_path, capsys):
    enc = {"id": "enc", "type": "encoder", "element": "pull", "window": "10 ms"}
    _expect_error(
        tmp_path,
        capsys,
        _line_with(sensors=[enc]),
        "sensors[1]",
        "window applies to an encoder with counts_per_rev",
    )


# ---------------------------------------------------------------------------- pitch
def _pitch_rows(cl, s_values, u_values, strain=0.0):
    """States at which the pitch is evaluated: unwind radius set by its length s,
    the unwound length u, the registration span at ``strain``."""
    y = nominal_state(cl, 130.0)
    Y = np.repeat(y[None], len(s_values), axis=0)
    Y[:, cl.index("unwind.length")] = s_values
    Y[:, cl.index("unwind.unstretched_length")] = u_values
    Y[:, cl.index("registration.strain")] = strain
    A = cl.outputs(0.0, Y)
    R = A[:, cl.aux_index("unwind.radius_m")]
    T = A[:, cl.aux_index("registration.tension_N")]
    pitch = A[:, cl.aux_index("sensor_B.pitch_m")]
    return R, T, pitch, A


def test_relaxed_pitch_law():
    """The true pitch over a roll's life equals (T/EA + 1)·(q0 + q1·R³)."""
    law = {"relaxed_pitch_law": {"q0": f"{Q0} m", "q1": f"{Q1} 1/m^2", "unwind": "unwind"}}
    cl = compile_line(load_line(_reg_line(law), "line.yaml"))
    EA = cl.line.web.EA
    s = np.linspace(0.0, 4000.0, 9)  # unwind radius 0.30 m down towards the core
    for strain in (0.0, 1.2e-3):
        R, T, pitch, _ = _pitch_rows(cl, s, np.zeros_like(s), strain)
        assert R[0] > R[-1] + 0.05
        np.testing.assert_allclose(pitch, (T / EA + 1) * (Q0 + Q1 * R**3), rtol=1e-13)
    # the controller reads it as tension through the same law: at the set-point the loop error
    # is zero where the pitch equals (T_ref/EA + 1)·L0(R)
    assert (Q0 + Q1 * R[0] ** 3) - (Q0 + Q1 * R[-1] ** 3) > 1e-4


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pitch_variation_statistics(seed):
    """Over 4000 correlation lengths of web, the variation has the declared std and
    correlation length (correlation 1/e at lag ℓ) within sampling error; a seed repeats."""
    d = _reg_line(
        {
            "relaxed_pitch": f"{Q0} m",
            "pitch_variation": {"std": f"{STD * 1e6:g} um", "correlation_length": f"{ELL} m"},
        }
    )
    line = load_line(d, "line.yaml")
    var = realise_pitch_variations(line, np.random.SeedSequence(seed))
    again = realise_pitch_variations(line, np.random.SeedSequence(seed))
    np.testing.assert_array_equal(var["sensor_B"], again["sensor_B"])
    # its stream is at a fixed key: streams spawned before (the disturbances') do not move it
    spawned = np.random.SeedSequence(seed)
    spawned.spawn(3)
    np.testing.assert_array_equal(
        var["sensor_B"], realise_pitch_variations(line, spawned)["sensor_B"]
    )
    cl = compile_line(line, pitch_variations=var)
    du = 0.05
    u = np.arange(0.0, 4000 * ELL, du)
    s0 = np.zeros_like(u)
    _, T, pitch, _ = _pitch_rows(cl, s0, u)
    delta = pitch / (T / line.web.EA + 1) - Q0
    assert abs(delta.std() / STD - 1) < 0.08
    assert abs(delta.mean()) < 0.1 * STD
    x = delta - delta.mean()
    lags = np.arange(0, int(3 * ELL / du))
    acf = np.array([np.dot(x[: len(x) - k], x[k:]) / (len(x) - k) for k in lags]) / x.var()
    ell_est = du * np.argmax(acf < math.exp(-1))
    assert abs(ell_est / ELL - 1) < 0.08
    np.testing.assert_allclose(
        acf[:: int(0.5 / du)], np.exp(-((lags[:: int(0.5 / du)] * du / ELL) ** 2)), atol=0.08
    )
    # smooth: no knots (the second difference is tiny compared with the signal)
    assert np.abs(np.diff(delta, 2)).max() < 0.01 * STD


def test_pitch_in_a_run_law_variation_and_loop(tmp_path):
    """A run of the registration line with the law and the variation, the loop closed on the
    pitch: same seed gives identical data, another seed other data; the true pitch follows
    (T/EA + 1)·L0 with L0 - L0(R) the zero-mean variation, and the loop turns the variation
    into a real tension disturbance (T - T_ref ≈ -EA·δ/L0)."""
    d = _reg_line(
        {
            "relaxed_pitch_law": {"q0": f"{Q0} m", "q1": f"{Q1} 1/m^2"},
            "pitch_variation": {"std": "8 um", "correlation_length": "3 m"},
            "noise": "2 um",
        }
    )
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    scen = {
        "line": "line.yaml",
        "duration": "20 s",
        "record_rate": "50 Hz",
        "seed": 7,
        "initial": {"state": "steady"},
        "programme": [{"at": 0, "line_speed": "0.5 m/s"}],
    }
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(scen, sort_keys=False))
    frames = []
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        r2rsim.run_scenario(tmp_path / "s.yaml", output=tmp_path / name, seed=seed)
        frames.append(pd.read_parquet(tmp_path / name / "samples"))
    a, b, c = frames
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a["true.sensor_B.pitch_m"], c["true.sensor_B.pitch_m"])
    EA = load_line(d, "line.yaml").web.EA
    T = a["state.registration.tension_N"].to_numpy()
    R = a["state.unwind.radius_m"].to_numpy()
    L0 = a["true.sensor_B.pitch_m"].to_numpy() / (T / EA + 1)
    delta = L0 - (Q0 + Q1 * R**3)
    k = a["t_s"].to_numpy() > 1.0
    assert 3e-6 < delta[k].std() < 15e-6
    # the pitch loop holds the pitch: the variation shows up in the tension
    dT = T[k] - 130.0
    assert np.corrcoef(dT, delta[k])[0, 1] < -0.8
    assert abs(dT.std() / (EA * delta[k].std() / Q0) - 1) < 0.3


# ---------------------------------------------------------------------------- vibration
@pytest.mark.parametrize(
    "sensor, col",
    [
        (
            {"id": "lcx", "type": "load_cell", "element": "reg_idler", "noise_per_speed": 0.8},
            "tension_N",
        ),
        (
            {
                "id": "px",
                "type": "pitch_length",
                "span": "registration",
                "relaxed_pitch": "0.25 m",
                "noise_per_speed": 4e-6,
            },
            "pitch_m",
        ),
    ],
)
def test_noise_per_speed_scales_with_speed(sensor, col):
    """The added noise std is noise_per_speed·|v| at two speeds (20 000 samples each: ~0.5 %
    sampling error)."""
    cl = compile_line(load_line(_reg_line(extra_sensors=[sensor]), "line.yaml"))
    sid = sensor["id"]
    node = "reg_idler"  # the load cell's element; downstream of the registration span
    n = 20000
    stds = []
    for v in (0.5, 2.0):
        t = np.arange(n) / 100.0
        aux = np.zeros((n, len(cl.aux_names)))
        aux[:, cl.aux_index(f"{sid}.{col}")] = 1.0
        aux[:, cl.aux_index(f"{sid}.{col.replace('_', '_seen_', 1)}")] = 1.0
        aux[:, cl.aux_index(f"{node}.surface_speed_m_s")] = -v  # |v|
        m = MeasurementModel(cl, 100.0, np.random.SeedSequence(5)).measure(t, aux)
        err = m[f"meas.{sid}.{col}"] - 1.0
        stds.append(err.std())
        assert abs(err.std() / (sensor["noise_per_speed"] * v) - 1) < 0.03
        assert abs(err.mean()) < 4 * err.std() / math.sqrt(n)
    assert abs(stds[1] / stds[0] / 4.0 - 1) < 0.04


def test_new_streams_leave_old_noise_alone():
    """A sensor's nominal noise is the same whether or not it (or another sensor) has the new
    options: those draw from streams spawned after the existing ones."""
    base = {"id": "lcx", "type": "load_cell", "element": "reg_idler", "noise": 0.5}
    outs = []
    for extra in ({}, {"noise_per_speed": 0.0}):
        enc = {"id": "enc", "type": "encoder", "element": "reg_drive", "counts_per_rev": 512}
        cl = compile_line(load_line(_reg_line(extra_sensors=[{**base, **extra}, enc]), "line.yaml"))
        t = np.arange(500) / 100.0
        aux = np.zeros((500, len(cl.aux_names)))
        outs.append(MeasurementModel(cl, 100.0, np.random.SeedSequence(9)).measure(t, aux))
    np.testing.assert_array_equal(outs[0]["meas.lcx.tension_N"], outs[1]["meas.lcx.tension_N"])


# ---------------------------------------------------------------------------- schema
def _line_with(sensors=(), pitch=None):
    d = copy.deepcopy(SMALL_LINE)
    d["sensors"] = d["sensors"] + list(sensors)
    return d


def _expect_error(tmp_path, capsys, line, ypath, words):
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(line, sort_keys=False))
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(SMALL_SCENARIO, sort_keys=False))
    out = tmp_path / "out"
    code = main(["run", str(tmp_path / "scen.yaml"), "-o", str(out), "-q"])
    err = capsys.readouterr().err.strip()
    assert code != 0
    assert len(err.splitlines()) == 1, err
    assert f"line.yaml: {ypath}" in err, err
    assert words in err, err
    assert not out.exists()


PITCH = {"id": "pb", "type": "pitch_length", "span": "span2"}
BAD = [
    ("no relaxed pitch", {**PITCH}, "sensors[1]", "exactly one of them"),
    (
        "both relaxed pitches",
        {**PITCH, "relaxed_pitch": 0.25, "relaxed_pitch_law": {"q0": 0.25, "q1": 0.0}},
        "sensors[1]",
        "exactly one of them",
    ),
    (
        "law on a rewind",
        {**PITCH, "relaxed_pitch_law": {"q0": 0.25, "q1": 0.0, "unwind": "rewind"}},
        "sensors[1].relaxed_pitch_law.unwind",
        "not an unwind",
    ),
    (
        "law on a missing element",
        {**PITCH, "relaxed_pitch_law": {"q0": 0.25, "q1": 0.0, "unwind": "nope"}},
        "sensors[1].relaxed_pitch_law.unwind",
        "'nope'",
    ),
    (
        "law not positive",
        {**PITCH, "relaxed_pitch_law": {"q0": 0.25, "q1": "-20 1/m^2"}},
        "sensors[1].relaxed_pitch_law.q1",
        "must stay positive",
    ),
    (
        "q1 of the wrong unit",
        {**PITCH, "relaxed_pitch_law": {"q0": 0.25, "q1": "2 m"}},
        "sensors[1].relaxed_pitch_law.q1",
        "",
    ),
    (
        "variation std zero",
        {**PITCH, "relaxed_pitch": 0.25, "pitch_variation": {"std": 0, "correlation_length": 2}},
        "sensors[1].pitch_variation.std",
        "> 0",
    ),
    (
        "variation without correlation length",
        {**PITCH, "relaxed_pitch": 0.25, "pitch_variation": {"std": "8 um"}},
        "sensors[1].pitch_variation",
        "correlation_length",
    ),
    (
        "variation as large as the pitch",
        {
            **PITCH,
            "relaxed_pitch": 0.25,
            "pitch_variation": {"std": "5 cm", "correlation_length": 2},
        },
        "sensors[1]",
        "a tenth of the relaxed pitch",
    ),
    (
        "variation correlation length too short",
        {
            **PITCH,
            "relaxed_pitch": 0.25,
            "pitch_variation": {"std": "8 um", "correlation_length": "1 um"},
        },
        "sensors[1].pitch_variation.correlation_length",
        ">= 0.001",
    ),
    (
        "negative noise_per_speed",
        {"id": "e2", "type": "encoder", "element": "pull", "noise_per_speed": -1.0},
        "sensors[1].noise_per_speed",
        ">= 0",
    ),
    (
        "zero window",
        {"id": "e2", "type": "encoder", "element": "pull", "counts_per_rev": 100, "window": 0},
        "sensors[1].window",
        "> 0",
    ),
]


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_sensor_options(tmp_path, capsys, case):
    _, sensor, ypath, words = case
    _expect_error(tmp_path, capsys, _line_with(sensors=[sensor]), ypath, words)


def test_schema_output_documents_new_fields(capsys):
    assert main(["schema", "line"]) == 0
    out = capsys.readouterr().out
    for words in (
        "relaxed_pitch_law",
        "pitch_variation",
        "noise_per_speed",
        "window",
        "counts_per_rev",
        "correlation length",
    ):
        assert words in out, words


def test_pitch_law_jacobian_in_the_loop():
    """With the law and the variation, the analytic Jacobian of the pitch filter and of the
    pitch loop (calibrated with L0(R)) matches central differences in the unwind's radius
    (its length s) and unwound length u."""
    d = _reg_line(
        {
            "relaxed_pitch_law": {"q0": f"{Q0} m", "q1": f"{Q1} 1/m^2"},
            "pitch_variation": {"std": "8 um", "correlation_length": "2 m"},
        }
    )
    cl = compile_line(load_line(d, "line.yaml"))
    y = nominal_state(cl, 130.0)
    y = y + 1e-3 * np.random.default_rng(1).standard_normal(len(y)) * np.abs(y).clip(1e-3)
    y[cl.index("unwind.unstretched_length")] = 3.7
    J = cl.jacobian(0.3, y)
    for col in ("unwind.length", "unwind.unstretched_length"):
        j = cl.index(col)
        h = 1e-4
        yp, ym = y.copy(), y.copy()
        yp[j] += h
        ym[j] -= h
        fd = (cl.rhs(0.3, yp) - cl.rhs(0.3, ym)) / (2 * h)
        for row in ("sensor_B.filtered", "registration_loop.integral"):
            i = cl.index(row)
            assert J[i, j] == pytest.approx(fd[i], rel=1e-5, abs=1e-12), (row, col)
        assert J[cl.index("sensor_B.filtered"), j] != 0.0
