"""Reproduction study of Shui (2018) Ch. 2: the hybrid multistage tension model and virtual
sensor (``hybrid-sov``) against the data-driven comparator, on the calibrated Ch. 2 test bed
(lines/thesis_testbed_realistic.yaml; docs/diagnostics.md §9).

Data: the test bed's roll-change cycles (scenarios/thesis_realistic/testbed_cycles.yaml,
600 s runs with about eight roll changes, every roll different) and the dancer-failure runs
(testbed_dancer_failure_sweep.yaml). As the dataset documents it (docs/dataset.md §8.2), the
models train on the first 4 complete cycles of the 0.5 m/s run of seed 1 and validate on the
first 3 complete cycles of the 0.6 m/s run of seed 2 (other rolls, other speed); the last 3
cycles of the training run (same speed, other rolls) are a second, reported-only validation.

The study runs hybrid-sov's offline preprocessing (``causal=False``, the centred filter of
the thesis; see ``CAUSAL``); the dancer-failure detection of the plug-in's causal default is
reported beside it, not asserted.

    python benchmarks/reproduction/ch2_hybrid_sov.py -o results/ch2
    python benchmarks/reproduction/ch2_hybrid_sov.py -o results/ch2 \
        --data /work/data/testbed_cycles --startup-data /work/data/testbed_startup
    python benchmarks/reproduction/ch2_hybrid_sov.py --quick -o "$(mktemp -d)"

Writes DIR/report.md, DIR/table_2_3.csv, table_2_4.csv, table_2_5.csv, assertions.json and
the figures. Exit status: 0 when every asserted check passes or is one of the study's
documented non-reproductions (``EXPECTED_FAILURES``: printed as XFAIL (documented), with its
reason); 3 when a check the committed report passes fails, or a listed one unexpectedly
passes (XPASS; see _expected.py); 1 is an error, 2 a usage error. ``--quick`` (CI) asserts
the checks the full study passes; the ones it fails are reported in parentheses, not asserted.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _expected.py, beside this file
from _expected import exit_status, report_note, summary, verdict  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
LINE = REPO / "lines" / "thesis_testbed_realistic.yaml"
SCEN = REPO / "scenarios" / "thesis_realistic"
#: the checks the committed full report (docs/reproduction/hybrid_sov/report.md) fails: the
#: documented non-reproductions, each with its reason. They are XFAIL (documented), not a
#: failure: the exit status is 0 unless another check fails or one of these passes (XPASS)
EXPECTED_FAILURES = {
    "tension AIC hybrid < data-driven (Tobit likelihoods)": (
        "AIC on tens of thousands of autocorrelated training samples rewards the data-driven "
        "model's better in-sample fit (report: Reading the results)"
    ),
    "pitch AIC hybrid < data-driven (Gaussian likelihoods)": (
        "as the tension AIC: the in-sample fit of the quadratic data-driven pitch model wins"
    ),
    "pitch: transient RMSE >= 1.5 x steady RMSE (hybrid, validation)": (
        "each test-bed roll has its own relaxed pitch, which L0(R) cannot know: the pitch "
        "error is a per-roll offset more than a transient one"
    ),
    "stepwise keeps the dancer angle in the dancer stage (alternating fit)": (
        "the alternating fit's pitch-derived stage-3 target carries per-roll offsets (~4.5 N) "
        "and selects no dancer term; the oracle fit selects alpha"
    ),
}
N_TRAIN, N_VAL = 4, 3
#: the study runs hybrid-sov's offline preprocessing (centred Savitzky-Golay filter), as the
#: thesis does: its comparisons with the true tensions (T_s3 RMSE, the pre-changeover climb,
#: the roll-change windows) need estimates that refer to their own sample, while the default
#: causal filter's refer to half a window earlier. The causal default's dancer-failure
#: detection is reported beside the asserted offline one.
CAUSAL = False

#: Thesis Table 2-3 (normalised units) and Table 2-4, for the side-by-side tables
THESIS_23 = {
    "physics + linear": (0.2136, 0.2228, None, 0.0140, 0.0102, -4229),
    "physics + censored": (0.2137, 0.2214, 7096, None, None, None),
    "data-driven linear": (0.1493, 0.2526, None, 0.0138, 0.0344, -4210),
    "data-driven censored": (0.1354, 0.2612, 7797, None, None, None),
}
THESIS_24 = {"tension": (0.1277, 0.3229, 0.2214), "pitch": (0.0037, 0.0260, 0.0102)}
THESIS_25 = {"tension": (0.4076, 0.5590), "pitch": (0.1001, 0.2818)}


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-o", "--output", required=True, help="report directory")
    p.add_argument(
        "--quick",
        action="store_true",
        help="reduced version for CI: fewer runs and bootstrap replicates",
    )
    p.add_argument(
        "--data",
        help="the test-bed cycles dataset (testbed_cycles.yaml sweep); "
        "default: simulate into OUTPUT/data",
    )
    p.add_argument(
        "--failure-data",
        help="the dancer-failure dataset (testbed_dancer_failure_sweep.yaml); default: simulate",
    )
    p.add_argument(
        "--startup-data",
        help="the start-up run (testbed_startup.yaml) for the "
        "censored data; default: simulate (skipped with --quick)",
    )
    p.add_argument("--workdir", help="where simulated datasets go (default OUTPUT/data)")
    p.add_argument(
        "--n-boot",
        type=int,
        default=None,
        help="bootstrap replicates over cycles (default 2000, quick 500)",
    )
    args = p.parse_args(argv)
    args.command = " ".join(sys.argv[1:] if argv is None else argv)
    if args.n_boot is None:
        args.n_boot = 500 if args.quick else 2000
    if args.n_boot < 100:
        p.error("--n-boot must be >= 100")
    return args


# ---------------------------------------------------------------------------- data
def _sweep_file(out: Path, name: str, scenario: Path, seeds, axes: str = "") -> Path:
    path = out / f"{name}.yaml"
    path.write_text(f"name: {name}\nscenario: {scenario}\nseeds: {list(seeds)}\n{axes}")
    return path


def simulate(out: Path, quick: bool, need=("cycles", "failure", "startup")) -> dict:
    """Simulate the datasets the study needs (``need``) into ``out``: the cycles, the
    dancer failures and (not with ``quick``) the start-up run."""
    from r2rsim import run_scenario
    from r2rsim.sweep import run_sweep

    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    if "cycles" not in need:
        pass
    elif quick:  # the two runs the split needs (seed 1 at 0.5 m/s, seed 2 at 0.6 m/s) + 2
        spec = _sweep_file(
            out,
            "cycles",
            SCEN / "testbed.yaml",
            [1, 2],
            (
                "axes:\n  - {name: speed, path: 'programme[0].line_speed', "
                "values: [0.5 m/s, 0.6 m/s]}\n"
            ),
        )
    else:
        spec = SCEN / "testbed_cycles.yaml"
    if "cycles" in need:
        run_sweep(spec, out / "testbed_cycles", workers=1)
        paths["cycles"] = out / "testbed_cycles"
    if "failure" in need:
        fail = _sweep_file(
            out, "failure", SCEN / "testbed_dancer_failure.yaml", [1] if quick else [1, 2, 3]
        )
        run_sweep(fail, out / "dancer_failure", workers=1)
        paths["failure"] = out / "dancer_failure"
    if "startup" in need and not quick:
        run_scenario(SCEN / "testbed_startup.yaml", output=out / "testbed_startup")
        paths["startup"] = out / "testbed_startup"
    return paths


def splice_events(dataset: Path, run_id: str) -> pd.DataFrame:
    """The roll-change events of a run: t_s and state (fill, brake, swap, complete, ...)."""
    ev = pd.read_parquet(dataset / "events.parquet")
    ev = ev[(ev["run_id"] == run_id) & (ev["kind"] == "splice")]
    return ev[["t_s", "state"]].reset_index(drop=True)


def cycles_of(t: np.ndarray, events: pd.DataFrame) -> list[np.ndarray]:
    """Boolean masks of the complete cycles of a run: from one roll swap to the next."""
    swaps = np.sort(events.loc[events["state"] == "swap", "t_s"].to_numpy())
    return [(t >= a) & (t < b) for a, b in zip(swaps[:-1], swaps[1:], strict=True)]


def windows(events: pd.DataFrame, start: str, end: str) -> list[tuple[float, float]]:
    """(start, end) times of each roll change's phase from state ``start`` to ``end``."""
    a = np.sort(events.loc[events["state"] == start, "t_s"].to_numpy())
    b = np.sort(events.loc[events["state"] == end, "t_s"].to_numpy())
    return [(x, b[b > x][0]) for x in a if (b > x).any()]


