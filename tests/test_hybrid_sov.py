"""hybrid-sov on simulated test-bed data: the physics regressors against r2rsim's true
tensions (noise-free channels), the stage structure read from the line file, the model and
the plug-in's parameter checks."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import r2rsim
from r2rsim.dataset.read import read_runs
from r2rsim.diagnostics.hybrid_sov import DataDrivenModel, HybridModel, HybridSoV, load_stages
from r2rsim.diagnostics.hybrid_sov import _features as F
from r2rsim.errors import InputError

from conftest import REPO

LINE = REPO / "lines" / "thesis_testbed_realistic.yaml"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """90 s of the calibrated test bed: steady running and the first roll change (fill at
    about 67 s, splice at 75 s)."""
    d = tmp_path_factory.mktemp("hsov") / "tb"
    r2rsim.run_scenario(REPO / "scenarios" / "thesis_realistic" / "testbed.yaml", output=d,
                        seed=1, duration=90.0)
    return read_runs(d)[0]


def _noise_free(run):
    """The visible frame with every sensor's noise-free value (``true.*``) in its place."""
    S = run.samples
    cols = [c for c in S.columns if c.startswith(("t_s", "true.", "act."))]
    return S[cols].rename(columns=lambda c: c.replace("true.", "meas.", 1))


def test_stages_from_the_line_file():
    st = load_stages(LINE)
    assert st.unwind == "unwind" and st.dancer == "dancer" and st.driven.id == "drive4"
    assert [r.id for r in st.idlers[2]] == ["s2a", "s2b", "s2c"]
    assert [r.id for r in st.idlers[5]] == ["r5a", "r5b"]
    assert st.web_EA == pytest.approx(4.5e9 * 0.5 * 125e-6)
    assert st.column("tension") == "meas.lc_stage2.tension_N"
    # J(R) of the unwind: core + (π/2)ρw(R⁴ - Rc⁴)
    assert st.roll_inertia(0.093) == pytest.approx(
        0.3 + np.pi / 2 * 1390 * 0.5 * (0.093**4 - 0.076**4))
    with pytest.raises(InputError, match="stage"):
        load_stages(REPO / "lines" / "registration_realistic.yaml")


def test_physics_regressors_reproduce_true_tensions(run):
    # tolerance: median |error| <= 0.5 N and RMSE <= 1 % of the ~300 N tension; the largest
    # errors are at the abrupt accelerations of the roll change, where the smoothed
    # derivative lags (the thesis's transient spikes)
    st = load_stages(LINE)
    s = F.signals(_noise_free(run), st, "savgol", window_s=0.2)
    S = run.samples
    T1 = F.physics_T1(st, s)
    T2 = T1 + F.idler_sum(st, 2, s)
    T4 = S["state.span6.tension_N"].to_numpy() + F.driven_term(st, s)
    for est, col in ((T1, "span1"), (T2, "span4"), (T4, "registration")):
        err = est - S[f"state.{col}.tension_N"].to_numpy()
        assert np.median(np.abs(err)) < 0.5, col
        assert np.sqrt(np.mean(err**2)) < 3.0, col
    # signs: the unwind brakes (τ < 0) and the web pulls it: -τ/R carries the tension
    assert np.median(-s.tau1 / s.R) > 250.0
    # the zero-speed splice's brake (0.5 m/s² from about 73 s to rest): J(R)·ω̇/R is a
    # 20 N step at its start and end, where the smoothed derivative errs by about ±6 N for
    # a window's length; over the brake as a whole the balance holds (a wrong sign or a
    # missing inertia term would leave tens of newtons here)
    t = S["t_s"].to_numpy()
    brake = (t > 72.0) & (t < 75.0) & (s.dw1 < -1.0)
    assert brake.sum() > 50
    err1 = T1 - S["state.span1.tension_N"].to_numpy()
    assert abs(np.mean(err1[brake])) < 0.5
    assert np.max(np.abs(err1[brake])) < 10.0


def test_models_fit_and_predict(run):
    st = load_stages(LINE)
    frame = run.visible(drive_data=True)
    s = F.signals(frame, st)
    hm = HybridModel(st, kind="tobit").fit([s])
    p = hm.predict(s)
    S = run.samples
    # the virtual sensor tracks the unmeasured stage-3 tension within a few newtons
    e3 = p["T_s3"].to_numpy() - S["state.span6.tension_N"].to_numpy()
    assert np.sqrt(np.mean(e3**2)) < 10.0
    assert hm.stage12_.test == "LR" and hm.stage3_.method == "alternating"
    assert np.sqrt(np.mean((p["Y_s4"].to_numpy() - s.Y) ** 2)) < 20e-6
    dd = DataDrivenModel(kind="ols").fit([s])
    assert dd.tension_.test == "F"
    assert np.sqrt(np.mean((dd.predict(s)["T_s2"].to_numpy() - s.T2) ** 2)) < 5.0


