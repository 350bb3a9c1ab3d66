"""The thesis scenario set (scenarios/thesis/, Shui 2018): every file there loads and runs as
is (a short run of 30 s; the dancer failure in full), and the fault scenarios give the known
answers of their fault models.

Known answers (lines/registration.yaml, OC1 = 0.5 m/s, OC2 = 1.0 m/s):

* sensor_A is a monitoring load cell (noise 0.3 N): an offset b appears as mean(meas - true)
  = b after the onset, a gain g ramped in over 10 s as meas = (1 + g·p(t))·true, and the
  process is the fault-free run's.
* sensor_B (pitch length, pitch = (T/EA + 1)·L0) is read by the registration loop, which
  converts it back with the nominal EA and holds the tension it sees at 130 N. With the
  reading multiplied by (1 + g) it holds T = EA·((1 + 130/EA)/(1 + g) - 1). The files map the
  thesis's levels to gains g = +-0.05/0.15·T/(EA + T), i.e. +-5 %/15 % of the tension seen (a
  5 % gain on the pitch itself would mean 5.6 kN: see the files' headers); those runs go the
  full 60 s so the loop settles.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim

from conftest import REPO

THESIS = REPO / "scenarios" / "thesis"
FILES = sorted(THESIS.glob("*.yaml"))
DURATION = 30.0  # s, the short run
ONSET = 20.0  # s, every fault of the set
RAMP = 10.0  # s, the degradation ramp
NOISE_A = 0.3  # N, sensor_A noise std (lines/registration.yaml)
T_SET = 130.0  # N, registration loop set-point
EA = 4.5e9 * 50e-6 * 0.5  # PET 4.5 GPa x 50 um x 0.5 m = 112.5 kN
T_BREAK = 210e6 * 50e-6 * 0.5  # 5.25 kN
REWIND_TORQUE_MAX = 100.0  # N m
TRIM_LIMIT = 0.05  # m/s, registration_loop output_limit

# file stem -> (fault type, target, magnitude in SI, operating mode): the thesis levels mapped
# to numbers as the files' headers say
LEVELS = {"N05": -0.05, "N15": -0.15, "P05": 0.05, "P15": 0.15}
EXPECTED: dict[str, tuple[str, str, float, str]] = {}
for _tag, _r in LEVELS.items():
    EXPECTED[f"sensor_a_offset_{_tag}"] = ("sensor.offset", "sensor_A", _r * T_SET, "OC1")
    # sensor B: a gain equal to an _r error of the tension the loop sees (the files' headers)
    EXPECTED[f"sensor_b_gain_{_tag}"] = (
        "sensor.gain",
        "sensor_B",
        float(f"{_r * T_SET / (EA + T_SET):.4e}"),
        "OC1",
    )
for _oc in ("OC1", "OC2"):
    for _p in (5, 10, 15, 20):
        EXPECTED[f"sensor_a_degradation_P{_p:02d}_{_oc}"] = (
            "sensor.gain",
            "sensor_A",
            _p / 100,
            _oc,
        )
NOMINAL = {"oc1_nominal": ("OC1", 0.5), "oc2_nominal": ("OC2", 1.0)}
NOMINAL_OF = {"OC1": "oc1_nominal", "OC2": "oc2_nominal"}


def ideal_registration_tension(g: float) -> float:
    """True tension at which the registration loop sees 130 N when sensor B reads (1+g)·pitch."""
    return EA * ((1 + T_SET / EA) / (1 + g) - 1)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Run a scenario once (short unless it is the dancer failure) and cache its tables."""
    cache: dict[str, dict] = {}
    base = tmp_path_factory.mktemp("thesis")

    def get(stem: str) -> dict:
        if stem not in cache:
            out = base / stem
            # the dancer failure must reach its break, and the in-loop sensor B faults need
            # the loop to settle (about 25 s after the onset): those run in full
            full = stem == "dancer_failure" or stem.startswith("sensor_b_gain")
            duration = None if full else DURATION
            summary = r2rsim.run_scenario(THESIS / f"{stem}.yaml", output=out, duration=duration)
            cache[stem] = {
                "summary": summary,
                **{k: pd.read_parquet(out / f"{k}.parquet") for k in ("faults", "runs", "events")},
                "samples": pd.read_parquet(out / "samples").sort_values("k").reset_index(drop=True),
            }
        return cache[stem]

    return get