def in_windows(t, wins) -> np.ndarray:
    m = np.zeros(len(t), bool)
    for a, b in wins:
        m |= (t >= a) & (t <= b)
    return m


# ---------------------------------------------------------------------------- statistics
def rmse(e) -> float:
    e = np.asarray(e, float)
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e**2)))


def bootstrap_improvement(
    err_h: list[np.ndarray], err_d: list[np.ndarray], n_boot: int, seed: int = 0
) -> tuple[float, float, float]:
    """Relative RMSE improvement 1 - RMSE_h/RMSE_d pooled over cycles, and its 95 %
    percentile bootstrap interval with cycles resampled with replacement."""
    sh = np.array([np.sum(e**2) for e in err_h])
    sd = np.array([np.sum(e**2) for e in err_d])
    n = np.array([len(e) for e in err_h])
    point = 1.0 - np.sqrt(sh.sum() / n.sum()) / np.sqrt(sd.sum() / n.sum())
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(sh), size=(n_boot, len(sh)))
    boot = 1.0 - np.sqrt(sh[idx].sum(1) / n[idx].sum(1)) / np.sqrt(sd[idx].sum(1) / n[idx].sum(1))
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return float(point), float(lo), float(hi)


def decorrelation_lag(x: np.ndarray) -> int:
    """The first lag at which the sample autocorrelation falls below 1/e."""
    x = x - x.mean()
    f = np.fft.rfft(x, 2 * len(x))
    acf = np.fft.irfft(f * np.conj(f))[: len(x)]
    acf /= acf[0]
    below = np.flatnonzero(acf < np.exp(-1))
    return int(below[0]) if below.size else len(x) // 10


def whiteness(resids: list[np.ndarray]) -> dict:
    """Ljung-Box (10 lags) and ARCH (5 lags) p-values of residuals decimated per cycle to
    their decorrelation time."""
    from statsmodels.stats.diagnostic import acorr_ljungbox

    lag = max(1, int(np.median([decorrelation_lag(r) for r in resids])))
    dec = np.concatenate([r[::lag] for r in resids])
    lb = acorr_ljungbox(dec, lags=[10], return_df=True)
    return {
        "lag_samples": lag,
        "n": int(dec.size),
        "ljung_box_p": float(lb["lb_pvalue"].iloc[0]),
        "arch_p": arch_lm_p(dec, 5),
        "resid": dec,
    }


