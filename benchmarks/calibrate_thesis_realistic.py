"""Calibration of the thesis-realistic set (scenarios/thesis_realistic/, docs/dataset.md §8.2).

Measures the noise of a well-designed *local* residual on healthy runs of each condition and
prints how many of its standard deviations a 5 % and a 20 % sensor-A fault are. The residual
is the regime-local static A-B parity relation of the thesis (Ch. 3, Ω¹): sensor A against
sensor B's pitch, ``r = A - (c0 + c1·B)`` with (c0, c1) fitted by least squares on five runs
of the condition, then averaged over 1 s (the white sensor noise filtered out) and evaluated
on five other runs. Its standard deviation there, σ, contains what no filter removes: the
printing variation along the web, each run's roll (modulus, thickness, relaxed pitch, radius
in the pitch law) and calibration, and the disturbances.

Seeds 1001-1010, which no sweep of the set and no benchmark uses. The target (issue 16):
a 20 % fault about 4-6σ and a 5 % fault about 1-1.5σ.

    python benchmarks/calibrate_thesis_realistic.py [--workers N]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
SET = REPO / "scenarios" / "thesis_realistic"
FIT_SEEDS = list(range(1001, 1006))
TEST_SEEDS = list(range(1006, 1011))
WINDOW_S = 1.0
#: the healthy sweep's conditions and their tension set-points [N]
CONDITIONS = {"OC1": 130.0, "OC2": 160.0, "OC3": 145.0, "P2": 130.0}


def local_residual_sigma(runs, setpoint: float, fit_seeds=FIT_SEEDS, test_seeds=TEST_SEEDS) -> dict:
    """σ of the 1 s-averaged local A-B residual of one condition's ``runs``: fitted on the
    runs of ``fit_seeds``, measured on those of ``test_seeds``."""

    def averaged(run):
        s = run.samples
        s = s[s.t_s >= 10.0]  # after the first controller transients
        k = int(round(WINDOW_S * 100))
        n = len(s) // k * k
        a = s["meas.sensor_A.tension_N"].to_numpy()[:n].reshape(-1, k)
        b = s["meas.sensor_B.pitch_m"].to_numpy()[:n].reshape(-1, k)
        return np.nanmean(a, axis=1), np.nanmean(b, axis=1)

    fit = [averaged(r) for r in runs if r.info["seed"] in fit_seeds]
    test = [averaged(r) for r in runs if r.info["seed"] in test_seeds]
    a = np.concatenate([f[0] for f in fit])
    b = np.concatenate([f[1] for f in fit])
    b0 = b.mean()  # centred: B varies by parts per million of its value
    c1, c0 = np.polyfit(b - b0, a, 1)
    res = [ta - (c0 + c1 * (tb - b0)) for ta, tb in test]
    within = float(np.mean([r.std(ddof=1) for r in res]))
    between = float(np.std([r.mean() for r in res], ddof=1))
    sigma = float(np.concatenate(res).std(ddof=1))
    return {
        "sigma_N": sigma,
        "within_run_N": within,
        "between_runs_N": between,
        "P05_sigmas": 0.05 * setpoint / sigma,
        "P20_sigmas": 0.20 * setpoint / sigma,
    }


def calibrate(
    fit_seeds=FIT_SEEDS, test_seeds=TEST_SEEDS, duration=None, workers=None, modes=CONDITIONS
) -> dict[str, dict]:
    """Run the healthy sweep's conditions ``modes`` with the given seeds (optionally shorter)
    and measure the local residual of each: {mode: local_residual_sigma(...)}."""
    from r2rsim.dataset.read import read_runs
    from r2rsim.sweep import run_sweep

    sweep = yaml.safe_load((SET / "healthy.yaml").read_text())
    sweep.update(
        name="thesis_realistic_calibration",
        scenario=str(SET / "registration.yaml"),
        seeds=list(fit_seeds) + list(test_seeds),
    )
    sweep.pop("seed", None)
    if duration is not None:
        sweep.setdefault("set", {})["duration"] = duration
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "calibration.yaml"
        path.write_text(yaml.safe_dump(sweep))
        run_sweep(path, output=Path(tmp) / "out", workers=workers)
        for mode in modes:
            runs = read_runs(Path(tmp) / "out", where={"mode": mode})
            out[mode] = local_residual_sigma(runs, CONDITIONS[mode], fit_seeds, test_seeds)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args(argv)
    print(
        f"{'condition':<10} {'set-point':>9} {'sigma':>7} {'within':>7} {'between':>8} "
        f"{'P05/sigma':>9} {'P20/sigma':>9}"
    )
    for mode, m in calibrate(workers=args.workers).items():
        print(
            f"{mode:<10} {CONDITIONS[mode]:>7.0f} N {m['sigma_N']:>5.2f} N "
            f"{m['within_run_N']:>5.2f} N {m['between_runs_N']:>6.2f} N "
            f"{m['P05_sigmas']:>9.2f} {m['P20_sigmas']:>9.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
