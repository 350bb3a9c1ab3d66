"""Process disturbances: drawn from the process stream, acting in the simulation exactly as
drawn, independent of the measurement noise, and reproducible. The random ones are smooth sums
of sinusoids whose realised std and spectrum match the declared ones (``shape: table``, the
earlier interpolated tables, is still available)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml
from test_jacobian import FULL, _assert_jacobian_matches_fd, _state

import r2rsim
from r2rsim.compile import kernels
from r2rsim.compile.disturbances import (
    CUTOFF,
    N_SINES,
    DisturbanceInstance,
    autocorrelation,
    realise_disturbances,
)
from r2rsim.compile.layout import NodeP
from r2rsim.errors import InputError
from r2rsim.schema.loader import load_scenario
from r2rsim.schema.scenario import ProgrammeStep

from conftest import REPO, write

RATE = 200.0


def run(tmp_path, disturbances, *, seed=1, name="d", noise=False, duration=20.0, rate=RATE):
    d = yaml.safe_load((REPO / "lines" / "pet_film_line.yaml").read_text())
    if not noise:
        for s in d["sensors"]:
            s.pop("noise", None)
    line = write(tmp_path / f"line_{name}.yaml", yaml.safe_dump(d))
    sc = {
        "name": name,
        "line": str(line),
        "duration": duration,
        "record_rate": rate,
        "seed": seed,
        "warmup": 1.0,
        "programme": [{"at": 0, "line_speed": 5.0}],
        "disturbances": disturbances,
    }
    path = write(tmp_path / f"{name}.yaml", yaml.safe_dump(sc))
    out = tmp_path / f"out_{name}"
    r2rsim.run_scenario(path, output=out)
    return pd.read_parquet(out / "samples"), path


DRAG = {"type": "bearing_drag", "element": "idler1", "std": "0.02 N*m", "bandwidth": "2 Hz"}


def test_bearing_drag_acts_exactly_as_drawn(tmp_path):
    # idler torque balance: J·dw/dt = R·(T2 - T1) - b·w - drag(t), with drag(t) the sum of
    # sinusoids drawn from the process stream (sampled at 2 kHz so that dw/dt of the idler's
    # 29 Hz mode can be taken from the samples)
    s, path = run(tmp_path, [DRAG], rate=2000.0, duration=8.0)
    scenario, line, _ = load_scenario(path)
    root = np.random.SeedSequence(scenario.seed)
    (drag,) = realise_disturbances(scenario, line, root.spawn(3)[0])
    assert drag.shape == "sines"
    t = s.t_s.to_numpy()
    w = s["state.idler1.speed_rad_s"].to_numpy().astype(float)
    dT = (s["state.span2.tension_N"] - s["state.span1.tension_N"]).to_numpy().astype(float)
    implied = 0.05 * dT - 5e-4 * w - 0.011 * np.gradient(w, t)
    drawn = drag.value(t)
    m = t > 1.0
    assert np.std(drawn) == pytest.approx(0.02, rel=0.5)  # 8 s of a 2 Hz process
    err = implied[m] - drawn[m]
    # what is left is the finite-difference dw/dt and float32 samples (no kinks any more)
    assert np.sqrt(np.mean(err**2)) < 0.02 * np.std(drawn[m])
    assert np.corrcoef(implied[m], drawn[m])[0, 1] > 0.9998


def test_table_shape_still_acts_as_drawn(tmp_path):
    # the earlier form, kept to reproduce old data: an AR(1) table on the sample grid
    s, path = run(tmp_path, [{**DRAG, "shape": "table"}], rate=2000.0, duration=4.0)
    scenario, line, _ = load_scenario(path)
    (drag,) = realise_disturbances(scenario, line, np.random.SeedSequence(1).spawn(3)[0])
    assert drag.shape == "table" and len(drag.values) == 4 * 2000 + 2
    t = s.t_s.to_numpy()
    w = s["state.idler1.speed_rad_s"].to_numpy().astype(float)
    dT = (s["state.span2.tension_N"] - s["state.span1.tension_N"]).to_numpy().astype(float)
    implied = 0.05 * dT - 5e-4 * w - 0.011 * np.gradient(w, t)
    m = t > 1.0
    assert np.corrcoef(implied[m], drag.value(t)[m])[0, 1] > 0.995
    # a first-order spectrum at 2 Hz: lag-one correlation exp(-2*pi*2/2000) on the grid
    c = np.corrcoef(drag.values[:-1], drag.values[1:])[0, 1]
    assert c == pytest.approx(np.exp(-2 * np.pi * 2 / 2000.0), abs=1e-3)


def _realise(tmp_path, dist, seeds, speed=1.0):
    """The realisations of one disturbance for each seed (no simulation)."""
    path = write(
        tmp_path / "sc.yaml",
        yaml.safe_dump(
            {
                "name": "sc",
                "line": str(REPO / "lines" / "pet_film_line.yaml"),
                "duration": 120.0,
                "record_rate": 100.0,
                "programme": [{"at": 0, "line_speed": speed}],
                "disturbances": [dist],
            }
        ),
    )
    scenario, line, _ = load_scenario(path)
    return [
        realise_disturbances(scenario, line, np.random.SeedSequence(seed).spawn(3)[0])[0]
        for seed in seeds
    ]


@pytest.mark.parametrize(
    "dist, std, corner, unit",
    [
        (DRAG, 0.02, 2.0, "s"),
        (
            {
                "type": "wound_in_strain",
                "element": "unwind",
                "std": 3e-5,
                "correlation_length": "5 m",
            },
            3e-5,
            1.0 / (2 * np.pi * 5.0),
            "m",
        ),
    ],
)
def test_sines_have_the_declared_std_and_spectrum(tmp_path, dist, std, corner, unit):
    ds = _realise(tmp_path, dist, range(300))
    d = ds[0]
    assert d.shape == "sines" and len(d.amplitudes) == N_SINES
    # the variance is exact: every term carries std²/N, so the mean square of each
    # realisation over a long record is std²
    for x in ds:
        assert np.sum(x.amplitudes**2) / 2 == pytest.approx(std**2, rel=1e-12)
        assert x.omegas.min() > 0 and x.omegas.max() <= 2 * np.pi * CUTOFF * corner * 1.000001
    # the spectrum: the ensemble autocorrelation at lags of 1/2, 1 and 2 time constants
    # (correlation lengths) against the truncated first-order spectrum's. Each seed gives
    # the mean over 200 points 20 time constants apart; the tolerance is four standard
    # errors of the mean over the 300 independent seeds (a 6e-5 chance of a false failure
    # for a Gaussian estimate; the seeds are fixed, so the test is deterministic anyway)
    tc = 1.0 / (2 * np.pi * corner)
    s0 = 20 * tc * np.arange(200)
    ms = np.array([np.mean(x.value(s0) ** 2) for x in ds]) / std**2
    assert abs(ms.mean() - 1.0) < 4 * ms.std(ddof=1) / np.sqrt(len(ms)) + 1e-3
    for lag in (0.5 * tc, tc, 2 * tc):
        r = np.array([np.mean(x.value(s0) * x.value(s0 + lag)) for x in ds]) / std**2
        expect = autocorrelation(lag, corner)
        assert abs(r.mean() - expect) < 4 * r.std(ddof=1) / np.sqrt(len(r)), (unit, lag)
    # the cut-off at 10 corners changes the first-order correlation exp(-lag/tc) by little
    assert autocorrelation(tc, corner) == pytest.approx(np.exp(-1), abs=0.025)
    assert autocorrelation(2 * tc, corner) == pytest.approx(np.exp(-2), abs=0.02)


def test_sines_are_seeded(tmp_path):
    a, b = _realise(tmp_path, DRAG, [7, 7])
    (c,) = _realise(tmp_path, DRAG, [8])
    t = np.linspace(0.0, 20.0, 2001)
    np.testing.assert_array_equal(a.value(t), b.value(t))  # same seed: identical
    assert np.max(np.abs(a.value(t) - c.value(t))) > 0.01  # another seed: another trace
    assert not np.any(np.isin(a.phases, c.phases))


def test_sines_are_smooth_and_tables_are_not(tmp_path):
    # a kink makes the largest second difference shrink like h (a jump of the slope), a
    # smooth signal like h²: halving the step divides it by 2 and by 4 respectively
    (sines,) = _realise(tmp_path, DRAG, [3])
    (table,) = _realise(tmp_path, {**DRAG, "shape": "table"}, [3])

    def second_difference(d, h):
        x = d.value(np.arange(0.0, 10.0, h) + 0.3e-3)
        return np.max(np.abs(np.diff(x, 2)))

    h = 1e-3
    smooth = second_difference(sines, h) / second_difference(sines, h / 2)
    kinked = second_difference(table, h) / second_difference(table, h / 2)
    assert smooth == pytest.approx(4.0, rel=0.05)
    assert kinked == pytest.approx(2.0, rel=0.25)
    # and bounded by the analytic curvature sum a·omega²
    bound = np.sum(sines.amplitudes * sines.omegas**2)
    assert second_difference(sines, h) <= bound * h * h


@pytest.mark.parametrize("model", ["exact", "linear"])
def test_jacobian_with_disturbances(tmp_path, model):
    # the wound-in strain depends on the unwound length (a state): d/du enters the rows of
    # the unwind's length and of the first span; a bearing drag depends on time only
    path = write(tmp_path / "full.yaml", FULL.format(model=model, limit=200))
    line = r2rsim.load_line(path)
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=2.0)])
    rng = np.random.default_rng(5)
    n = N_SINES
    wound = DisturbanceInstance(
        "wound_in_strain",
        "unwind",
        "sines",
        amplitudes=np.full(n, 1e-3),
        omegas=rng.uniform(1, 30, n),
        phases=rng.uniform(0, 6, n),
    )
    drag = DisturbanceInstance(
        "bearing_drag",
        "idler1",
        "sines",
        amplitudes=np.full(n, 0.01),
        omegas=rng.uniform(1, 60, n),
        phases=rng.uniform(0, 6, n),
    )
    cl = r2rsim.compile_line(line, prog, (), [wound, drag])
    plain = r2rsim.compile_line(line, prog)
    y = _state(cl, np.random.default_rng(3))
    _assert_jacobian_matches_fd(cl, 1.7, y, floor=1e-7)
    iu, ie = cl.index("unwind.unstretched_length"), cl.index("span1.strain")
    J = cl.jacobian(1.7, y)
    assert J[iu, iu] != 0.0 and J[ie, iu] != 0.0
    assert plain.jacobian(1.7, y)[ie, iu] == 0.0
    assert (cl.lband, cl.uband) == (plain.lband, plain.uband)  # the band does not grow


def test_bearing_drag_cache_never_changes_a_value(tmp_path):
    # the kernel keeps the last three drag values by time (Radau IIA evaluates each stage
    # time several times per step): the first evaluation of a fresh line is at t = 0, where
    # an unmarked (zeroed) slot would match; then repeats, the stage pattern, and more
    # distinct times than slots
    path = write(tmp_path / "full.yaml", FULL.format(model="exact", limit=200))
    line = r2rsim.load_line(path)
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=2.0)])
    rng = np.random.default_rng(8)
    n = N_SINES
    drag = DisturbanceInstance(
        "bearing_drag",
        "idler1",
        "sines",
        amplitudes=np.full(n, 0.01),
        omegas=rng.uniform(1, 60, n),
        phases=rng.uniform(0, 6, n),
    )
    cl = r2rsim.compile_line(line, prog, (), [drag])
    plain = r2rsim.compile_line(line, prog)
    y = _state(cl, np.random.default_rng(3))
    iw = cl.index("idler1.speed")
    inertia = cl.node_p[cl.node_ids.index("idler1"), NodeP.J]
    start, end = kernels.scratch_layout(cl.I)
    times = [0.0, 0.3, 0.3, 0.1, 0.2, 0.3, 0.1, 0.2, 0.3, 0.3, 5.0, 0.7, 0.9, 0.1, 0.0]
    for t in times:
        got = cl.rhs(t, y)
        cl._W[start:end] = np.nan  # the same evaluation with an empty cache
        assert np.array_equal(got, cl.rhs(t, y))
        torque = float(np.sum(drag.amplitudes * np.sin(drag.omegas * t + drag.phases)))
        assert torque != 0.0
        dw = got[iw] - plain.rhs(t, y)[iw]
        assert dw == pytest.approx(-torque / inertia, rel=1e-9)


def test_disturbances_are_seeded_and_apart_from_measurement_noise(tmp_path):
    both = [
        DRAG,
        {"type": "wound_in_strain", "element": "unwind", "std": 1e-5, "correlation_length": "5 m"},
        {"type": "out_of_round", "element": "idler1", "eccentricity": "0.02 mm"},
    ]
    a, _ = run(tmp_path, both, name="a", noise=True, duration=6.0)
    b, _ = run(tmp_path, both, name="b", noise=True, duration=6.0)
    c, _ = run(tmp_path, both, name="c", noise=True, seed=2, duration=6.0)
    clean, _ = run(tmp_path, [], name="clean", noise=True, duration=6.0)
    state = [col for col in a.columns if col.startswith(("state.", "true.", "meas."))]
    pd.testing.assert_frame_equal(a[state], b[state])  # same seed: the same data
    T = "state.span1.tension_N"
    assert np.max(np.abs(a[T] - c[T])) > 0.05  # another seed: other disturbances
    assert np.max(np.abs(a[T] - clean[T])) > 0.05  # they act on the process
    # the measurement noise does not depend on the process disturbances (no filter on the
    # diameter sensor: meas - true is the noise itself)
    na = (a["meas.dia_unwind.diameter_m"] - a["true.dia_unwind.diameter_m"]).to_numpy()
    nc = (clean["meas.dia_unwind.diameter_m"] - clean["true.dia_unwind.diameter_m"]).to_numpy()
    assert np.std(na) > 0
    np.testing.assert_allclose(na, nc, atol=1e-6)


def test_out_of_round_idler_ripples_at_its_rotation_frequency(tmp_path):
    s, _ = run(
        tmp_path,
        [{"type": "out_of_round", "element": "idler1", "eccentricity": "0.02 mm"}],
        duration=4.0,
    )
    t = s.t_s.to_numpy()
    m = t > 1.0
    T = s["state.span1.tension_N"].to_numpy()[m]
    spec = np.abs(np.fft.rfft(T - T.mean()))
    f = np.fft.rfftfreq(m.sum(), 1.0 / RATE)
    f_rot = s["state.idler1.speed_rad_s"].to_numpy()[m].mean() / (2 * np.pi)  # 15.9 Hz
    assert abs(f[np.argmax(spec)] - f_rot) <= f[1]
    assert np.ptp(T) > 1.0


@pytest.mark.parametrize(
    "dist, message",
    [
        ({"type": "bearing_drag", "element": "idler1", "std": 0.01}, "needs 'bandwidth'"),
        (
            {"type": "bearing_drag", "element": "nope", "std": 0.01, "bandwidth": 1.0},
            "no element 'nope'",
        ),
        (
            {
                "type": "wound_in_strain",
                "element": "idler1",
                "std": 1e-5,
                "correlation_length": 1.0,
            },
            "applies to an unwind",
        ),
        (
            {"type": "out_of_round", "element": "idler1", "eccentricity": "6 cm"},
            "not less than the roller radius",
        ),
        (
            {"type": "bearing_drag", "element": "idler1", "std": "2 N", "bandwidth": 1.0},
            "dimension",
        ),
        ({**DRAG, "band_limit": "1 Hz"}, "below the bandwidth (2 Hz)"),
        ({**DRAG, "shape": "table", "band_limit": "5 Hz"}, "of shape sines only"),
        (
            {
                "type": "wound_in_strain",
                "element": "unwind",
                "std": 1e-5,
                "correlation_length": 1.0,
                "band_limit": "5 Hz",
            },
            "bearing_drag disturbance of shape sines only",
        ),
    ],
)
def test_bad_disturbances_are_rejected(tmp_path, dist, message):
    line = REPO / "lines" / "pet_film_line.yaml"
    sc = {
        "name": "bad",
        "line": str(line),
        "duration": 5.0,
        "programme": [{"at": 0, "line_speed": 5.0}],
        "disturbances": [dist],
    }
    path = write(tmp_path / "bad.yaml", yaml.safe_dump(sc))
    with pytest.raises(InputError) as exc:
        r2rsim.run_scenario(path, output=tmp_path / "out")
    assert message in str(exc.value) and "disturbances[0]" in str(exc.value)
    assert not (tmp_path / "out").exists()


def test_band_limit_drops_the_terms_above_it_and_keeps_the_rest(tmp_path):
    # the same seed draws the same 32 terms; a band limit keeps those at or below it, so a
    # band-limited run is the full one minus its high-frequency part
    seeds = range(1, 9)
    full = _realise(tmp_path, DRAG, seeds)
    limited = _realise(tmp_path, {**DRAG, "band_limit": "5 Hz"}, seeds)
    kept_total = 0
    for f, b in zip(full, limited, strict=True):
        keep = f.omegas <= 2 * np.pi * 5.0
        assert 0 < keep.sum() < 32
        np.testing.assert_array_equal(b.omegas, f.omegas[keep])
        np.testing.assert_array_equal(b.phases, f.phases[keep])
        np.testing.assert_array_equal(b.amplitudes, f.amplitudes[keep])
        # its mean square over a long record is std^2 * kept / 32 (equal-power terms)
        t = np.arange(0.0, 2000.0, 0.01)
        assert np.mean(b.value(t) ** 2) == pytest.approx(0.02**2 * keep.sum() / 32, rel=0.03)
        kept_total += keep.sum()
    # stratified frequencies: the share of terms below 5 Hz is the share of the truncated
    # first-order spectrum there, atan(5/2) / atan(10), up to one term per draw
    assert kept_total / (32 * len(full)) == pytest.approx(
        np.arctan(2.5) / np.arctan(10), abs=1 / 32
    )


def test_the_band_limited_example_runs_the_full_draw_minus_its_high_terms(tmp_path):
    # scenarios/band_limited_drag.yaml against the same file without its band limits: each
    # drag is the full drag minus the terms above 5 Hz, to the bit, and the solver needs
    # fewer right-hand sides for it
    path = REPO / "scenarios" / "band_limited_drag.yaml"
    full = yaml.safe_load(path.read_text())
    full["line"] = str(REPO / "lines" / "registration.yaml")
    for d in full["disturbances"]:
        d.pop("band_limit", None)
    full_path = write(tmp_path / "full.yaml", yaml.safe_dump(full))
    draws = {}
    for label, p in (("limited", path), ("full", full_path)):
        scenario, line, _ = load_scenario(p)
        stream = np.random.SeedSequence(scenario.seed).spawn(3)[0]
        draws[label] = realise_disturbances(scenario, line, stream)
    drags = 0
    for b, f in zip(draws["limited"], draws["full"], strict=True):
        if b.type != "bearing_drag":
            assert b.type == f.type and (b.omegas is None or np.array_equal(b.omegas, f.omegas))
            continue
        drags += 1
        above = f.omegas > 2 * np.pi * 5.0
        assert 0 < above.sum() < 32
        t = np.linspace(0.0, 60.0, 6001)
        high = np.sin(np.multiply.outer(t, f.omegas[above]) + f.phases[above]) @ f.amplitudes[above]
        np.testing.assert_allclose(b.value(t), f.value(t) - high, rtol=0, atol=1e-15)
    assert drags == 2
    rhs = {}
    for label, p in (("limited", path), ("full", full_path)):
        summary = r2rsim.run_scenario(p, output=tmp_path / label, duration=20.0)
        assert not summary.terminated
        rhs[label] = summary.solver_stats["nfev"]
    assert rhs["limited"] < 0.8 * rhs["full"], rhs