def arch_lm_p(e: np.ndarray, nlags: int) -> float:
    """Engle's ARCH LM test: n·R² of e² regressed on its ``nlags`` lags, chi²(nlags)
    (statsmodels' het_arch, written out: its return type changes between releases)."""
    from scipy import stats

    e2 = (e - e.mean()) ** 2
    y = e2[nlags:]
    X = np.column_stack([np.ones(len(y))] + [e2[nlags - k : -k] for k in range(1, nlags + 1)])
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r2 = 1.0 - np.sum((y - X @ beta) ** 2) / np.sum((y - y.mean()) ** 2)
    return float(stats.chi2.sf(len(y) * r2, nlags))


def slope(t, y) -> float:
    return float(np.polyfit(t - t[0], y, 1)[0])


# ---------------------------------------------------------------------------- study
class Cycle:
    """One cycle: its preprocessed signals, true tensions and roll-change windows."""

    def __init__(self, sig, truth, fills, transients):
        self.sig, self.truth, self.fills, self.transients = sig, truth, fills, transients


def load_cycles(dataset: Path, where: dict, st, first: int, count: int) -> list[Cycle]:
    from r2rsim.dataset.read import read_runs
    from r2rsim.diagnostics.hybrid_sov import _features as F

    runs = read_runs(dataset, where=where)
    if len(runs) != 1:
        raise SystemExit(f"{dataset}: expected one run with {where}, found {len(runs)}")
    run = runs[0]
    ev = splice_events(dataset, run.run_id)
    S, frame = run.samples, run.visible(drive_data=True)
    t = S["t_s"].to_numpy()
    masks = cycles_of(t, ev)
    if len(masks) < first + count:
        raise SystemExit(f"{dataset} {where}: {len(masks)} complete cycles, need {first + count}")
    fills, trans = windows(ev, "fill", "brake"), windows(ev, "fill", "complete")
    out = []
    for m in masks[first : first + count]:
        truth = {
            "T3": S.loc[m, "state.span6.tension_N"].to_numpy(),
            "T4": S.loc[m, "state.registration.tension_N"].to_numpy(),
        }
        out.append(Cycle(F.signals(frame[m], st, causal=CAUSAL), truth, fills, trans))
    return out


def fit_models(train: list[Cycle], st):
    from r2rsim.diagnostics.hybrid_sov import DataDrivenModel, HybridModel

    sigs = [c.sig for c in train]
    truth = [c.truth for c in train]
    m = {}
    for kind in ("ols", "tobit"):
        m[f"hybrid_{kind}"] = HybridModel(st, kind).fit(sigs)
        m[f"oracle_{kind}"] = HybridModel(st, kind).fit(sigs, truth=truth)
        m[f"dd_{kind}"] = DataDrivenModel(kind).fit(sigs)
    return m


def errors(model, cycles: list[Cycle], what: str) -> list[np.ndarray]:
    """Per cycle: tension (T_s2 vs the load cell) [N], pitch [um] or T_s3 vs truth [N]."""
    out = []
    for c in cycles:
        p = model.predict(c.sig)
        if what == "tension":
            e = p["T_s2"].to_numpy() - c.sig.T2
        elif what == "pitch":
            e = 1e6 * (p["Y_s4"].to_numpy() - c.sig.Y)
        else:
            e = p["T_s3"].to_numpy() - c.truth["T3"]
        out.append(e[c.sig.valid])
    return out


def pooled(errs) -> float:
    return rmse(np.concatenate(errs))


def table_23(m, train, val, val2) -> pd.DataFrame:
    rows = []
    for label, key, pitch in (
        ("physics + linear", "hybrid_ols", True),
        ("physics + censored", "hybrid_tobit", True),
        ("data-driven linear", "dd_ols", True),
        ("data-driven censored", "dd_tobit", False),
        ("physics + censored, oracle stage 3", "oracle_tobit", True),
    ):
        mod = m[key]
        fit12 = mod.tension_.fit if key.startswith("dd") else mod.stage12_.fit
        sig_tr = [c.sig for c in train]
        row = {
            "model": label,
            "tension_train_N": pooled(errors(mod, train, "tension")),
            "tension_val_N": pooled(errors(mod, val, "tension")),
            "tension_val_same_speed_N": pooled(errors(mod, val2, "tension")),
            "tension_aic": fit12.aic,
            "pitch_train_um": pooled(errors(mod, train, "pitch")) if pitch else np.nan,
            "pitch_val_um": pooled(errors(mod, val, "pitch")) if pitch else np.nan,
            "pitch_val_same_speed_um": (pooled(errors(mod, val2, "pitch")) if pitch else np.nan),
            "pitch_aic": mod.pitch_aic(sig_tr) if pitch else np.nan,
        }
        if key.startswith(("hybrid", "oracle")):
            row["T_s3_val_N"] = pooled(errors(mod, val, "T3"))
        rows.append(row)
    return pd.DataFrame(rows)


def table_24(model, cycles: list[Cycle]) -> pd.DataFrame:
    rows = []
    for what, unit in (("tension", "N"), ("pitch", "um")):
        errs = errors(model, cycles, what)
        tr = [in_windows(c.sig.t, c.transients)[c.sig.valid] for c in cycles]
        e, m = np.concatenate(errs), np.concatenate(tr)
        rows.append(
            {
                "output": what,
                "unit": unit,
                "steady": rmse(e[~m]),
                "transient": rmse(e[m]),
                "one_cycle": rmse(e),
                "transient_share": float(m.mean()),
            }
        )
    return pd.DataFrame(rows)


