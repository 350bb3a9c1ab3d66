"""hybrid-sov on simulated test-bed data: the physics regressors against r2rsim's true
tensions (noise-free channels), the stage structure read from the line file, the model, the
plug-in's parameter checks, and its causal (default) and offline preprocessing."""

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
    r2rsim.run_scenario(
        REPO / "scenarios" / "thesis_realistic" / "testbed.yaml", output=d, seed=1, duration=90.0
    )
    return read_runs(d)[0]


@pytest.fixture(scope="module")
def dancer(tmp_path_factory):
    """80 s of the dancer-failure scenario (seed 1): the arm seizes at 40 s, the first fill
    starts at about 67 s; returns the run and the fill's start [s]."""
    d = tmp_path_factory.mktemp("hsov_df") / "df"
    r2rsim.run_scenario(
        REPO / "scenarios" / "thesis_realistic" / "testbed_dancer_failure.yaml",
        output=d,
        seed=1,
        duration=80.0,
    )
    ev = pd.read_parquet(d / "events.parquet")
    fill = float(ev.loc[(ev["kind"] == "splice") & (ev["state"] == "fill"), "t_s"].min())
    return read_runs(d)[0], fill


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
        0.3 + np.pi / 2 * 1390 * 0.5 * (0.093**4 - 0.076**4)
    )
    with pytest.raises(InputError, match="stage"):
        load_stages(REPO / "lines" / "registration_realistic.yaml")


def test_physics_regressors_reproduce_true_tensions(run):
    # tolerance: median |error| <= 0.5 N and RMSE <= 1 % of the ~300 N tension; the largest
    # errors are at the abrupt accelerations of the roll change, where the smoothed
    # derivative lags (the thesis's transient spikes)
    # the thesis's offline (centred) preprocessing: each estimate refers to its own sample
    st = load_stages(LINE)
    s = F.signals(_noise_free(run), st, "savgol", window_s=0.2, causal=False)
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
    s = F.signals(frame, st, causal=False)  # estimates at their own sample, as the truth
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


@pytest.mark.parametrize(
    "params, match",
    [
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
        (
            {"line": str(LINE), "causal": "yes"},
            "hybrid-sov: causal must be true or false, got 'yes'",
        ),
        ({"line": str(LINE), "causal": 1}, "hybrid-sov: causal must be true or false, got 1"),
        ({"line": str(LINE), "causal": None}, "hybrid-sov: causal must be true or false"),
        # a role named by a wrong id: the parameter and the line's candidates
        (
            {"line": str(LINE), "load_cell": "lc9"},
            r"hybrid-sov: load_cell 'lc9' is not a load "
            r"cell of the line \(load cells: lc_stage2\)",
        ),
        (
            {"line": str(LINE), "pitch_sensor": 3},
            "hybrid-sov: pitch_sensor must be null or the id of a sensor of the line, got 3",
        ),
        # a whole-run transform reads later samples: refused by the causal default
        ({"line": str(LINE), "denoise": "wavelet"}, r"denoise='wavelet' .* needs causal=False"),
        # every reading censored: no Tobit maximum (statsmodels warned, the fit went on)
        (
            {"line": str(LINE), "censor_at": 1e6},
            "censor_at=1e\\+06 N censors every stage-2 load-cell reading of the training runs",
        ),
    ],
)
def test_plugin_parameters_are_checked(run, params, match):
    with pytest.raises(InputError, match=match):
        HybridSoV(**params).fit([run])


def test_a_dead_sensor_in_training_is_refused(run):
    # it was filled with zeros, and the model then alarmed on every healthy sample
    frame = run.visible(drive_data=True)
    col = next(c for c in frame.columns if c.startswith("meas.") and "pitch" in c)
    with pytest.raises(
        InputError, match=f"hybrid-sov: training run 1 has no finite sample of {col}"
    ):
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

    monkeypatch.setitem(sys.modules, "pywt", None)  # import pywt now raises ImportError
    with pytest.raises(InputError, match=r"r2rsim\[wavelet\]"):
        F.wavelet_denoise(np.zeros(64))