def test_the_set_is_complete_and_distinct():
    stems = {p.stem for p in FILES}
    assert set(EXPECTED) | set(NOMINAL) | {"dancer_failure"} <= stems
    scenarios = [r2rsim.load_scenario(p)[0] for p in FILES]
    names = [s.name for s in scenarios]
    assert None not in names and len(set(names)) == len(names)
    assert all("seed" in yaml.safe_load(p.read_text()) for p in FILES)  # fixed, not default


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_thesis_scenario(path, run):
    scenario, _, line_path = r2rsim.load_scenario(path)
    assert line_path.is_file()
    r = run(path.stem)
    s, faults = r["samples"], r["faults"]
    t = s["t_s"].to_numpy()
    assert len(s) > 0 and np.all(np.diff(t) > 0)
    summary = r["summary"]
    if path.stem != "dancer_failure":  # every other scenario runs to its end
        full = path.stem.startswith("sensor_b_gain")
        duration = scenario.duration if full else DURATION
        assert not summary.terminated, summary.termination_reason
        assert summary.simulated_s == duration
        assert t[-1] == pytest.approx(duration, abs=1e-9)
        assert len(s) == round(duration * scenario.record_rate) + 1
    # labels agree with faults.parquet and the programme's mode (generic: covers new files)
    active = np.zeros(len(s), bool)
    for f in faults.itertuples():
        end = f.end_t_s if not math.isnan(f.end_t_s) else math.inf
        active |= (t >= f.onset_t_s - 1e-9) & (t < end)
    np.testing.assert_array_equal(s["label.is_faulty"].to_numpy(), active)
    modes = [st.mode for st in scenario.programme if st.mode is not None]
    if modes:
        assert set(s["label.mode"].astype(str)) <= set(modes)

    stem = path.stem
    if stem == "dancer_failure":
        check_dancer_failure(r)
    elif stem in NOMINAL:
        check_nominal(r, *NOMINAL[stem])
    elif stem in EXPECTED:
        ftype, target, magnitude, mode = EXPECTED[stem]
        check_fault_row(r, ftype, target, magnitude, mode)
        if stem.startswith("sensor_a_offset"):
            check_sensor_a_offset(r, run(NOMINAL_OF[mode]), magnitude)
        elif stem.startswith("sensor_a_degradation"):
            check_sensor_a_degradation(r, run(NOMINAL_OF[mode]), magnitude)
        else:
            check_sensor_b_gain(r, run(NOMINAL_OF[mode]), magnitude)


def check_dancer_failure(r):
    # the full 90 s: seize at 60 s, fill from 63 s, the web breaks during the changeover
    runs, ev = r["runs"].iloc[0], r["events"]
    assert bool(runs["terminated"]) and runs["termination_reason"] == "web_break"
    assert 63.0 < runs["termination_t_s"] < 90.0
    f, s = r["faults"], r["samples"]
    assert len(f) == 1 and (f.fault_type.iloc[0], f.target_id.iloc[0]) == (
        "dancer.arm_stuck",
        "dancer",
    )
    assert (s["label.is_faulty"].to_numpy() == (s.t_s.to_numpy() >= 60.0)).all()
    assert (s["label.primary_type"][s.t_s >= 60.0] == "dancer.arm_stuck").all()
    seize = ev[ev.kind == "dancer_seized"]
    assert len(seize) == 1 and seize.t_s.iloc[0] == pytest.approx(60.0)
    assert (ev.kind == "web_break").sum() == 1


def check_nominal(r, mode, speed):
    s, runs = r["samples"], r["runs"].iloc[0]
    assert r["faults"].empty and not bool(runs["terminated"])
    assert runs["operating_mode"] == mode
    assert (s["label.mode"].astype(str) == mode).all() and not s["label.is_faulty"].any()
    after = s.t_s >= 5.0  # warm-up
    assert s["sp.line_speed_m_s"].to_numpy() == pytest.approx(speed)
    assert s["state.rewind.surface_speed_m_s"][after].to_numpy() == pytest.approx(speed, rel=1e-4)
    assert s["state.registration.tension_N"][after].to_numpy() == pytest.approx(T_SET, rel=1e-3)