def climb_slopes(model, cycles: list[Cycle]) -> pd.DataFrame:
    """Slopes of the estimated and the true stage-3 tension during each fill (the
    pre-changeover climb, thesis Fig. 2-15a) [N/s]."""
    rows = []
    for i, c in enumerate(cycles):
        p = model.predict(c.sig)["T_s3"].to_numpy()
        for a, b in c.fills:
            m = (c.sig.t >= a) & (c.sig.t <= b)
            if m.sum() < 10:
                continue
            rows.append(
                {
                    "cycle": i + 1,
                    "fill_t_s": a,
                    "est_N_s": slope(c.sig.t[m], p[m]),
                    "true_N_s": slope(c.sig.t[m], c.truth["T3"][m]),
                }
            )
    return pd.DataFrame(rows)


def diagnose(
    method: str, train: Path, test: Path, out: Path, drive: bool, causal: bool = CAUSAL
) -> dict:
    """``r2rsim diagnose`` in-process; returns pd and dd_median_s of the fault stratum
    (hybrid-sov with its ``causal`` parameter as given)."""
    from r2rsim.cli import main

    # --detection-window inf: the seized dancer shows only at the next roll change, about
    # 27 s after the seizure; the default 20 s window would count every method's detection
    # there as a miss, so the whole run is watched (r2rsim 0.2's window, as in the thesis)
    argv = [
        "diagnose",
        "--method",
        method,
        "--train",
        str(train),
        "--test",
        str(test),
        "-o",
        str(out),
        "--overwrite",
        "--n-boot",
        "0",  # its own results of a rerun
        "--detection-window",
        "inf",
    ]
    if drive:
        argv.append("--drive-data")
    if method == "hybrid-sov":
        argv += ["--param", f"line={LINE}", "--param", f"causal={str(causal).lower()}"]
    if main(argv) != 0:
        raise SystemExit(f"r2rsim diagnose --method {method} failed")
    met = pd.read_csv(out / "metrics.csv")
    met = met[met["fault"].astype(str).str.startswith("dancer")]
    get = dict(zip(met["metric"], met["value"], strict=True))
    return {
        "pd": float(get["pd"]),
        "dd_median_s": float(get.get("dd_median_s", np.nan)),
        "far_pre": float(get.get("far_pre", np.nan)),
    }


def failure_profiles(model, dataset: Path, st, before=20.0, after=6.0):
    """T̂_s3 around the first fill of each dancer-failure run."""
    from r2rsim.dataset.read import read_runs
    from r2rsim.diagnostics.hybrid_sov import _features as F

    prof = []
    for run in read_runs(dataset):
        ev = splice_events(dataset, run.run_id)
        fills = ev.loc[ev["state"] == "fill", "t_s"].to_numpy()
        if not fills.size:
            continue
        s = F.signals(run.visible(drive_data=True), st, causal=CAUSAL)
        p = model.predict(s)["T_s3"].to_numpy()
        m = (s.t >= fills[0] - before) & (s.t <= fills[0] + after)
        prof.append((s.t[m] - fills[0], p[m]))
    return prof


def normal_profiles(model, cycles: list[Cycle], before=20.0, after=6.0):
    prof = []
    for c in cycles:
        p = model.predict(c.sig)["T_s3"].to_numpy()
        for a, _ in c.fills:
            if c.sig.t[0] + before <= a <= c.sig.t[-1] - after:
                m = (c.sig.t >= a - before) & (c.sig.t <= a + after)
                prof.append((c.sig.t[m] - a, p[m]))
    return prof


def robustness(dataset: Path, st) -> pd.DataFrame:
    """Reported, not asserted: the main comparison repeated for every (training seed,
    validation seed) pair of the dataset, at the other speed (0.6 m/s) and at the same
    speed (0.5 m/s); hybrid and data-driven, both Tobit for the tension, OLS for the
    pitch."""
    from r2rsim.diagnostics.hybrid_sov import DataDrivenModel, HybridModel

    seeds = sorted(pd.read_parquet(dataset / "runs.parquet")["seed"].unique())
    rows = []
    for s_tr in seeds:
        train = load_cycles(dataset, {"speed": 0.5, "seed": int(s_tr)}, st, 0, N_TRAIN)
        sigs = [c.sig for c in train]
        hy, dd = HybridModel(st, "tobit").fit(sigs), DataDrivenModel("tobit").fit(sigs)
        for s_va in seeds:
            if s_va == s_tr:
                continue
            for speed in (0.6, 0.5):
                val = load_cycles(dataset, {"speed": speed, "seed": int(s_va)}, st, 0, N_VAL)
                rows.append(
                    {
                        "train_seed": int(s_tr),
                        "val_seed": int(s_va),
                        "val_speed_m_s": speed,
                        "tension_hybrid_N": pooled(errors(hy, val, "tension")),
                        "tension_dd_N": pooled(errors(dd, val, "tension")),
                        "pitch_hybrid_um": pooled(errors(hy, val, "pitch")),
                        "pitch_dd_um": pooled(errors(dd, val, "pitch")),
                    }
                )
    return pd.DataFrame(rows)