def test_plugin_detects_the_seized_dancer_at_the_roll_change(run, dancer):
    # the arm seizes at 40 s; nothing observable changes until the fill (about 67 s for
    # seed 1), when the seized dancer cannot store web and the web goes slack. The default
    # (causal) plug-in: its first alarm comes 0.24 s (half its window) after the offline
    # one's (test_causal_detection_lags_the_offline_one_by_half_a_window)
    bad, fill = dancer
    est = HybridSoV(line=str(LINE)).fit([run])
    assert est.is_causal()
    scores = est.score(bad)
    alarm = est.decide(scores).to_numpy()
    t = bad.samples["t_s"].to_numpy()
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
    R = np.concatenate(
        [
            np.linspace(0.093, 0.086, 50),
            np.linspace(0.0935, 0.086, 50),
            np.linspace(0.092, 0.09, 10),
        ]
    )
    idx = F.roll_index(R)
    assert idx[0] == 0 and idx[49] == 0 and idx[50] == 1 and idx[-1] == 2


# ---- causal (default) and offline preprocessing --------------------------------------------
def test_causal_preprocessing_is_the_offline_one_delayed_by_half_a_window(run):
    # the trailing quadratic read at its window's centre is the centred filter one half
    # window late; the targets (load cell, pitch) are delayed to match, so that every signal
    # of a row refers to the same instant t_k - delay_s
    st = load_stages(LINE)
    frame = run.visible(drive_data=True)
    c, o = F.signals(frame, st), F.signals(frame, st, causal=False)
    lag = 12  # (25 - 1)/2: 0.5 s at 50 Hz is 25 samples
    assert c.delay_s == pytest.approx(0.24, rel=1e-9) and o.delay_s == 0.0
    for name in (
        "w1",
        "dw1",
        "v",
        "dv",
        "w4",
        "dw4",
        "tau1",
        "tau4",
        "alpha",
        "dalpha",
        "T2s",
        "T2",
        "Y",
    ):
        off = getattr(o, name)
        np.testing.assert_allclose(
            getattr(c, name)[2 * lag :],
            off[lag:-lag],
            rtol=0,
            atol=1e-9 * np.max(np.abs(off)),
            err_msg=name,
        )
    # the radius: a 25-sample trailing median instead of the centred 1 s one, within the
    # reading's noise (0.13 mm per sample); its 8 mm jump at the roll change on the same
    # instant
    assert np.max(np.abs(c.R[2 * lag :] - o.R[lag:-lag])) < 3e-4
    assert np.diff(o.R).max() > 5e-3
    assert np.argmax(np.diff(c.R)) == np.argmax(np.diff(o.R)) + lag
    # no estimate before the window has filled
    assert not c.valid[: 2 * lag].any() and c.valid[2 * lag :].all() and o.valid.all()


