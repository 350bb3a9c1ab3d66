"""Splices, e-stop, the material balance across discrete changes (V13, V23) and the thesis
scenarios (Shui 2018, Fig. 2-13 and Fig. 2-15b), through line and scenario files."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml
from test_dancers import dancer_line

import r2rsim
from r2rsim.schema.scenario import ProgrammeStep, ScenarioEvent

from conftest import REPO, write


def _events(res, kind=None):
    return [e for e in res.events if kind is None or e.kind == kind]


def test_v13_material_balance_across_dancer_festoon_slack_and_splice(tmp_path):
    # Line B plus a translating dancer before the press: a zero-speed splice (festoon
    # empties and refills, joint travels), then an e-stop whose transient slackens spans and
    # drives the dancer into its stops. V13: sum(l_i) + U_N - U_0 stays constant to 1e-9.
    d = yaml.safe_load((REPO / "lines" / "newsprint_line.yaml").read_text())
    els = d["elements"]
    els[3].update(position=[0.0, 0.0], wrap="cw")
    els.insert(
        4,
        {
            "id": "dancer",
            "type": "dancer",
            "radius": 0.06,
            "inertia": 0.02,
            "position": [0.18, -1.0],
            "wrap": "ccw",
            "travel_range": [-0.3, 0.3],
            "mass": 20,
            "load_force": 560 - 20 * 9.81,
            "damping": 200,
        },
    )
    els.insert(
        5,
        {
            "id": "out",
            "type": "idler",
            "radius": 0.06,
            "inertia": 0.02,
            "position": [0.36, 0.0],
            "wrap": "cw",
        },
    )
    d["spans"] = [d["spans"][0], d["spans"][1], d["spans"][2], {}, {}, {"length": 3.0}]
    line = r2rsim.load_line(write(tmp_path / "b.yaml", yaml.safe_dump(d)))
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=12.0)])
    )
    events = [
        ScenarioEvent(at=5, type="splice", element="unwind"),
        ScenarioEvent(at=42, type="e_stop", deceleration=5.0),
    ]
    res = r2rsim.simulate(
        cl, 50.0, 200.0, r2rsim.nominal_state(cl), r2rsim.SolverSettings(rtol=1e-9), events=events
    )
    kinds = {e.kind for e in res.events}
    assert {
        "slack",
        "dancer_stop_low",
        "dancer_stop_high",
        "splice",
        "splice_joint",
        "e_stop",
    } <= kinds, kinds
    assert any(e.state == "swap" for e in res.events)
    assert np.ptp(res["festoon.position_m"]) > 2.0  # the festoon emptied and refilled
    assert np.ptp(res["dancer.position_m"]) > 0.1
    ell = sum(res[f"{s}.length_m"] / (1 + res[f"{s}.geometric_strain"]) for s in cl.span_ids)
    u0 = res.states[:, cl.index("unwind.unstretched_length")]
    un = res.states[:, cl.index("rewind.unstretched_length")]
    inv = ell + un - u0
    assert np.max(np.abs(inv - inv[0])) < 1e-9 * inv[0]


def flying_line(tmp_path, *, dancer: bool, delta: float, stiffness_ratio: float = 1.0):
    """Kinematic line whose unwind makes a flying splice with speed-match error delta (the
    splice joint as stiff as the web unless ``stiffness_ratio`` says otherwise)."""
    if dancer:  # as Line A: unwind -> free idler -> dancer
        path = dancer_line(tmp_path, EA=2.25e5, mass=10.0, force_total=520.0, outer=1.5)
        d = yaml.safe_load(path.read_text())
        rin = d["elements"][1]
        d["elements"][1] = {
            "id": "rin",
            "type": "idler",
            "radius": 0.05,
            "inertia": 0.011,
            "position": rin["position"],
            "wrap": rin["wrap"],
        }
    else:
        d = yaml.safe_load(
            dancer_line(tmp_path, EA=2.25e5, mass=10.0, force_total=520.0, outer=1.5).read_text()
        )
        d["elements"] = [d["elements"][0], d["elements"][1], d["elements"][-1]]
        d["spans"] = [{"length": 1.5}, {"length": 1.0}]
    src = d["elements"][0]
    src["spare_roll"] = dict(src["roll"])
    src["splicer"] = {
        "type": "flying",
        "speed_match_error": delta,
        "joint": {"stiffness_ratio": stiffness_ratio},
    }
    return write(tmp_path / f"flying_{dancer}.yaml", yaml.safe_dump(d))


def test_v23_flying_splice_speed_mismatch(tmp_path):
    # V23 (Line A values, delta = 0.5 %): with a free dancer it absorbs the mismatch at
    # dx/dt = delta·v/2 = 12.5 mm/s ...
    v, delta, EA, T, L = 5.0, 0.005, 2.25e5, 260.0, 1.5
    line = r2rsim.load_line(flying_line(tmp_path, dancer=True, delta=delta))
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=v)])
    )
    res = r2rsim.simulate(
        cl,
        20.0,
        10.0,
        r2rsim.nominal_state(cl, T),
        r2rsim.SolverSettings(rtol=1e-10, atol_scale=1e-4),
        events=[ScenarioEvent(at=1.0, type="splice", element="src")],
    )
    assert any(e.state == "swap" and e.t == 1.0 for e in res.events)
    # the wound-in strain equals the running strain, so the drift is exact (V14 form)
    assert res["dancer.velocity_m_s"][-1] == pytest.approx(delta * v / 2, rel=1e-5)
    # ... and without a dancer span 1's tension heads for T(1+delta) - EA·delta < 0: slack
    # at t = tau·ln((T0 - Tinf)/(-Tinf)) after the splice (V20 formula), tau = L/v
    line = r2rsim.load_line(flying_line(tmp_path, dancer=False, delta=delta))
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=v)])
    )
    res = r2rsim.simulate(
        cl,
        2.0,
        1000.0,
        r2rsim.nominal_state(cl, T),
        r2rsim.SolverSettings(rtol=1e-10, atol_scale=1e-4),
        events=[ScenarioEvent(at=1.0, type="splice", element="src")],
    )
    t_inf = T * (1 + delta) - EA * delta
    t_slack = 1.0 + L / v * np.log((T - t_inf) / (-t_inf))
    slack = [e for e in _events(res, "slack") if e.component == "span1"]
    assert slack and slack[0].t == pytest.approx(t_slack, abs=1e-3)


def test_splice_joint_carries_its_own_strain_through_the_nodes(tmp_path):
    # A joint twice as stiff as the web crosses a kinematic line (all nodes at v, wound-in
    # strain = running strain). It carries the running tension at strain T/EA_s, so by mass
    # conservation no span's tension changes while it enters, crosses and leaves: tension
    # stays T (without the joint's own strain in the flux it jumped by up to 1/(1 - f/2)).
    v, T, ls = 5.0, 260.0, 0.05
    line = r2rsim.load_line(flying_line(tmp_path, dancer=False, delta=0.0, stiffness_ratio=2.0))
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=v)])
    )
    res = r2rsim.simulate(
        cl,
        1.8,
        2000.0,
        r2rsim.nominal_state(cl, T),
        r2rsim.SolverSettings(rtol=1e-10, atol_scale=1e-4),
        events=[ScenarioEvent(at=1.0, type="splice", element="src")],
    )
    passes = [e for e in res.events if e.kind == "splice_joint"]
    # the lead enters span 2 once span 1's unstretched length L/(1+eps) has been paid out
    # at v/(1+eps), i.e. after L/v ...
    assert passes[0].state == "span2"
    assert passes[0].t == pytest.approx(1.0 + 1.5 / v, abs=1e-6)
    # ... and the trail leaves the line l_s later than the lead reaches the rewind
    assert passes[-1].state == "end"
    assert passes[-1].t == pytest.approx(1.0 + (2.5 + ls) / v, abs=1e-5)
    joint_in = np.isfinite(res["splice_joint1.lead_m"])
    assert joint_in.sum() > 500
    for s in ("span1", "span2"):
        assert np.max(np.abs(res[f"{s}.tension_N"] - T)) < 1e-6 * T


def test_e_stop_ramps_the_line_down_at_its_deceleration_limit(repo):
    scen, line, _ = r2rsim.load_scenario(repo / "scenarios" / "quickstart.yaml")
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    y0 = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    res = r2rsim.simulate(
        cl, 12.0, 200.0, y0, events=[ScenarioEvent(at=4.0, type="e_stop", deceleration=1.0)]
    )
    v0 = float(np.interp(4.0, res.t, res["setpoint.line_speed_m_s"]))
    sp = res["setpoint.line_speed_m_s"]
    t_end = 4.0 + v0 / 1.0
    on_ramp = (res.t > 4.0) & (res.t < t_end)
    assert sp[on_ramp] == pytest.approx(v0 - (res.t[on_ramp] - 4.0), abs=1e-9)
    assert np.all(sp[res.t >= t_end] == 0.0)
    # the master follows within its loop lag, and the line is at rest at the end
    pull = res["pull.surface_speed_m_s"]
    assert np.max(np.abs(pull[on_ramp] - sp[on_ramp])) < 0.02
    assert abs(pull[-1]) < 1e-3
    states = [e.state for e in _events(res, "e_stop")]
    assert states == ["start", "end"]
    # the compiled line is restored after the run: a second run is identical
    res2 = r2rsim.simulate(
        cl, 12.0, 200.0, y0, events=[ScenarioEvent(at=4.0, type="e_stop", deceleration=1.0)]
    )
    assert np.array_equal(res.states, res2.states)


def _run(repo, tmp_path, name):
    out = tmp_path / name
    summary = r2rsim.run_scenario(repo / "scenarios" / f"{name}.yaml", output=out)
    samples = pd.read_parquet(out / "samples")
    events = pd.read_parquet(out / "events.parquet")
    runs = pd.read_parquet(out / "runs.parquet")
    return summary, samples, events, runs


def test_newsprint_zero_speed_splice_keeps_the_press_running(repo, tmp_path):
    summary, s, ev, runs = _run(repo, tmp_path, "newsprint_splice")
    assert not runs["terminated"][0]
    phases = list(ev[ev.kind == "splice"].state)
    assert phases == ["fill", "brake", "dwell", "swap", "accelerate", "refill", "complete"]
    t_brake = ev[(ev.kind == "splice") & (ev.state == "brake")].t_s.iloc[0]
    t_acc = ev[(ev.kind == "splice") & (ev.state == "accelerate")].t_s.iloc[0]
    stopped = (s.t_s > t_brake + 2.3) & (s.t_s < t_acc)
    assert np.all(np.abs(s["state.unwind.surface_speed_m_s"][stopped]) < 0.05)
    # the festoon feeds the press: infeed speed held at 12 m/s within 0.5 %
    after = s.t_s > 2.0
    assert np.max(np.abs(s["state.infeed.surface_speed_m_s"][after] - 12.0)) < 0.06
    assert s["state.festoon.position_m"].min() > 0.0
    assert s["state.festoon.position_m"].max() < 4.0


def test_thesis_normal_cycles(repo, tmp_path):
    # Fig. 2-13: at every roll change stages 1-2 stop for the splice while the dancer keeps
    # stages 4-5 at constant speed; tensions stay within their limits
    summary, s, ev, runs = _run(repo, tmp_path, "thesis_normal_cycles")
    assert not runs["terminated"][0]
    sp = ev[ev.kind == "splice"]
    assert (sp.state == "swap").sum() >= 2
    assert (sp.state == "complete").sum() == (sp.state == "swap").sum()
    assert not ev.kind.isin(["slack", "web_break", "dancer_stop_low", "dancer_stop_high"]).any()
    after = s.t_s > 2.0
    for roller in ("drive4", "r5a", "r5b"):
        v = s[f"state.{roller}.surface_speed_m_s"][after]
        assert np.max(np.abs(v - 0.5)) < 0.005, roller  # within 1 % through the splices
    # the unwind really stops during each splice
    for t_dwell in sp[sp.state == "dwell"].t_s:
        at = (s.t_s > t_dwell + 0.2) & (s.t_s < t_dwell + 0.9)
        assert np.all(np.abs(s["state.unwind.surface_speed_m_s"][at]) < 0.02)
    limit = 0.5 * 1.5e3  # half the break tension
    for span in ("span3", "span4", "span5", "span6", "registration", "span8", "span9"):
        T = s[f"state.{span}.tension_N"][after]
        assert T.min() > 150.0 and T.max() < limit, span
    # the splice disturbs stage 2 tension (the thesis's spikes) far more than stage 5: compare
    # the fast part (minus the 1 s moving mean; the slow climb of the fill reaches both)
    t_sw = sp[sp.state == "swap"].t_s.iloc[0]
    win = (s.t_s > t_sw - 10) & (s.t_s < t_sw + 15)

    def fast(col):
        x = s[col][win]
        return np.ptp(x - x.rolling(100, center=True, min_periods=1).mean())

    assert fast("state.span3.tension_N") > 10 * fast("state.registration.tension_N")
    # Fig. 2-15a: tension climbs before every changeover while the dancer stores web
    lc = s["true.lc_stage2.tension_N"]
    for t_fill, t_brake in zip(
        sp[sp.state == "fill"].t_s, sp[sp.state == "brake"].t_s, strict=True
    ):
        before = lc[(s.t_s > t_fill - 5) & (s.t_s < t_fill)].mean()
        late_fill = lc[(s.t_s > t_brake - 1) & (s.t_s < t_brake)].mean()
        assert late_fill > 1.04 * before, (t_fill, before, late_fill)


def test_thesis_dancer_failure_breaks_the_web_during_the_changeover(repo, tmp_path):
    summary, s, ev, runs = _run(repo, tmp_path, "thesis_dancer_failure")
    assert runs["terminated"][0] and runs["termination_reason"][0] == "web_break"
    t_break = runs["termination_t_s"][0]
    seize = ev[ev.kind == "dancer_seized"].t_s.iloc[0]
    fill = ev[(ev.kind == "splice") & (ev.state == "fill")].t_s.iloc[0]
    brake = ev[(ev.kind == "splice") & (ev.state == "brake")].t_s.iloc[0]
    assert seize < fill < brake < t_break
    # Fig. 2-15b: the seized arm stores nothing, so no tension climb during the fill (the web
    # fed in goes slack instead) ...
    lc = s["true.lc_stage2.tension_N"]
    before = lc[(s.t_s > fill - 5) & (s.t_s < fill)].mean()
    assert lc[(s.t_s > fill) & (s.t_s < brake)].max() < 1.01 * before
    assert ((ev.kind == "slack") & (ev.t_s > fill) & (ev.t_s < brake)).any()
    # ... and the break comes during the changeover, before the new roll could be spliced
    swap = ev[(ev.kind == "splice") & (ev.state == "swap")]
    assert swap.empty or swap.t_s.iloc[0] > t_break
    assert not (ev.kind == "splice").values[ev.state.values == "complete"].any()
    last = ev.iloc[-1]
    assert last.kind == "web_break" and last.t_s == pytest.approx(t_break)