def censored_study(path: Path, st, model) -> dict:
    """Tobit against OLS on the start-up run (censored load-cell readings) and the defect
    classes (slack vs normal) by multinomial logistic regression."""
    from r2rsim.dataset.read import read_runs
    from r2rsim.diagnostics.hybrid_sov import HybridModel, fit_defect_classifier
    from r2rsim.diagnostics.hybrid_sov import _features as F

    run = read_runs(path)[0]
    s = F.signals(run.visible(drive_data=True), st, causal=CAUSAL)
    T_true = run.samples["state.span4.tension_N"].to_numpy()
    share = float(s.censored.mean())
    tob = HybridModel(st, "tobit").fit_tension([s])
    ols = HybridModel(st, "ols").fit_tension([s])
    labels = np.where(s.censored, "slack", "normal")
    cen = s.censored & s.valid
    out = {
        "censored_share": share,
        "tobit_selected": tob.stage12_.selected,
        "ols_selected": ols.stage12_.selected,
        # on the censored samples the latent Tobit mean should lie at or below 0 N
        "tobit_mean_on_censored_N": float(np.mean(tob.predict_tension(s)[cen])),
        "ols_mean_on_censored_N": float(np.mean(ols.predict_tension(s)[cen])),
        "true_mean_on_censored_N": float(np.mean(T_true[cen])),
    }
    if len(set(labels)) > 1:
        X = np.column_stack([model.predict_tension(s), s.alpha])
        clf = fit_defect_classifier(X, labels, random_state=0)
        out["classifier_accuracy_in_sample"] = float((clf.predict(X) == labels).mean())
        out["classes"] = sorted(str(x) for x in set(labels))
    return out


# ---------------------------------------------------------------------------- report
def _fmt(x, nd=3):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "—"
    return f"{x:.{nd}g}" if isinstance(x, float) else str(x)


def md_table(df: pd.DataFrame, nd=4) -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in df.itertuples(index=False):
        lines.append("| " + " | ".join(_fmt(v, nd) for v in r) + " |")
    return "\n".join(lines)


def figures(out: Path, m, val, train, fail_prof, norm_prof, wh):
    from r2rsim.report import plot_profiles, plot_residual_qq, plot_virtual_sensor

    c = val[0]
    h, o, d = (
        m["hybrid_tobit"].predict(c.sig),
        m["oracle_tobit"].predict(c.sig),
        m["dd_ols"].predict(c.sig),
    )
    pitch = {"vision": 1e6 * (c.sig.Y - 0.25), "hybrid": 1e6 * (h["Y_s4"].to_numpy() - 0.25)}
    dd_pitch = 1e6 * (d["Y_s4"].to_numpy() - 0.25)
    if rmse(dd_pitch - pitch["vision"]) < 100.0:  # else off the scale: see Table 2-3
        pitch["data-driven"] = dd_pitch
    fig = plot_virtual_sensor(
        c.sig.t,
        [
            (
                "T_s2 [N]",
                {
                    "load cell": c.sig.T2,
                    "hybrid": h["T_s2"].to_numpy(),
                    "data-driven": d["T_s2"].to_numpy(),
                },
            ),
            (
                "T_s3 [N] (no sensor)",
                {
                    "true (state.span6)": c.truth["T3"],
                    "virtual sensor": h["T_s3"].to_numpy(),
                    "oracle-trained": o["T_s3"].to_numpy(),
                },
            ),
            ("pitch - 250 mm [µm]", pitch),
        ],
        spans=[w for w in c.transients if c.sig.t[0] <= w[0] <= c.sig.t[-1]],
        title="Fig. 2-13 analogue: validation cycle 1 (0.6 m/s, seed 2)",
        span_label="roll change",
    )
    fig.savefig(out / "fig_2_13_virtual_sensor.png", dpi=80)
    fig = plot_residual_qq(
        {"tension residual": wh["tension"]["resid"], "pitch residual": wh["pitch"]["resid"]},
        title="Fig. 2-14 analogue: decimated validation residuals",
    )
    fig.savefig(out / "fig_2_14_qq.png", dpi=80)
    fig = plot_profiles(
        {"normal cycles (validation)": norm_prof, "dancer seized at 40 s": fail_prof},
        ylabel="virtual-sensor T_s3 [N]",
        xlabel="t - fill start [s]",
        title="Fig. 2-15 analogue: stage-3 tension around the roll change",
    )
    fig.savefig(out / "fig_2_15_profiles.png", dpi=80)