def check_fault_row(r, ftype, target, magnitude, mode):
    f, s = r["faults"], r["samples"]
    assert len(f) == 1
    row = f.iloc[0]
    assert (row.fault_type, row.target_id) == (ftype, target)
    assert row.magnitude == pytest.approx(magnitude, rel=1e-12)
    assert row.magnitude_unit == ("N" if ftype == "sensor.offset" else "rel")
    assert row.onset_t_s == pytest.approx(ONSET) and math.isnan(row.end_t_s)
    before = s.t_s < ONSET
    assert not s["label.is_faulty"][before].any() and s["label.is_faulty"][~before].all()
    assert (s["label.mode"].astype(str) == mode).all()
    assert r["runs"].iloc[0]["operating_mode"] == mode
    # (at the onset sample itself a ramp has p = 0 and label.ch is still False)
    assert s["label.ch." + row.expected_channels[0][len("meas.") :]][s.t_s > ONSET].all()


def _mean_within(x, expected, sigma):
    """mean(x) = expected within 3 standard errors of independent noise of std sigma."""
    assert abs(np.mean(x) - expected) < 3 * sigma / math.sqrt(len(x)), (np.mean(x), expected)


def check_sensor_a_offset(r, nominal, b):
    s, n = r["samples"], nominal["samples"]
    d = (s["meas.sensor_A.tension_N"] - s["true.sensor_A.tension_N"]).to_numpy()
    after = (s.t_s >= ONSET).to_numpy()
    _mean_within(d[after], b, NOISE_A)
    _mean_within(d[~after], 0.0, NOISE_A)
    assert r["faults"].iloc[0].profile == "step"
    # monitoring only: the process is the fault-free run's, sample for sample
    np.testing.assert_array_equal(
        s["state.registration.tension_N"].to_numpy(), n["state.registration.tension_N"].to_numpy()
    )
    state = [c for c in n.columns if c.startswith("state.")]
    pd.testing.assert_frame_equal(s[state], n[state])


def check_sensor_a_degradation(r, nominal, g):
    s, n = r["samples"], nominal["samples"]
    row = r["faults"].iloc[0]
    assert row.profile == "ramp" and row.ramp_s == pytest.approx(RAMP)
    t = s.t_s.to_numpy()
    p = np.clip((t - ONSET) / RAMP, 0.0, 1.0)
    np.testing.assert_allclose(s["label.severity"].to_numpy()[t >= ONSET], p[t >= ONSET], atol=1e-9)
    meas, true = s["meas.sensor_A.tension_N"].to_numpy(), s["true.sensor_A.tension_N"].to_numpy()
    after = t >= ONSET
    _mean_within((meas - (1 + g * p) * true)[after], 0.0, NOISE_A)
    # least-squares gain of (meas - true) on p·true, with its standard error
    x = (p * true)[after]
    g_hat = np.dot(x, (meas - true)[after]) / np.dot(x, x)
    assert abs(g_hat - g) < 3 * NOISE_A / math.sqrt(np.dot(x, x)), (g_hat, g)
    state = [c for c in n.columns if c.startswith("state.")]
    pd.testing.assert_frame_equal(s[state], n[state])


def check_sensor_b_gain(r, nominal, g):
    s, n = r["samples"], nominal["samples"]
    t = s.t_s.to_numpy()
    assert r["faults"].iloc[0].profile == "step"
    late = t >= ONSET + 1.0  # past sensor B's 20 ms filter and its 50 Hz hold
    ratio = (s["meas.sensor_B.pitch_m"] / s["true.sensor_B.pitch_m"]).to_numpy()[late]
    assert np.median(ratio) == pytest.approx(1 + g, abs=1e-5)
    # before the onset nothing differs from the fault-free run (to the solver's tolerance)
    before = np.nonzero(t < ONSET)[0]  # the nominal run is the short one
    np.testing.assert_allclose(
        s["state.registration.tension_N"].to_numpy()[before],
        n["state.registration.tension_N"].to_numpy()[before],
        rtol=1e-5,
    )
    # V21 in the pitch model: the loop holds the tension it sees, so the true tension settles
    # at EA·((1 + 130/EA)/(1 + g) - 1) (+-5 % / +-15 % of 130 N), to 0.1 %
    T = s["state.registration.tension_N"].to_numpy()
    settled = t >= 55.0
    np.testing.assert_allclose(T[settled], ideal_registration_tension(g), rtol=1e-3)
    assert abs(s["ctrl.registration_loop.output_m_s"].to_numpy()[-1]) < TRIM_LIMIT
    assert not bool(r["runs"].iloc[0]["terminated"])