def test_causal_statistic_uses_no_later_sample(run, dancer):
    # streaming: scoring the run up to sample k gives, at samples 0..k, what scoring the
    # whole run gives; across the seizure's roll change and a load-cell drop-out (held at
    # its last reading, not interpolated towards the next)
    bad, fill = dancer
    frame = bad.visible(drive_data=True).copy()
    frame.loc[frame.index[1000:1040], "meas.lc_stage2.tension_N"] = np.nan  # 20.0-20.8 s
    k_fill = int(np.searchsorted(frame["t_s"].to_numpy(), fill))
    ks = (8, 24, 30, 1010, 1045, k_fill + 5, k_fill + 30, len(frame) - 1)
    est = HybridSoV(line=str(LINE)).fit([run])
    full = est.score(frame)
    for k in ks:
        part = est.score(frame.iloc[: k + 1])
        assert part.index.equals(frame.index[: k + 1])
        np.testing.assert_allclose(
            part.to_numpy(float),
            full.iloc[: k + 1].to_numpy(float),
            rtol=1e-9,
            atol=0,
            equal_nan=True,
            err_msg=f"k={k}",
        )
    stat = full["statistic"].to_numpy()
    assert np.isnan(stat[:24]).all() and np.isfinite(stat[24:1012]).all()
    # the drop-out: no residual from 1012 (1000 + the delay) to 1051; the moving average
    # of the residuals (25 samples) carries the earlier ones until 1035
    assert np.isfinite(stat[1035]) and np.isnan(stat[1036:1052]).all()
    assert np.isfinite(stat[1052:]).all()
    # the offline (centred) statistic reads later samples: truncating the run changes it
    off = HybridSoV(line=str(LINE), causal=False).fit([run])
    assert not off.is_causal()
    full_off = off.score(frame)["statistic"].to_numpy()
    worst = 0.0
    for k in ks[1:]:
        part_off = off.score(frame.iloc[: k + 1])["statistic"].to_numpy()
        ok = np.isfinite(part_off) & np.isfinite(full_off[: k + 1])
        rel = np.abs(part_off[ok] - full_off[: k + 1][ok]) / np.abs(full_off[: k + 1][ok])
        worst = max(worst, float(rel.max()))
    assert worst > 0.1


def test_causal_detection_lags_the_offline_one_by_half_a_window(run, dancer):
    # the same model (the selection tests read the same instants of the line), the alarm
    # half a window later: measured, the offline one 0.01 s after the fill's start, the
    # causal one 0.25 s
    bad, fill = dancer
    t = bad.samples["t_s"].to_numpy()
    est = {c: HybridSoV(line=str(LINE), causal=c).fit([run]) for c in (True, False)}
    assert est[True].delay_s_ == pytest.approx(0.24) and est[False].delay_s_ == 0.0
    m_c, m_o = est[True].model_, est[False].model_
    assert m_c.stage12_.selected == m_o.stage12_.selected
    assert m_c.stage3_.stage3.selected == m_o.stage3_.stage3.selected
    assert est[True].threshold_ == pytest.approx(est[False].threshold_, rel=0.02)
    first = {}
    for c, e in est.items():
        alarm = e.decide(e.score(bad)).to_numpy()
        assert not alarm[(t > 5.0) & (t < fill)].any(), c
        first[c] = t[alarm].min()
    assert 0.0 <= first[False] - fill < 0.1
    assert first[True] - first[False] == pytest.approx(0.24, abs=0.04)


def test_wavelet_denoising_is_offline_only(run):
    st = load_stages(LINE)
    frame = run.visible(drive_data=True)
    with pytest.raises(InputError, match=r"denoise='wavelet' .* needs causal=False"):
        F.signals(frame, st, "wavelet")
    est = HybridSoV(line=str(LINE), denoise="wavelet", causal=False).fit([run])
    assert not est.is_causal() and np.isfinite(est.threshold_)


def test_causal_scoring_needs_the_training_sample_period(run):
    # the causal filter's coefficients come from the training period, not from the scored
    # run's time stamps (which would read later samples)
    frame = run.visible(drive_data=True)
    slow = frame.assign(t_s=2.0 * frame["t_s"])
    est = HybridSoV(line=str(LINE)).fit([run])
    assert est.dt_ == pytest.approx(0.02)
    with pytest.raises(
        InputError,
        match=r"sampled every 0\.04 s, the model was fitted on "
        r"runs sampled every 0\.02 s",
    ):
        est.score(slow)
    with pytest.raises(InputError, match=r"training run 2 is sampled every 0\.04 s"):
        HybridSoV(line=str(LINE)).fit([frame, slow])
    # offline, every run is filtered at its own period, as before
    off = HybridSoV(line=str(LINE), causal=False).fit([run])
    assert off.dt_ is None and np.isfinite(off.score(slow)["statistic"]).any()