def main(argv=None) -> int:
    args = parse_args(argv)
    t0 = time.perf_counter()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    from r2rsim.diagnostics.hybrid_sov import load_stages

    need = [
        k
        for k, v in (
            ("cycles", args.data),
            ("failure", args.failure_data),
            ("startup", args.startup_data),
        )
        if not v
    ]
    sim = (
        simulate(Path(args.workdir) if args.workdir else out / "data", args.quick, need)
        if need
        else {}
    )
    cycles_ds = Path(args.data) if args.data else sim["cycles"]
    fail_ds = Path(args.failure_data) if args.failure_data else sim["failure"]
    startup_ds = Path(args.startup_data) if args.startup_data else sim.get("startup")
    st = load_stages(LINE)
    train = load_cycles(cycles_ds, {"speed": 0.5, "seed": 1}, st, 0, N_TRAIN)
    val = load_cycles(cycles_ds, {"speed": 0.6, "seed": 2}, st, 0, N_VAL)
    val2 = load_cycles(cycles_ds, {"speed": 0.5, "seed": 1}, st, N_TRAIN, N_VAL)
    m = fit_models(train, st)

    t23 = table_23(m, train, val, val2)
    t24 = table_24(m["hybrid_tobit"], val)
    wh = {w: whiteness(errors(m["hybrid_tobit"], val, w)) for w in ("tension", "pitch")}
    t25 = pd.DataFrame(
        [
            {
                "output": w,
                "decimation_samples": v["lag_samples"],
                "n": v["n"],
                "ljung_box_p": v["ljung_box_p"],
                "arch_p": v["arch_p"],
            }
            for w, v in wh.items()
        ]
    )
    boot = {}
    for w in ("tension", "pitch"):
        for fam, dd in (("censored", "dd_tobit"), ("linear", "dd_ols")):
            if w == "pitch" and fam == "censored":
                continue
            hy = "hybrid_tobit" if fam == "censored" else "hybrid_ols"
            boot[(w, fam)] = bootstrap_improvement(
                errors(m[hy], val, w), errors(m[dd], val, w), args.n_boot
            )
    climbs = climb_slopes(m["hybrid_tobit"], val)
    climb_ratio = float(climbs["est_N_s"].mean() / climbs["true_N_s"].mean())
    diag = {
        "hybrid-sov (offline)": diagnose(
            "hybrid-sov", cycles_ds, fail_ds, out / "diag_hybrid", True
        ),
        "hybrid-sov (causal, reported)": diagnose(
            "hybrid-sov", cycles_ds, fail_ds, out / "diag_hybrid_causal", True, causal=True
        ),
        "residual": diagnose("residual", cycles_ds, fail_ds, out / "diag_residual", False),
    }
    stage3 = {
        k: {
            "selected": m[k].stage3_.stage3.selected,
            "test": m[k].stage3_.stage3.test,
            "iterations": m[k].stage3_.iterations,
        }
        for k in ("hybrid_tobit", "oracle_tobit", "hybrid_ols", "oracle_ols")
    }
    cens = censored_study(startup_ds, st, m["hybrid_tobit"]) if startup_ds else None
    rob = None if args.quick else robustness(cycles_ds, st)
    figures(
        out,
        m,
        val,
        train,
        failure_profiles(m["hybrid_tobit"], fail_ds, st),
        normal_profiles(m["hybrid_tobit"], val),
        wh,
    )

    r = t23.set_index("model")
    A = []

    def check(name, value, threshold, ok, quick=True):
        # --quick (CI) asserts what the full study reproduces; the checks the full study
        # fails (quick=False) it reports in parentheses: CI guards against regressions, the
        # full study's report says what is not reproduced (EXPECTED_FAILURES: XFAIL)
        result = verdict(name, bool(ok), not (args.quick and not quick), EXPECTED_FAILURES)
        A.append({"assertion": name, "measured": value, "threshold": threshold, "result": result})

    for w in ("tension", "pitch"):
        for fam in ("censored", "linear") if w == "tension" else ("linear",):
            pt, lo, hi = boot[(w, fam)]
            check(
                f"{w}: validation RMSE hybrid < data-driven ({fam}) by >= 5 %, bootstrap "
                f"95 % CI over cycles excludes 0",
                f"{100 * pt:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]",
                ">= 5 %, lo > 0",
                pt >= 0.05 and lo > 0,
            )
    for fam, h, d in (
        ("censored", "physics + censored", "data-driven censored"),
        ("linear", "physics + linear", "data-driven linear"),
    ):
        tr_h, tr_d = r.loc[h, "tension_train_N"], r.loc[d, "tension_train_N"]
        va_h, va_d = r.loc[h, "tension_val_N"], r.loc[d, "tension_val_N"]
        check(
            f"tension ({fam}): data-driven train RMSE <= 1.05 x hybrid and validation "
            f"RMSE higher (overfitting)",
            f"train {tr_d:.3f} vs {tr_h:.3f} N; val {va_d:.3f} vs {va_h:.3f} N",
            "dd_train <= 1.05 hy_train, dd_val > hy_val",
            tr_d <= 1.05 * tr_h and va_d > va_h,
        )
    tr_h, tr_d = (
        r.loc["physics + linear", "pitch_train_um"],
        r.loc["data-driven linear", "pitch_train_um"],
    )
    va_h, va_d = (
        r.loc["physics + linear", "pitch_val_um"],
        r.loc["data-driven linear", "pitch_val_um"],
    )
    check(
        "pitch (linear): data-driven train RMSE <= 1.05 x hybrid and validation higher",
        f"train {tr_d:.3f} vs {tr_h:.3f} um; val {va_d:.3f} vs {va_h:.3f} um",
        "dd_train <= 1.05 hy_train, dd_val > hy_val",
        tr_d <= 1.05 * tr_h and va_d > va_h,
    )
    a_h, a_d = (
        r.loc["physics + censored", "tension_aic"],
        r.loc["data-driven censored", "tension_aic"],
    )
    check(
        "tension AIC hybrid < data-driven (Tobit likelihoods)",
        f"{a_h:.0f} vs {a_d:.0f}",
        "hybrid < data-driven",
        a_h < a_d,
        quick=False,
    )
    a_h, a_d = r.loc["physics + linear", "pitch_aic"], r.loc["data-driven linear", "pitch_aic"]
    check(
        "pitch AIC hybrid < data-driven (Gaussian likelihoods)",
        f"{a_h:.0f} vs {a_d:.0f}",
        "hybrid < data-driven",
        a_h < a_d,
        quick=False,
    )
    for row in t24.itertuples():
        check(
            f"{row.output}: transient RMSE >= 1.5 x steady RMSE (hybrid, validation)",
            f"{row.transient:.3g} vs {row.steady:.3g} {row.unit} "
            f"({row.transient / row.steady:.2f}x)",
            ">= 1.5x",
            row.transient >= 1.5 * row.steady,
            quick=row.output == "tension",
        )
    sel = stage3["hybrid_tobit"]["selected"]
    check(
        "stepwise keeps the dancer angle in the dancer stage (alternating fit)",
        ", ".join(sel) or "(none)",
        "alpha selected",
        "alpha" in sel,
        quick=False,
    )
    check(
        "virtual sensor's pre-changeover climb slope >= 50 % of the true slope",
        f"{100 * climb_ratio:.0f} % ({len(climbs)} fills)",
        ">= 50 %",
        climb_ratio >= 0.5,
    )
    dh, dr = diag["hybrid-sov (offline)"], diag["residual"]
    check(
        "r2rsim diagnose --method hybrid-sov (offline): P_D = 1 on the dancer-failure runs",
        f"{dh['pd']:.2f}",
        "= 1",
        dh["pd"] == 1.0,
    )
    check(
        "detection delay hybrid-sov (offline) <= residual baseline (median)",
        f"{dh['dd_median_s']:.2f} s vs {dr['dd_median_s']:.2f} s",
        "<=",
        dh["dd_median_s"] <= dr["dd_median_s"],
    )
    ta = pd.DataFrame(A)

    t23.to_csv(out / "table_2_3.csv", index=False)
    t24.to_csv(out / "table_2_4.csv", index=False)
    t25.to_csv(out / "table_2_5.csv", index=False)
    (out / "assertions.json").write_text(
        json.dumps(
            {
                "assertions": A,
                "stage3": stage3,
                "diagnose": diag,
                "climb_ratio": climb_ratio,
                "bootstrap": {f"{w}/{f}": v for (w, f), v in boot.items()},
                "censored_startup": cens,
            },
            indent=2,
            default=str,
        )
    )
    if rob is not None:
        rob.to_csv(out / "robustness.csv", index=False)
    write_report(
        out,
        args,
        t23,
        t24,
        t25,
        ta,
        stage3,
        climbs,
        diag,
        cens,
        m,
        time.perf_counter() - t0,
        cycles_ds,
        fail_ds,
        rob,
        train,
    )
    print(ta.to_string(index=False))
    print("\n" + summary(ta["assertion"], ta["result"], EXPECTED_FAILURES))
    print(f"report: {out / 'report.md'}")
    return exit_status(ta["result"])


