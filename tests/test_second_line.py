"""The second registration line (issue 35 item 5; lines/second_registration_line.yaml,
scenarios/second_line/, benchmarks/second_line.yaml, docs/dataset.md §8.3): its files are
valid, its sweeps plan what they say, the line holds its set-points, and every shipped
baseline and the thesis methods parity and gsmms fit and score on it with documented
parameters only."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim
from r2rsim import run_scenario
from r2rsim.bench import load_spec
from r2rsim.dataset.read import read_runs
from r2rsim.diagnostics.registry import get
from r2rsim.evaluate.harness import evaluate
from r2rsim.schema.loader import load_line, load_scenario
from r2rsim.schema.scenario import ProgrammeStep
from r2rsim.sweep import plan_sweep

from conftest import REPO

LINE = REPO / "lines" / "second_registration_line.yaml"
SET = REPO / "scenarios" / "second_line"
SPEC = REPO / "benchmarks" / "second_line.yaml"
A, B = "meas.sensor_A.tension_N", "meas.sensor_B.pitch_m"


def test_the_line_and_every_scenario_and_sweep_validate():
    line = load_line(LINE)
    assert line.name == "paper_registration_line"
    for path in sorted(SET.glob("*.yaml")):
        if "scenario:" in path.read_text(encoding="utf-8"):
            assert plan_sweep(path).runs, path
        else:
            assert load_scenario(path)[0].duration <= 300.0, path


def test_the_line_differs_from_the_thesis_lines():
    new = load_line(LINE)
    web = new.web
    for other in ("registration_realistic", "thesis_testbed_realistic"):
        old = load_line(REPO / "lines" / f"{other}.yaml")
        assert (web.modulus, web.thickness, web.width) != (
            old.web.modulus,
            old.web.thickness,
            old.web.width,
        )
        assert sorted(s.length for s in new.spans if s.length) != sorted(
            s.length for s in old.spans if s.length
        )
    kinds = {e.id: e.type for e in new.elements}
    assert kinds["dancer"] == "dancer" and kinds["infeed"] == "driven"
    sensors = {s.id: s.type for s in new.sensors}
    assert sensors["sensor_A"] == "load_cell" and sensors["sensor_B"] == "pitch_length"
    # encoders on the driven roller and the idlers around it (the parity model's inputs), and
    # on the reel and the guide roller (with the reel's diameter and the guide's load cell:
    # what the hybrid stage model adds)
    assert {s.element for s in new.sensors if s.type == "encoder"} == {
        "infeed",
        "lc_roll",
        "print_idler",
        "unwind",
        "guide_in",
    }
    assert {e.id: e.stage for e in new.elements if e.stage is not None} == {
        "unwind": 1,
        "guide_in": 2,
        "dancer": 3,
        "lc_roll": 3,
        "infeed": 4,
        "print_idler": 5,
    }
    loop = next(c for c in new.controllers if c.id == "registration_loop")
    assert (loop.sensor, loop.element) == ("sensor_B", "infeed")


@pytest.mark.parametrize("roll", ["full", "near_core"])
@pytest.mark.parametrize("speed", [1.5, 2.5])
def test_the_line_is_linearly_stable(tmp_path, roll, speed):
    """As tests/test_lines.py for the other shipped lines, at both operating speeds."""
    d = yaml.safe_load(LINE.read_text(encoding="utf-8"))
    if roll == "near_core":
        core = r2rsim.Line.model_validate(d).elements[0].roll.core_radius
        d["elements"][0]["roll"]["outer_radius"] = 1.2 * core
    path = tmp_path / "line.yaml"
    path.write_text(yaml.safe_dump(d), encoding="utf-8")
    line = r2rsim.load_line(path)
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=speed)])
    )
    y = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    assert y is not None
    _, lam = cl.linearise(0.0, y)
    worst = lam[np.argmax(lam.real)]
    assert worst.real < 1e-3, f"{roll} roll at {speed} m/s: unstable mode {worst:.4g} 1/s"


@pytest.mark.parametrize("sweep, n_runs", [("healthy.yaml", 24), ("faults.yaml", 48)])
def test_the_sweeps_plan(sweep, n_runs):
    runs = plan_sweep(SET / sweep).runs
    assert len(runs) == n_runs
    assert len({r.run_id for r in runs}) == n_runs
    modes = {r.scenario_data["programme"][0]["mode"] for r in runs}
    assert modes == {"L1", "L2"}
    for r in runs:  # one mode per run: the base scenario's L2 step is replaced
        assert len(r.scenario_data["programme"]) == 1


def test_the_healthy_sweep_is_healthy_and_the_fault_sweep_shares_its_seeds():
    healthy = plan_sweep(SET / "healthy.yaml").runs
    assert not any(r.scenario_data.get("faults") for r in healthy)
    assert {r.seed for r in healthy} == set(range(1, 13))
    runs = plan_sweep(SET / "faults.yaml").runs
    free = [r for r in runs if not r.scenario_data.get("faults")]
    faulty = [r for r in runs if r.scenario_data.get("faults")]
    assert len(free) == 6 and len(faulty) == 42
    # a fault-free case per condition, with the fault runs' seeds (their plants)
    for mode in ("L1", "L2"):
        seeds_free = {r.seed for r in free if r.scenario_data["programme"][0]["mode"] == mode}
        seeds_faulty = {r.seed for r in faulty if r.scenario_data["programme"][0]["mode"] == mode}
        assert seeds_free == seeds_faulty == {101, 102, 103}
    assert not {r.seed for r in runs} & {r.seed for r in healthy}
    types = {r.scenario_data["faults"][0]["type"] for r in faulty}
    assert types == {"sensor.offset", "sensor.gain", "dancer.arm_stuck"}


def _dancer_tension(line) -> float:
    """The infeed-zone tension the translating dancer holds at mid-stroke: the load force and
    the carriage's weight, shared by its two spans, which lean θ off the travel axis (the
    inner tangent between guide_in and the dancer roller; lc_roll is the mirror image)."""
    els = {e.id: e for e in line.elements}
    d, g = els["dancer"], els["guide_in"]
    dx, dy = d.position[0] - g.position[0], g.position[1] - d.position[1]
    theta = math.atan2(dx, dy) - math.asin((g.radius + d.radius) / math.hypot(dx, dy))
    return (d.load_force + d.mass * 9.81) / (2.0 * math.cos(theta))


@pytest.fixture(scope="module")
def steady_run(tmp_path_factory):
    """40 s of the base scenario in L1 (its L2 step is at 60 s), without the per-run
    variability: a drawn reel modulus or relaxed pitch moves the tension the pitch loop holds
    (by design, docs/dataset.md §8.1), which is not what this test is about."""
    d = tmp_path_factory.mktemp("steady")
    scen = yaml.safe_load((SET / "production.yaml").read_text(encoding="utf-8"))
    scen.pop("variability")
    scen["line"] = str(LINE)
    (d / "s.yaml").write_text(yaml.safe_dump(scen), encoding="utf-8")
    out = run_scenario(d / "s.yaml", d / "run", duration=40.0).output
    s = pd.read_parquet(next((out / "samples").glob("*/part-0.parquet")))
    return scen, s[s.t_s >= 20.0]


def test_the_base_run_reaches_its_set_points(steady_run):
    scen, s = steady_run
    step = scen["programme"][0]
    assert step["mode"] == "L1" and s["label.mode"].eq("L1").all()
    line = load_line(LINE)
    ea = line.web.modulus * line.web.thickness * line.web.width
    pitch = next(x for x in line.sensors if x.id == "sensor_B")
    # registration span: the loop holds the pitch, so the true tension follows the printing
    # variation: std EA/L0·σ_p, whose mean over the window's web length ℓ = v·Δt has the
    # standard deviation σ·sqrt(2·l_c/ℓ) (exponential correlation of length l_c, ℓ >> l_c).
    # Tolerance: 3 of those, about 8.7 N at 200 N
    sp = float(step["tension"]["registration_loop"].split()[0])
    v = float(step["line_speed"].split()[0])
    sigma = ea / pitch.relaxed_pitch_law.q0 * pitch.pitch_variation.std
    ell = v * (s.t_s.iloc[-1] - s.t_s.iloc[0])
    tol = 3.0 * sigma * math.sqrt(2.0 * pitch.pitch_variation.correlation_length / ell)
    assert 5.0 < tol < 12.0
    assert abs(s["state.print_span.tension_N"].mean() - sp) < tol
    # the tension the loop sees (sensor B through E·S and L0): its error averages out
    assert abs(s["ctrl.registration_loop.error_N"].mean()) < 0.01 * sp
    # sensor A reads the same span (within its noise's mean and the span's variation)
    assert abs(s[A].mean() - s["state.print_span.tension_N"].mean()) < 1.0
    # the dancer's spans at the tension its load holds; the carriage's Coulomb friction
    # (2 N) may leave half of it on each span
    t_dancer = _dancer_tension(line)
    assert abs(t_dancer - 220.0) < 0.1
    dancer = next(e for e in line.elements if e.id == "dancer")
    for span in ("span2", "span3"):
        assert abs(s[f"state.{span}.tension_N"].mean() - t_dancer) < dancer.coulomb / 2 + 0.2
    assert abs(s["state.dancer.position_m"]).max() < 0.01
    # the rewind at its set-point (torque mode + load-cell trim): 1 N
    assert (
        abs(s["state.span7.tension_N"].mean() - float(step["tension"]["rewind_tension"].split()[0]))
        < 1.0
    )


# ---- the plug-ins on short runs of the line -------------------------------------------------

#: the methods of benchmarks/second_line.yaml, with their parameters from the spec (the
#: documented constructor parameters, nothing else)
METHODS = {m.key: (m.method, m.params) for m in load_spec(SPEC).methods}


@pytest.fixture(scope="module")
def short_runs(tmp_path_factory):
    """30 s runs of the base scenario in L1: three healthy to train, one to calibrate, and a
    healthy one, a sensor-A offset of +10 % and a sensor-B gain shifting the loop's tension
    by -10 % (both from 15 s) to test."""
    d = tmp_path_factory.mktemp("short")
    base = yaml.safe_load((SET / "production.yaml").read_text(encoding="utf-8"))
    base["line"] = str(LINE)
    faults = {
        6: [
            {
                "id": "a_offset",
                "type": "sensor.offset",
                "target": "sensor_A",
                "onset": "15 s",
                "magnitude": "20 N",
            }
        ],
        7: [
            {
                "id": "b_gain",
                "type": "sensor.gain",
                "target": "sensor_B",
                "onset": "15 s",
                "magnitude": -5.2056e-05,
            }
        ],
    }
    runs = {}
    for seed in range(1, 8):
        scen = {**base, "seed": seed, "faults": faults.get(seed, [])}
        (d / f"s{seed}.yaml").write_text(yaml.safe_dump(scen), encoding="utf-8")
        out = run_scenario(d / f"s{seed}.yaml", d / f"run{seed}", duration=30.0).output
        runs[seed] = read_runs(out, verify=False)[0]
    return [runs[1], runs[2], runs[3]], [runs[4]], [runs[5], runs[6], runs[7]]


def test_the_spec_has_the_baselines_and_thesis_methods():
    assert set(METHODS) == {
        "residual",
        "pca",
        "dpca",
        "iforest",
        "parity",
        "gsmms",
        "gsmms_physics",
        "gsmms_global",
    }
    for method, params in METHODS.values():
        get(method)(**params)  # documented parameters only: the constructor takes them


@pytest.mark.parametrize("key", sorted(METHODS))
def test_every_method_fits_and_scores_on_the_line(short_runs, key):
    train, val, test = short_runs
    method, params = METHODS[key]
    ev = evaluate(get(method)(**params), train, test, val, alpha=0.01, m=3, n_boot=0)
    m = ev.metrics
    for fault in ("sensor.offset:sensor_A", "sensor.gain:sensor_B"):
        sel = (m.fault == fault) & (m.metric == "pd")
        assert sel.sum() >= 1, (key, fault)
        assert np.isfinite(m.loc[sel, "value"]).all(), (key, fault)
    far = m[(m.fault == "all") & (m.metric == "far_ff")]["value"]
    assert len(far) and np.isfinite(far).all()
    if key == "parity":  # its A-B relations see a 10 % offset of sensor A
        sel = (m.fault == "sensor.offset:sensor_A") & (m.metric == "pd")
        assert (m.loc[sel, "value"] == 1.0).all()


def test_hybrid_sov_configures_itself_from_the_line_and_sees_a_seized_dancer(short_runs, tmp_path):
    # no role, no line file: the stages, sensors and constants come from the line each run
    # carries. selection="F" (OLS): this line's load cell is never censored, and the Tobit
    # likelihood's Hessian is singular without a censored sample
    train, val, _ = short_runs
    base = yaml.safe_load((SET / "production.yaml").read_text(encoding="utf-8"))
    scen = {
        **base,
        "line": str(LINE),
        "seed": 8,
        "faults": [
            {"id": "seized", "type": "dancer.arm_stuck", "target": "dancer", "onset": "12 s"}
        ],
    }
    (tmp_path / "s8.yaml").write_text(yaml.safe_dump(scen), encoding="utf-8")
    out = run_scenario(tmp_path / "s8.yaml", tmp_path / "run8", duration=30.0).output
    seized = read_runs(out, verify=False)[0]
    ev = evaluate(
        get("hybrid-sov")(selection="F"),
        train,
        [val[0], seized],
        [],
        m=3,
        n_boot=0,
        drive_data=True,
    )
    m = ev.metrics
    pd_ = m[(m.fault == "dancer.arm_stuck:dancer") & (m.metric == "pd")]["value"]
    assert pd_.tolist() == [1.0]
    est = get("hybrid-sov")(selection="F").fit(train)
    assert est.stages_.driven.id == "infeed" and est.stages_.sensor_ids["tension"] == "lc_guide"