@pytest.mark.parametrize("params, match", [
    ({}, "needs line"),
    ({"line": "nope.yaml"}, "does not exist"),
    ({"line": str(LINE), "selection": "t"}, "selection"),
    ({"line": str(LINE), "denoise": "fft"}, "denoise"),
    ({"line": str(LINE), "alpha": 2.0}, "alpha"),
    ({"line": str(LINE), "window_s": 0}, "window_s"),
    ({"line": str(LINE), "window_s": float("nan")}, "window_s"),
    ({"line": str(LINE), "censor_at": float("inf")}, "censor_at must be a finite"),
    ({"line": str(LINE), "censor_at": 1e300}, "within ±1e6 N"),
    ({"line": str(LINE), "window_s": 1e300}, "at most 60 s"),
    ({"line": str(LINE), "window_s": True}, "window_s must be a number"),
    ({"line": str(LINE), "alpha_enter": True}, "alpha_enter must be a number"),
    ({"line": str(LINE), "alpha_enter": 0.0}, r"alpha_enter must be a number in \(0, 1\)"),
    ({"line": str(LINE), "alpha": False}, r"alpha must be a number in \(0, 1\)"),
    ({"line": str(LINE), "censor_at": "0"}, "censor_at must be a number"),
    ({"line": True}, "line must be the path"),
    ({"line": "/dev/zero"}, "line file /dev/zero is not a regular file"),
    ({"line": str(REPO)}, "is not a regular file"),
    ({"line": str(LINE), "random_state": -1}, "random_state must be null or an integer"),
    # every reading censored: no Tobit maximum (statsmodels warned, the fit went on)
    ({"line": str(LINE), "censor_at": 1e6}, "censor_at=1e\\+06 N censors every stage-2 "
                                             "load-cell reading of the training runs"),
])
def test_plugin_parameters_are_checked(run, params, match):
    with pytest.raises(InputError, match=match):
        HybridSoV(**params).fit([run])


def test_a_dead_sensor_in_training_is_refused(run):
    # it was filled with zeros, and the model then alarmed on every healthy sample
    frame = run.visible(drive_data=True)
    col = next(c for c in frame.columns if c.startswith("meas.") and "pitch" in c)
    with pytest.raises(InputError, match=f"hybrid-sov: training run 1 has no finite sample "
                                         f"of {col}"):
        HybridSoV(line=str(LINE)).fit([frame.assign(**{col: np.nan})])


def test_torques_need_drive_data(run):
    with pytest.raises(InputError, match="drive data"):
        HybridSoV(line=str(LINE)).fit([run.visible().assign(**{"act.x": 0.0})])


def test_wavelet_denoising_reduces_noise():
    # PyWavelets is in the test extra: a missing one fails here, it is not skipped
    rng = np.random.default_rng(0)
    t = np.linspace(0, 10, 1024)
    clean = np.sin(t) + 0.5 * np.sin(3 * t)
    noisy = clean + rng.normal(scale=0.2, size=t.size)
    den = F.wavelet_denoise(noisy)
    assert np.sqrt(np.mean((den - clean) ** 2)) < 0.5 * np.sqrt(np.mean((noisy - clean) ** 2))


def test_wavelet_option_without_pywavelets_names_the_extra(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pywt", None)     # import pywt now raises ImportError
    with pytest.raises(InputError, match=r"r2rsim\[wavelet\]"):
        F.wavelet_denoise(np.zeros(64))


def test_plugin_detects_the_seized_dancer_at_the_roll_change(run, tmp_path):
    # the arm seizes at 40 s; nothing observable changes until the fill (about 67 s for
    # seed 1), when the seized dancer cannot store web and the web goes slack
    r2rsim.run_scenario(REPO / "scenarios" / "thesis_realistic" /
                        "testbed_dancer_failure.yaml", output=tmp_path / "df", seed=1,
                        duration=80.0)
    bad = read_runs(tmp_path / "df")[0]
    est = HybridSoV(line=str(LINE)).fit([run])
    scores = est.score(bad)
    alarm = est.decide(scores).to_numpy()
    t = bad.samples["t_s"].to_numpy()
    ev = pd.read_parquet(tmp_path / "df" / "events.parquet")
    fill = float(ev.loc[(ev["kind"] == "splice") & (ev["state"] == "fill"), "t_s"].min())
    assert 60.0 < fill < 75.0
    assert not alarm[(t > 5.0) & (t < fill)].any()
    first = t[alarm].min()
    assert fill < first < fill + 1.0
    # the virtual sensor sees the slack web: stage-3 tension far below its healthy level
    late = (t > fill + 2.0) & (t < fill + 5.0)
    assert scores.loc[late, "T_s3_N"].max() < 100.0
    healthy = est.score(run)
    assert healthy["T_s3_N"].iloc[: 50 * 60].min() > 250.0


def test_roll_index_steps_at_roll_changes():
    R = np.concatenate([np.linspace(0.093, 0.086, 50), np.linspace(0.0935, 0.086, 50),
                        np.linspace(0.092, 0.09, 10)])
    idx = F.roll_index(R)
    assert idx[0] == 0 and idx[49] == 0 and idx[50] == 1 and idx[-1] == 2