def notes(t23: pd.DataFrame, train) -> list[str]:
    """Measured facts that explain the tables (numbers from this run)."""
    r = t23.set_index("model")
    h, d = r.loc["physics + censored"], r.loc["data-driven linear"]
    n_cens = int(sum(int(np.sum(c.sig.censored)) for c in train))
    return [
        f"* Censored load-cell samples in the training cycles: {n_cens}. Without censoring "
        "the Tobit fit equals OLS, so the censored and linear rows coincide.",
        f"* Validation at the training speed (other rolls): tension hybrid "
        f"{h['tension_val_same_speed_N']:.3f} N, data-driven "
        f"{d['tension_val_same_speed_N']:.3f} N; pitch hybrid "
        f"{h['pitch_val_same_speed_um']:.2f} µm, data-driven "
        f"{d['pitch_val_same_speed_um']:.2f} µm. At the other speed (the asserted split): "
        f"tension {h['tension_val_N']:.3f} against {d['tension_val_N']:.3f} N, pitch "
        f"{h['pitch_val_um']:.2f} against {d['pitch_val_um']:.4g} µm: the quadratic "
        "data-driven model extrapolates badly in speed, while the physics regressors carry "
        "over.",
        "* The test bed's rolls each have their own relaxed pitch (4 µm std, "
        "scenarios/thesis_realistic/testbed.yaml): L0(R) = q0 + q1·R³ cannot know it, so "
        "the hybrid pitch error is a per-roll offset more than a transient error, and the "
        "pitch-derived stage-3 target carries per-roll offsets of about 4.5 N.",
        "* AIC is computed on the training samples (tens of thousands of autocorrelated "
        "samples): it rewards the better in-sample fit.",
    ]


