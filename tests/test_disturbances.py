"""Process disturbances: drawn from the process stream on fixed grids, acting in the
simulation exactly as drawn, independent of the measurement noise, and reproducible."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim
from r2rsim.compile.disturbances import realise_disturbances
from r2rsim.errors import InputError
from r2rsim.schema.loader import load_scenario

from conftest import REPO, write

RATE = 200.0


def run(tmp_path, disturbances, *, seed=1, name="d", noise=False, duration=20.0, rate=RATE):
    d = yaml.safe_load((REPO / "lines" / "pet_film_line.yaml").read_text())
    if not noise:
        for s in d["sensors"]:
            s.pop("noise", None)
    line = write(tmp_path / f"line_{name}.yaml", yaml.safe_dump(d))
    sc = {"name": name, "line": str(line), "duration": duration, "record_rate": rate,
          "seed": seed, "warmup": 1.0, "programme": [{"at": 0, "line_speed": 5.0}],
          "disturbances": disturbances}
    path = write(tmp_path / f"{name}.yaml", yaml.safe_dump(sc))
    out = tmp_path / f"out_{name}"
    r2rsim.run_scenario(path, output=out)
    return pd.read_parquet(out / "samples"), path


DRAG = {"type": "bearing_drag", "element": "idler1", "std": "0.02 N*m", "bandwidth": "2 Hz"}


def test_bearing_drag_acts_exactly_as_drawn(tmp_path):
    # idler torque balance: J·dw/dt = R·(T2 - T1) - b·w - drag(t), with drag(t) the table
    # drawn on the sample grid from the process stream (sampled at 2 kHz so that dw/dt of
    # the idler's 29 Hz mode can be taken from the samples)
    s, path = run(tmp_path, [DRAG], rate=2000.0, duration=8.0)
    scenario, line, _ = load_scenario(path)
    root = np.random.SeedSequence(scenario.seed)
    (drag,) = realise_disturbances(scenario, line, root.spawn(3)[0])
    t = s.t_s.to_numpy()
    w = s["state.idler1.speed_rad_s"].to_numpy().astype(float)
    dT = (s["state.span2.tension_N"] - s["state.span1.tension_N"]).to_numpy().astype(float)
    implied = 0.05 * dT - 5e-4 * w - 0.011 * np.gradient(w, t)
    table = drag.values[: len(t)]
    m = t > 1.0
    assert np.std(table) == pytest.approx(0.02, rel=0.3)  # the drawn sequence itself
    err = implied[m] - table[m]
    # (what is left is mostly the finite-difference dw/dt across the table's kinks)
    assert np.sqrt(np.mean(err**2)) < 0.1 * np.std(table[m])
    assert np.corrcoef(implied[m], table[m])[0, 1] > 0.995
    # a first-order spectrum at 2 Hz: lag-one correlation exp(-2*pi*2/2000) on the grid
    c = np.corrcoef(table[:-1], table[1:])[0, 1]
    assert c == pytest.approx(np.exp(-2 * np.pi * 2 / 2000.0), abs=1e-3)


def test_disturbances_are_seeded_and_apart_from_measurement_noise(tmp_path):
    both = [DRAG, {"type": "wound_in_strain", "element": "unwind", "std": 1e-5,
                   "correlation_length": "5 m"},
            {"type": "out_of_round", "element": "idler1", "eccentricity": "0.02 mm"}]
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
    s, _ = run(tmp_path, [{"type": "out_of_round", "element": "idler1",
                           "eccentricity": "0.02 mm"}], duration=4.0)
    t = s.t_s.to_numpy()
    m = t > 1.0
    T = s["state.span1.tension_N"].to_numpy()[m]
    spec = np.abs(np.fft.rfft(T - T.mean()))
    f = np.fft.rfftfreq(m.sum(), 1.0 / RATE)
    f_rot = s["state.idler1.speed_rad_s"].to_numpy()[m].mean() / (2 * np.pi)  # 15.9 Hz
    assert abs(f[np.argmax(spec)] - f_rot) <= f[1]
    assert np.ptp(T) > 1.0


@pytest.mark.parametrize("dist, message", [
    ({"type": "bearing_drag", "element": "idler1", "std": 0.01}, "needs 'bandwidth'"),
    ({"type": "bearing_drag", "element": "nope", "std": 0.01, "bandwidth": 1.0},
     "no element 'nope'"),
    ({"type": "wound_in_strain", "element": "idler1", "std": 1e-5,
      "correlation_length": 1.0}, "applies to an unwind"),
    ({"type": "out_of_round", "element": "idler1", "eccentricity": "6 cm"},
     "not less than the roller radius"),
    ({"type": "bearing_drag", "element": "idler1", "std": "2 N", "bandwidth": 1.0},
     "dimension"),
])
def test_bad_disturbances_are_rejected(tmp_path, dist, message):
    line = REPO / "lines" / "pet_film_line.yaml"
    sc = {"name": "bad", "line": str(line), "duration": 5.0,
          "programme": [{"at": 0, "line_speed": 5.0}], "disturbances": [dist]}
    path = write(tmp_path / "bad.yaml", yaml.safe_dump(sc))
    with pytest.raises(InputError) as exc:
        r2rsim.run_scenario(path, output=tmp_path / "out")
    assert message in str(exc.value) and "disturbances[0]" in str(exc.value)
    assert not (tmp_path / "out").exists()