def write_report(
    out,
    args,
    t23,
    t24,
    t25,
    ta,
    stage3,
    climbs,
    diag,
    cens,
    m,
    wall,
    cycles_ds,
    fail_ds,
    rob=None,
    train=(),
):
    th23 = pd.DataFrame(
        [
            {
                "model": k,
                "tension_train": v[0],
                "tension_val": v[1],
                "tension_aic": v[2],
                "pitch_train": v[3],
                "pitch_val": v[4],
                "pitch_aic": v[5],
            }
            for k, v in THESIS_23.items()
        ]
    )
    t24t = t24.copy()
    t24t["thesis steady / transient / one cycle"] = [
        " / ".join(f"{x:g}" for x in THESIS_24[o]) for o in t24["output"]
    ]
    t25t = t25.copy()
    t25t["thesis LB p / ARCH p"] = [
        " / ".join(f"{x:g}" for x in THESIS_25[o]) for o in t25["output"]
    ]
    s12 = m["hybrid_tobit"].stage12_
    lines = [
        "# Reproduction of Shui (2018) Ch. 2: hybrid multistage tension model and virtual "
        "sensor (`hybrid-sov`)",
        "",
        f"Generated by `python benchmarks/reproduction/ch2_hybrid_sov.py {args.command}` "
        f"in {wall:.0f} s. Data: `{cycles_ds.name}` "
        f"(scenarios/thesis_realistic/testbed_cycles.yaml), `{fail_ds.name}` (dancer "
        "failures, testbed_dancer_failure.yaml); line `lines/thesis_testbed_realistic.yaml`.",
        "",
        f"Training: the first {N_TRAIN} complete cycles (roll swap to roll swap) of the "
        f"0.5 m/s run of seed 1. Validation: the first {N_VAL} complete cycles of the 0.6 m/s "
        "run of seed 2 (other rolls, other friction, other speed; the split docs/dataset.md "
        f"§8.2 documents). Second validation (reported only): cycles {N_TRAIN + 1}-"
        f"{N_TRAIN + N_VAL} of the training run (same speed, other rolls). Units: N and µm "
        "(the thesis's numbers are normalised: compare ratios and directions only).",
        "",
        "**The study runs hybrid-sov's offline variant** (`causal=False`: centred "
        "Savitzky–Golay smoothing and differentiation, as in the thesis). The thesis's "
        "analysis is offline, and the comparisons with the true tensions (the T_s3 RMSE, "
        "the pre-changeover climb, the roll-change windows) need estimates that refer to "
        "their own sample; the plug-in's default causal filter reads no later sample, and "
        "its estimates refer to half a smoothing window earlier. The default's "
        "dancer-failure detection is reported beside the asserted offline one "
        "(`hybrid-sov (causal, reported)`), not asserted.",
        "",
        "## Assertions",
        "",
        md_table(ta),
        "",
        report_note(ta["result"], EXPECTED_FAILURES),
        "",
        "## Reading the results",
        "",
        *notes(t23, train),
        "",
        "## Table 2-3 analogue (RMSE; tension = the stage-2 load cell, T_s2)",
        "",
        md_table(t23),
        "",
        "Thesis Table 2-3 (normalised):",
        "",
        md_table(th23),
        "",
        "## Table 2-4 analogue (hybrid, censored; validation cycles; RMSE)",
        "",
        "Transient = from the start of the fill to the completed splice of each roll change.",
        "",
        md_table(t24t),
        "",
        "## Table 2-5 analogue (residual tests, reported, not asserted)",
        "",
        "Residuals of the validation cycles decimated per cycle to their decorrelation time "
        "(first lag with autocorrelation < 1/e); Ljung-Box with 10 lags, ARCH LM with 5.",
        "",
        md_table(t25t),
        "",
        "## Model selection",
        "",
        f"Stage 1-2 (Tobit, {s12.test} tests): forced `const, tau1/R, J1*dw1/R`; selected "
        f"`{', '.join(s12.selected) or '(none)'}`.",
        "",
        "Stage 3 (dancer), candidates `idlers3, alpha, dalpha, w_d, dw_d, w1, dw1` after the "
        "forced `const, T2`:",
        "",
        md_table(
            pd.DataFrame(
                [
                    {
                        "fit": k,
                        "selected": ", ".join(v["selected"]) or "(none)",
                        "test": v["test"],
                        "alternating iterations": v["iterations"],
                    }
                    for k, v in stage3.items()
                ]
            )
        ),
        "",
        f"Data-driven tension (Tobit): {len(m['dd_tobit'].tension_.selected)} terms selected "
        f"of {len(m['dd_tobit'].design_t_.center)}; pitch (OLS): "
        f"{len(m['dd_ols'].pitch_.selected)} of {len(m['dd_ols'].design_p_.center)}.",
        "",
        "## Pre-changeover climb (validation fills)",
        "",
        md_table(climbs),
        "",
        "## Dancer failure (`r2rsim diagnose`, trained on the healthy cycle runs)",
        "",
        md_table(pd.DataFrame([{"method": k, **v} for k, v in diag.items()])),
        "",
        "hybrid-sov ran with `--drive-data` (it needs the torques), offline "
        "(`--param causal=false`) for the assertions and with its causal default for the "
        "reported row; the residual baseline on the default visible channels. Every method "
        "ran with `--detection-window inf`: the seized dancer shows only at the next roll "
        "change, about 27 s after the seizure, beyond the default 20 s window.",
        "",
    ]
    if rob is not None:
        lines += [
            "## Robustness over seeds (reported, not asserted)",
            "",
            f"Training on the first {N_TRAIN} cycles at 0.5 m/s of one seed, validating "
            f"on the first {N_VAL} cycles of another seed at 0.6 m/s or at 0.5 m/s; "
            "Tobit tension models, OLS pitch models; pooled RMSE.",
            "",
            md_table(rob),
            "",
        ]
    if cens is not None:
        lines += [
            "## Censored data (start-up run)",
            "",
            f"{100 * cens['censored_share']:.1f} % of the load-cell samples are censored "
            f"(reading 0 N). Stage 1-2 selected by Tobit: "
            f"`{', '.join(cens['tobit_selected'])}`; by OLS: "
            f"`{', '.join(cens['ols_selected'])}`. Mean T̂_s2 on the censored samples: "
            f"Tobit latent mean {cens['tobit_mean_on_censored_N']:.1f} N, OLS "
            f"{cens['ols_mean_on_censored_N']:.1f} N (true span tension "
            f"{cens['true_mean_on_censored_N']:.1f} N).",
            "",
            f"Defect classes {cens.get('classes')}: multinomial logistic regression on "
            f"(T̂_s2, α), in-sample accuracy "
            f"{cens.get('classifier_accuracy_in_sample', float('nan')):.3f} (one run: "
            "no held-out data; the cycle runs have no slack or over-stretch samples).",
            "",
        ]
    else:
        lines += ["## Censored data", "", "Skipped (--quick): no start-up run.", ""]
    lines += [
        "## Figures",
        "",
        "![Fig 2-13](fig_2_13_virtual_sensor.png)",
        "",
        "![Fig 2-14](fig_2_14_qq.png)",
        "",
        "![Fig 2-15](fig_2_15_profiles.png)",
        "",
    ]
    (out / "report.md").write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
