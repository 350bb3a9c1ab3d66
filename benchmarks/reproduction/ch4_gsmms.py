"""Reproduction study of thesis Ch. 4 (GSMMS: a growing self-organising map with local parity
relations fitted by mini-batch SGD) on the calibrated registration data of
``scenarios/thesis_realistic/`` (docs/dataset.md §8.2).

    python benchmarks/reproduction/ch4_gsmms.py --data /work/data -o results/ch4
    python benchmarks/reproduction/ch4_gsmms.py --quick -o "$(mktemp -d)"

``--data DIR`` reuses simulated sweep datasets (``DIR/healthy``, ``DIR/faults`` and, if
present, ``DIR/switching``, made by ``r2rsim sweep scenarios/thesis_realistic/<name>.yaml``);
without it the script simulates what it needs into ``OUT/data`` (``--quick``: a few short
runs). Seeds: healthy 1-10 train, 11-15 calibrate the per-node statistics, 16-20 test; fault
seeds 101-105 are test only (the quick version scales these down). It writes
``OUT/report.md`` with its tables and figures and prints a PASS/FAIL table. Exit status, as
the other reproduction studies: 0 when every asserted check passes or is one of the study's
documented non-reproductions (``EXPECTED_FAILURES``: printed as XFAIL (documented), with its
reason); 3 when a check the committed report passes fails, or a listed one unexpectedly
passes (XPASS; see _expected.py); 1 is an error, 2 a usage error.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _expected.py, beside this file
from _expected import ASSERTION_FAILED, exit_status, report_note, summary, verdict  # noqa: E402, F401

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "scenarios" / "thesis_realistic" / "registration.yaml"
_SAME = (
    "both conditions run the same product, so one A-B relation fits OC1 and OC2 alike and "
    "the global model is not worse (the thesis's gap appears with a second product; "
    "report: Why the global model is not worse here)"
)
#: the checks the committed full report (docs/reproduction/gsmms/report.md) fails: the
#: documented non-reproductions, each with its reason. They are XFAIL (documented), not a
#: failure: the exit status is 0 unless another check fails or one of these passes (XPASS)
EXPECTED_FAILURES = {
    "global worse in some condition": _SAME,
    "four-cell mean GSMMS − global": _SAME,
    "OC3 (held out) streamed: node added": (
        "OC3 lies between OC1 and OC2 with the same A-B relation: it joins an existing node, "
        "re-fitted to fit it (the FAR check passes; report: Why OC3 adds no node)"
    ),
}
A = "meas.sensor_A.tension_N"
B = "meas.sensor_B.pitch_m"
KEEP = (
    "k",
    "t_s",
    "meas.",
    "sp.",
    "label.is_faulty",
    "label.severity",
    "label.score_mask",
    "label.mode",
)
CONDITIONS = {"OC1": (0.5, 130.0), "OC2": (1.0, 160.0), "OC3": (0.75, 145.0)}
MAGNITUDES = (0.05, 0.10, 0.15, 0.20)
#: the GSMMS configuration of the study, pinned (not the plug-in's defaults): the thesis's
#: A-B parity with one relation per node, fault-normalised on sensor A (docs/diagnostics.md
#: §11), partition on the set-points; the analogue of thesis Table 4-2, which scores only
#: sensor-A faults
STUDY = dict(model_features=[A, B], fault_channels=A, partition_features=["sp.*"], random_state=0)
#: the thesis-literal design: one unit-norm minimum-variance relation (eq. 4.21)
LITERAL = dict(
    model_features=[A, B], fault_channels=None, partition_features=["sp.*"], random_state=0
)
#: the plug-in's default configuration (a fault-normalised relation for every channel
#: meas.*, partition on sp.*), compared with STUDY on sensor-A and sensor-B faults
DEFAULT = dict(random_state=0)
#: the harness settings of that comparison (docs/diagnostics.md §5.1)
HARNESS = dict(alpha=0.01, m=3, n_boot=0)
#: fault groups of the comparison: (label, case prefix of faults.yaml, record-only?)
GROUPS = (
    ("A offset", "A offset", False),
    ("A degradation", "A degradation", False),
    ("A drift", "A drift", False),
    ("B gain in loop", "B gain", False),
    ("B gain record-only", "B gain", True),
)


@dataclass
class Plan:
    """Which seeds play which part, and how the degradation faults ramp."""

    train: tuple
    calibrate: tuple
    test: tuple
    fault_seeds: tuple
    ramp_s: float
    quick: bool


FULL = Plan(
    tuple(range(1, 11)),
    tuple(range(11, 16)),
    tuple(range(16, 21)),
    tuple(range(101, 106)),
    120.0,
    False,
)
QUICK = Plan((1, 2), (3,), (4, 5), (101,), 20.0, True)


# ------------------------------------------------------------------------------ data
def _yaml_sweeps(plan: Plan, duration_s: float) -> dict[str, dict]:
    """The sweep specifications of the quick version (the full one uses the shipped sweeps)."""
    modes = list(CONDITIONS)
    healthy = {
        "name": "gsmms_quick_healthy",
        "scenario": str(SCENARIO),
        "set": {"duration": f"{duration_s} s"},
        "combine": "zip",
        "axes": [
            {"name": "mode", "path": "programme[0].mode", "values": modes},
            {
                "name": "speed",
                "path": "programme[0].line_speed",
                "values": [f"{CONDITIONS[m][0]} m/s" for m in modes],
            },
            {
                "name": "tension",
                "path": "programme[0].tension.registration_loop",
                "values": [f"{CONDITIONS[m][1]} N" for m in modes],
            },
            {
                "name": "unwind_tension",
                "path": "programme[0].tension.unwind_tension",
                "values": [f"{CONDITIONS[m][1]} N" for m in modes],
            },
        ],
        "seeds": list(plan.train + plan.calibrate + plan.test),
    }
    cells = [(m, g) for m in ("OC1", "OC2") for g in MAGNITUDES]
    fault = {
        "id": "sensor_fault",
        "type": "sensor.gain",
        "target": "sensor_A",
        "onset": "30 s",
        "magnitude": 0.05,
        "profile": {"shape": "ramp", "ramp": f"{plan.ramp_s} s"},
    }
    faults = {
        "name": "gsmms_quick_faults",
        "scenario": str(SCENARIO),
        "set": {"duration": f"{duration_s} s", "faults": [fault]},
        "combine": "zip",
        "axes": [
            {
                "name": "case",
                "path": "description",
                "values": [
                    f"A degradation P{round(g * 100):02d} over {plan.ramp_s:g} s {m}"
                    for m, g in cells
                ],
            },
            {"name": "mode", "path": "programme[0].mode", "values": [m for m, _ in cells]},
            {
                "name": "speed",
                "path": "programme[0].line_speed",
                "values": [f"{CONDITIONS[m][0]} m/s" for m, _ in cells],
            },
            {
                "name": "tension",
                "path": "programme[0].tension.registration_loop",
                "values": [f"{CONDITIONS[m][1]} N" for m, _ in cells],
            },
            {
                "name": "unwind_tension",
                "path": "programme[0].tension.unwind_tension",
                "values": [f"{CONDITIONS[m][1]} N" for m, _ in cells],
            },
            {
                "name": "magnitude",
                "path": "faults.sensor_fault.magnitude",
                "values": [g for _, g in cells],
            },
        ],
        "seeds": list(plan.fault_seeds),
    }
    return {"healthy": healthy, "faults": faults}


def simulate(out: Path, plan: Plan, workers: int) -> Path:
    """Simulate the quick version's datasets into ``out/data``; returns that directory."""
    import yaml

    from r2rsim.sweep import run_sweep

    root = out / "data"
    root.mkdir(parents=True, exist_ok=True)
    for name, spec in _yaml_sweeps(plan, 100.0).items():
        path = root / f"{name}.yaml"
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        run_sweep(path, root / name, workers=workers)
    return root


def load(path: Path, where: dict) -> list:
    """Runs of a dataset, their samples cut to what the study reads (memory: 40+ runs)."""
    from r2rsim.dataset.read import read_runs

    runs = read_runs(path, where=where)
    for r in runs:
        r.samples = r.samples[[c for c in r.samples.columns if c.startswith(KEEP)]]
    return runs


@dataclass
class Data:
    healthy: dict = field(default_factory=dict)  # (mode, part) -> runs
    faults: dict = field(default_factory=dict)  # (mode, magnitude) -> runs
    switching: list = field(default_factory=list)


def read_data(root: Path, plan: Plan) -> Data:
    d = Data()
    for mode in CONDITIONS:
        for part in ("train", "calibrate", "test"):
            d.healthy[mode, part] = load(
                root / "healthy", {"mode": mode, "seed": list(getattr(plan, part))}
            )
    cases = [
        f"A degradation P{round(g * 100):02d} over {plan.ramp_s:g} s {m}"
        for m in ("OC1", "OC2")
        for g in MAGNITUDES
    ]
    for r in load(root / "faults", {"case": cases, "seed": list(plan.fault_seeds)}):
        m = re.match(r"A degradation P(\d\d) over [\d.]+ s (OC\d)", r.info["axis.case"])
        d.faults.setdefault((m.group(2), int(m.group(1)) / 100), []).append(r)
    if (root / "switching").is_dir():
        d.switching = load(root / "switching", {})
    if not plan.quick:  # the second product of the healthy sweep (not in the quick data)
        for part in ("train", "calibrate", "test"):
            d.healthy["P2", part] = load(
                root / "healthy", {"mode": "P2", "seed": list(getattr(plan, part))}
            )
    return d


# ------------------------------------------------------------------------------ metrics
def alarms(est, run) -> np.ndarray:
    return est.decide(est.score(run)).to_numpy(bool)


def far(est, runs) -> float:
    """False-alarm rate over the scored samples of healthy runs."""
    hits = [alarms(est, r)[r.samples["label.score_mask"].to_numpy(bool)] for r in runs]
    return float(np.mean(np.concatenate(hits)))


def steady(run) -> np.ndarray:
    return (run.samples["label.severity"].to_numpy() >= 1.0) & run.samples[
        "label.score_mask"
    ].to_numpy(bool)


def dr_steady(est, runs) -> float:
    """Detection rate over the samples where the fault is at full size (thesis 'power')."""
    return float(np.mean(np.concatenate([alarms(est, r)[steady(r)] for r in runs])))


def mean_abs_z(est, runs) -> float:
    return float(
        np.nanmean(np.concatenate([est.score(r)["statistic"].to_numpy()[steady(r)] for r in runs]))
    )


def node_purity(est, runs_by_mode: dict) -> dict:
    """Per condition, the share of its samples in the nodes it owns (a node belongs to the
    condition that gives it most samples)."""
    counts = {
        m: np.bincount(
            np.concatenate(
                [
                    est.score(r)["bmu"].to_numpy()[r.samples["label.score_mask"].to_numpy(bool)]
                    for r in runs
                ]
            )
            + 1,
            minlength=est.n_nodes_ + 1,
        )[1:]
        for m, runs in runs_by_mode.items()
    }
    table = pd.DataFrame(counts)  # nodes x conditions
    owner = table.idxmax(axis=1)
    return {m: float(table.loc[owner == m, m].sum() / table[m].sum()) for m in table}


def four_cell(row: dict) -> float:
    return float(np.mean([1 - row["far_OC1"], 1 - row["far_OC2"], row["dr_OC1"], row["dr_OC2"]]))


def fitted(cls, params, data: Data, modes=("OC1", "OC2"), calibrate=True):
    est = cls(**params).fit([r for m in modes for r in data.healthy[m, "train"]])
    if calibrate:
        est.calibrate([r for m in modes for r in data.healthy[m, "calibrate"]])
    return est


def detection_row(name, est, data: Data) -> dict:
    row = {"model": name, "nodes": est.n_nodes_}
    for m in ("OC1", "OC2"):
        row[f"far_{m}"] = far(est, data.healthy[m, "test"])
        row[f"dr_{m}"] = dr_steady(est, data.faults[m, 0.20])
    row["four_cell"] = four_cell(row)
    return row


def solver_comparison(est, data: Data) -> pd.DataFrame:
    """Table 4-1 analogue: each node's relation refitted on the fixed final partition by
    batch GD, single-sample SGD and mini-batch SGD (and the exact oracle), timed side by
    side in this process; RMSE of the parity residuals in N of sensor A."""
    from r2rsim.diagnostics.gsmms import fit_relations

    S, Z = est.training_arrays([r for m in ("OC1", "OC2") for r in data.healthy[m, "train"]])
    bmu = est.graph_.bmu(S)
    F = est._fault_directions()
    scale_a = est.z_scale_[est.model_columns_.index(A)]
    rows = []
    for solver in ("batch", "sgd", "minibatch", "eigh"):
        res, seconds = np.empty(len(Z)), 0.0
        for m in np.unique(bmu):
            sel = bmu == m
            t0 = time.perf_counter()
            om, b = fit_relations(
                Z[sel], np.ones(sel.sum()), F=F, solver=solver, rng=np.random.default_rng(0)
            )
            seconds += time.perf_counter() - t0
            res[sel] = (Z[sel] @ om + b)[:, 0]
        rows.append(
            {
                "solver": solver,
                "time_s": seconds,
                "rmse_N": float(np.sqrt(np.mean(res**2))) * scale_a,
                "samples": int(len(Z)),
            }
        )
    return pd.DataFrame(rows).set_index("solver")


def relations(models: dict) -> pd.DataFrame:
    """Each node's relation as a slope c of A on B [N/µm] and its residual σ [N]."""
    rows = []
    for name, est in models.items():
        ia, ib = est.model_columns_.index(A), est.model_columns_.index(B)
        for m, om in enumerate(est.models_.omega):
            w = om[:, 0] / est.z_scale_  # the relation in physical units
            rows.append(
                {
                    "model": name,
                    "node": m,
                    "c_N_per_um": -w[ib] / w[ia] * 1e-6,
                    "residual_sigma_N": float(est.node_std_[m, 0]) / abs(w[ia]),
                    "statistics_samples": int(est.node_count_[m]),
                }
            )
    return pd.DataFrame(rows).set_index("model")


def product_section(data: Data) -> list[str]:
    """OC1, OC2 and the second product P2 (same set-points as OC1, a stiffer web and another
    printed pitch, so another A-B relation) in training: GSMMS against the global model."""
    from r2rsim.diagnostics.gsmms import GSMMS, GlobalParity

    modes = ("OC1", "OC2", "P2")
    # P2 shares OC1's set-points: sensor B's pitch level (0.25 m against 0.30 m) is the only
    # visible sign of the product, so it joins the partition here
    params = {**STUDY, "partition_features": ["sp.*", B]}
    rows, models = [], {}
    for name, cls in (("GSMMS", GSMMS), ("global (one node)", GlobalParity)):
        est = fitted(cls, params, data, modes=modes)
        models[name] = est
        row = detection_row(name, est, data)
        row["far_P2"] = far(est, data.healthy["P2", "test"])
        rows.append(row)
    s, g = rows
    purity = node_purity(models["GSMMS"], {m: data.healthy[m, "test"] for m in modes})
    return [
        "## A second product in training (beyond the issue's setting)",
        "",
        "The same study with the healthy runs of product P2 (PET 75 µm, L0 = 0.30 m, at "
        "OC1's set-points) added to training, calibration and test; partition on `sp.*` and "
        "sensor B's pitch (the only visible sign of the product). The P20 faults are OC1's "
        "and OC2's as above (there are no P2 fault runs in the data). Not asserted:",
        "",
        md_table(pd.DataFrame(rows).set_index("model"), ".4f"),
        "",
        f"GSMMS has {models['GSMMS'].n_nodes_} nodes; share of each condition's test samples "
        "in its own node(s): "
        + ", ".join(f"{m} {p:.2f}" for m, p in purity.items())
        + " (a condition that shares a node with a larger one counts 0).",
        "",
        md_table(relations(models), ".4g"),
        "",
        f"Four-cell mean GSMMS − global: {s['four_cell'] - g['four_cell']:+.3f}; detection "
        f"rate of P20 in OC1 {s['dr_OC1']:.3f} against {g['dr_OC1']:.3f}. A single relation "
        "cannot cancel both the change of set-point and the change of product, so the "
        "global residual spreads and loses its power in OC1: the Table 4-2 pattern, for "
        "the reason the thesis gives (regimes whose relations differ).",
        "",
    ]


def _group(run) -> str | None:
    """The GROUPS label of a run of faults.yaml ("fault-free" for the fault-free cases)."""
    case = str(run.info.get("axis.case"))
    if case.startswith("fault-free"):
        return "fault-free"
    record_only = "record-only" in case
    return next(
        (g for g, prefix, rec in GROUPS if case.startswith(prefix) and rec == record_only), None
    )


def configuration_section(root: Path, data: Data, plan: Plan) -> list[str]:
    """P_D and pd_null (harness, docs/diagnostics.md §5.1) of sensor-A and sensor-B faults
    in OC1 and OC2 for the study's configuration and the plug-in's default: trained on the
    healthy training seeds of both, threshold recalibrated on the calibration seeds at
    alpha 0.01, persistence 3, tested on the healthy test seeds and every fault case."""
    from r2rsim.diagnostics.gsmms import GSMMS
    from r2rsim.evaluate.harness import evaluate, fault_key

    faults = load(root / "faults", {"mode": ["OC1", "OC2"], "seed": list(plan.fault_seeds)})
    by_group: dict = {}
    for r in faults:
        by_group.setdefault(_group(r), []).append(r)
    if "fault-free" not in by_group or not all(g in by_group for g, _, _ in GROUPS):
        return []
    part = {
        p: [r for m in ("OC1", "OC2") for r in data.healthy[m, p]]
        for p in ("train", "calibrate", "test")
    }
    # in-loop and record-only B gains share the harness's stratum (sensor.gain:sensor_B):
    # the record-only runs are scored in a second evaluation (same fit, same null runs)
    sets = {
        False: [r for g, rs in by_group.items() if "record-only" not in str(g) for r in rs],
        True: by_group["fault-free"] + by_group["B gain record-only"],
    }
    configs = {"study (A-normalised, [A, B])": STUDY, "default (all channels, meas.*)": DEFAULT}
    rows = {}
    for name, params in configs.items():
        for record_only, test in sets.items():
            ev = evaluate(
                GSMMS(**params), part["train"], part["test"] + test, part["calibrate"], **HARNESS
            )
            t = ev.metrics[ev.metrics["magnitude"].isna()].set_index(
                ["condition", "fault", "metric"]
            )["value"]
            for g, _, rec in GROUPS:
                if rec != record_only:
                    continue
                fault = fault_key(by_group[g][0])
                for m in ("OC1", "OC2"):
                    rows.setdefault(g, {})[f"{name}, {m}"] = (
                        f"{t[m, fault, 'pd']:.2f} / {t[m, fault, 'pd_null']:.2f}"
                    )
    table = pd.DataFrame(rows).T
    table.index.name = "faults (P_D / pd_null)"
    return [
        "## Sensor A and sensor B faults in both configurations (harness; reported, not asserted)",
        "",
        "P_D and its null rate `pd_null` (docs/diagnostics.md §5.1: a fault counts as "
        "detected within 20 s of being fully developed; `pd_null` is the same rule at "
        "pretend onsets on the fault-free runs) of every sensor-A and sensor-B case of "
        "`faults.yaml` (all magnitudes pooled), through `r2rsim.evaluate.harness.evaluate`: "
        f"trained on healthy OC1 + OC2 seeds {plan.train[0]}-{plan.train[-1]}, the "
        f"plug-in's threshold recalibrated on seeds {plan.calibrate[0]}-"
        f"{plan.calibrate[-1]} at alpha {HARNESS['alpha']}, persistence {HARNESS['m']}; "
        f"tested on healthy seeds {plan.test[0]}-{plan.test[-1]} and fault seeds "
        f"{plan.fault_seeds[0]}-{plan.fault_seeds[-1]} (the fault-free cases of "
        "`faults.yaml` among the null runs).",
        "",
        md_table(table),
        "",
        "The study's configuration (one relation per node, fault-normalised on sensor A) is "
        "built for the faults of Table 4-2, sensor A's, and is nearly blind to a sensor-B "
        "gain that only changes B's record. The plug-in's default (`fault_channels: all`: "
        "a relation per channel with unit response to that channel's fault, over every "
        "`meas.*` channel) sees the faults of both sensors, at a higher null rate: it also "
        "watches B's pitch and the encoder speeds, whose level differs from plant to plant "
        "more than five calibration runs per regime show.",
        "",
    ]


def adaptation(data: Data) -> pd.DataFrame:
    """Fit on OC1 only, then stream OC2's training runs and then OC3's through partial_fit
    (two runs at a time); FAR on each condition's test runs after every stage."""
    from r2rsim.diagnostics.gsmms import GSMMS

    est = GSMMS(**STUDY).fit(data.healthy["OC1", "train"])
    rows = []

    def record(stage):
        row = {"stage": stage, "nodes": est.n_nodes_}
        for m in CONDITIONS:
            row[f"far_{m}"] = far(est, data.healthy[m, "test"])
        rows.append(row)

    record("fit on OC1")
    for new in ("OC2", "OC3"):
        runs = data.healthy[new, "train"]
        for i in range(0, len(runs), 2):
            est.partial_fit(runs[i : i + 2])
        record(f"+ stream {new}")
    return pd.DataFrame(rows).set_index("stage"), est.history_


def switching_table(est, runs) -> pd.DataFrame:
    """Within-run regime change OC1 -> OC2: how often the BMU is the node of the labelled
    mode (outside the 20 s ramp), the FAR of healthy runs and the detection rate of the A
    degradation at full size."""
    owner = {}
    rows = []
    for r in runs:
        s = est.score(r)
        t = r.samples["t_s"].to_numpy()
        mode = r.samples["label.mode"].astype(str).to_numpy()
        settled = (t < 100.0) | (t >= 121.0)
        for m in ("OC1", "OC2"):
            sel = settled & (mode == m)
            owner.setdefault(m, int(np.bincount(s["bmu"].to_numpy()[sel] + 1).argmax() - 1))
        follows = np.mean(
            [s["bmu"].to_numpy()[i] == owner[mode[i]] for i in np.flatnonzero(settled)]
        )
        a = est.decide(s).to_numpy(bool)
        scored = r.samples["label.score_mask"].to_numpy(bool)
        healthy = ~r.samples["label.is_faulty"].to_numpy(bool) & scored
        rows.append(
            {
                "run": r.run_id.split("__")[-1] + (" fault" if len(r.faults) else ""),
                "bmu_follows_mode": float(follows),
                "far_healthy_part": float(a[healthy].mean()),
                "far_in_ramp": float(a[healthy & ~settled].mean()),
                "dr_full_size": float(a[steady(r)].mean()) if steady(r).any() else np.nan,
            }
        )
    return pd.DataFrame(rows).set_index("run")


# ------------------------------------------------------------------------------ report
def md_table(df: pd.DataFrame, fmt: str = ".4f") -> str:
    """A Markdown table of a frame (index first), numbers formatted with ``fmt``."""

    def cell(v):
        if isinstance(v, (float, np.floating)):
            return "–" if np.isnan(v) else format(v, fmt)
        return str(v)

    head = [str(df.index.name or "")] + [str(c) for c in df.columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += [
        "| " + " | ".join([str(i)] + [cell(v) for v in row]) + " |"
        for i, row in zip(df.index, df.itertuples(index=False), strict=True)
    ]
    return "\n".join(lines)


@dataclass
class Check:
    name: str
    threshold: str
    measured: str
    ok: bool
    asserted: bool = True

    @property
    def result(self) -> str:
        return verdict(self.name, bool(self.ok), self.asserted, EXPECTED_FAILURES)


#: the checks the quick version asserts; the others need the full set of runs (a node's
#: residual spread between runs cannot be estimated from one calibration run, and timings
#: of a few thousand samples say nothing), so --quick reports them without asserting
QUICK_ASSERTED = (
    "regimes: nodes",
    "regimes: purity per condition",
    "dr P20 steady state",
    "severity monotone",
    "solver RMSEs agree",
    "OC2 streamed: node added",
)


def save(fig, path: Path):
    fig.savefig(path, dpi=80)


def study(root: Path, out: Path, plan: Plan) -> list[Check]:
    from r2rsim.diagnostics.gsmms import GSMMS, GlobalParity
    from r2rsim.report import plot_gsmms_map, plot_gsmms_residuals, plot_severity

    t_start = time.perf_counter()
    data = read_data(root, plan)
    md = [
        f"# Thesis Ch. 4 (GSMMS) on the calibrated registration data"
        f"{' (quick version)' if plan.quick else ''}",
        "",
        f"Data: `{root}`. Healthy seeds {plan.train[0]}-{plan.train[-1]} train, "
        f"{plan.calibrate[0]}-{plan.calibrate[-1]} calibrate the per-node residual "
        f"statistics, {plan.test[0]}-{plan.test[-1]} test; A degradations ramped over "
        f"{plan.ramp_s:g} s, fault seeds {plan.fault_seeds[0]}-{plan.fault_seeds[-1]}. "
        "Configuration (pinned in the script, not the plug-in's defaults): "
        f"`model_features: [{A}, {B}]`, `fault_channels: {A}`, "
        "`partition_features: sp.*`, i.e. one A-B parity relation per node (1 s moving "
        "averages of sensor A's tension and sensor B's pitch), fault-normalised on sensor A "
        "(docs/diagnostics.md §11), threshold 2σ of each node's residual. This is the "
        "configuration thesis Table 4-2 corresponds to: the table scores sensor-A faults "
        "only (the P20 degradations) with one relation per node between the thesis's "
        "sensors, and on this line the one relation that sees A is the A-normalised one "
        "(the thesis-literal unit-norm relation is blind to A, rows below). The plug-in's "
        "default (`fault_channels: all` over every `meas.*` channel, which also sees "
        "sensor-B faults) is compared with it in *Sensor A and sensor B faults in both "
        "configurations*. "
        "FAR: alarms over the scored samples of the healthy test runs; dr: alarms over "
        "the samples where the fault is at full size (`label.severity == 1`).",
        "",
    ]
    checks: list[Check] = []

    # ---- regimes -----------------------------------------------------------------------
    est = fitted(GSMMS, STUDY, data)
    glob = fitted(GlobalParity, STUDY, data)
    purity = node_purity(est, {m: data.healthy[m, "test"] for m in ("OC1", "OC2")})
    md += [
        "## Regimes (thesis Fig. 4-8a/b)",
        "",
        f"Fitted on OC1 + OC2 without being told how many regimes: **{est.n_nodes_} "
        f"nodes**. Growth: "
        + "; ".join(
            f"{h.n_nodes} nodes, loss {h.loss:.4g}, ζ = "
            f"[{', '.join(f'{z:.2f}' for z in h.zeta)}] → {h.decision}"
            for h in est.history_
        )
        + ".",
        "",
        "| condition | share of its test samples in its own node(s) |",
        "|---|---|",
    ]
    md += [f"| {m} | {p:.4f} |" for m, p in purity.items()]
    checks.append(Check("regimes: nodes", "≤ 4", str(est.n_nodes_), est.n_nodes_ <= 4))
    checks.append(
        Check(
            "regimes: purity per condition",
            "≥ 0.95",
            ", ".join(f"{m} {p:.3f}" for m, p in purity.items()),
            min(purity.values()) >= 0.95,
        )
    )
    fig = plot_gsmms_map(
        est,
        data.healthy["OC1", "test"][:2]
        + data.healthy["OC2", "test"][:2]
        + data.faults["OC1", 0.20][:1],
        "sp.line_speed_m_s",
        A,
        title="GSMMS on the set-points: healthy OC1/OC2 and OC1 P20",
    )
    save(fig, out / "map.png")
    md += ["", "![map](map.png)", ""]

    # ---- detection, global vs GSMMS ----------------------------------------------------
    rows = [detection_row("GSMMS", est, data), detection_row("global (one node)", glob, data)]
    lit = fitted(GSMMS, LITERAL, data)
    lit_g = fitted(GlobalParity, LITERAL, data)
    rows += [
        detection_row("GSMMS, thesis-literal unit-norm relation", lit, data),
        detection_row("global, thesis-literal unit-norm relation", lit_g, data),
    ]
    det = pd.DataFrame(rows).set_index("model")
    g, s = det.loc["global (one node)"], det.loc["GSMMS"]
    thesis = pd.DataFrame(
        {
            "far_OC1": [0.0690, 0.0184],
            "far_OC2": [0.0, 0.0643],
            "dr_OC1": [0.2722, 1.0],
            "dr_OC2": [1.0, 0.9883],
        },
        index=["thesis global", "thesis GSMMS"],
    )
    thesis["four_cell"] = [four_cell(r) for _, r in thesis.iterrows()]
    md += [
        "## Detection per condition, global vs GSMMS (thesis Table 4-2)",
        "",
        md_table(det, ".4f"),
        "",
        "Thesis Table 4-2 in the same terms "
        "(FAR = 1 − accuracy on N1/N2, dr = power on N1_f1/N2_f1):",
        "",
        md_table(thesis, ".4f"),
        "",
        "The thesis-literal rows use one unit-norm minimum-variance relation per node "
        "(eq. 4.21). Within a regime the registration loop holds sensor B still, so "
        "that relation is essentially 'B = const' and hardly sees a fault on A (its "
        "detection rate above); the fault-normalised design "
        "(docs/diagnostics.md §11) is the study's model.",
        "",
    ]
    for m in ("OC1", "OC2"):
        checks.append(
            Check(f"FAR at 2σ, {m}", "≤ 0.07", f"{s[f'far_{m}']:.4f}", s[f"far_{m}"] <= 0.07)
        )
        checks.append(
            Check(
                f"dr P20 steady state, {m}", "≥ 0.95", f"{s[f'dr_{m}']:.4f}", s[f"dr_{m}"] >= 0.95
            )
        )
    worse = {
        m: (g[f"dr_{m}"] <= s[f"dr_{m}"] - 0.3, g[f"far_{m}"] >= s[f"far_{m}"] + 0.03)
        for m in ("OC1", "OC2")
    }
    checks.append(
        Check(
            "global worse in some condition",
            "dr ≥ 0.3 lower or FAR ≥ 0.03 higher",
            "; ".join(
                f"{m}: Δdr {s[f'dr_{m}'] - g[f'dr_{m}']:+.3f}, "
                f"ΔFAR {g[f'far_{m}'] - s[f'far_{m}']:+.3f}"
                for m in worse
            ),
            any(a or b for a, b in worse.values()),
        )
    )
    checks.append(
        Check(
            "four-cell mean GSMMS − global",
            "≥ 0.10",
            f"{s['four_cell'] - g['four_cell']:+.4f}",
            s["four_cell"] - g["four_cell"] >= 0.10,
        )
    )
    md += [
        "Each relation as A ≈ c·B + const (c from Ω and the standardisation; the web's "
        "E·S/L0 is about 0.45 N/µm):",
        "",
        md_table(relations({"GSMMS": est, "global": glob}), ".4g"),
        "",
    ]
    if not next(c for c in checks if c.name.startswith("global worse")).ok:
        md += [
            "**Why the global model is not worse here.** Both conditions run the same "
            "product, so the A-B relation is the same physics in both (the table above): "
            "the single relation of the global model cancels the change of set-point "
            "between OC1 and OC2 as well as each node's relation fits its own regime, and "
            "its residual spread is nearly the same. The thesis's global failure (27 % "
            "power in OC1) appears here only when the partition sits on the faulty "
            "sensor (see *Masking* below: the same 20 % fault in OC1 then reads like "
            "OC2), or when the relation itself changes between regimes (see *A second "
            "product in training* below, when the data has product P2's runs).",
            "",
        ]
    runs = {}
    for m in ("OC1", "OC2"):
        runs[f"{m} healthy (test seed)"] = data.healthy[m, "test"][0]
        runs[f"{m} A degradation P20"] = data.faults[m, 0.20][0]
    save(plot_gsmms_residuals(est, runs, title="GSMMS residual per regime"), out / "residuals.png")
    save(
        plot_gsmms_residuals(glob, runs, title="global model residual"),
        out / "residuals_global.png",
    )
    md += ["![residuals](residuals.png)", "", "![residuals, global](residuals_global.png)", ""]

    # ---- severity -----------------------------------------------------------------------
    sev = {
        m: {g_: mean_abs_z(est, data.faults[m, g_]) for g_ in MAGNITUDES} for m in ("OC1", "OC2")
    }
    sev_dr = {
        m: {g_: dr_steady(est, data.faults[m, g_]) for g_ in MAGNITUDES} for m in ("OC1", "OC2")
    }
    tab = pd.DataFrame(
        {f"mean |z| {m}": sev[m] for m in sev} | {f"dr {m}": sev_dr[m] for m in sev_dr}
    )
    tab.index = [f"P{round(x * 100):02d}" for x in tab.index]
    md += [
        "## Severity (thesis Fig. 4-8c/d)",
        "",
        "Mean node-standardised |residual| over the full-size samples, and the detection "
        "rate there:",
        "",
        md_table(tab, ".3f"),
        "",
        "![severity](severity.png)",
        "",
    ]
    save(
        plot_severity(
            sev,
            threshold=est.threshold_,
            xlabel="A degradation (gain)",
            title="residual against severity",
        ),
        out / "severity.png",
    )
    for m in ("OC1", "OC2"):
        v = [sev[m][x] for x in MAGNITUDES]
        checks.append(
            Check(
                f"severity monotone, {m}",
                "P05 < P10 < P15 < P20",
                " < ".join(f"{x:.2f}" for x in v),
                bool(np.all(np.diff(v) > 0)),
            )
        )

    # ---- solvers ------------------------------------------------------------------------
    sol = solver_comparison(est, data)
    r = sol["rmse_N"]
    spread = float(
        r[["batch", "sgd", "minibatch"]].max() / r[["batch", "sgd", "minibatch"]].min() - 1
    )
    md += [
        "## Solvers (thesis Table 4-1)",
        "",
        "Each node's relation refitted on the final partition, timed side by side in one "
        "process (batch GD: 2000 full-gradient steps; single-sample SGD: one pass; "
        "mini-batch: 128 per step, max(3000 steps, one pass); the oracle is exact):",
        "",
        md_table(sol, ".4g"),
        "",
        "Thesis: batch GD 2377 s / RMSE 0.642, SGD 48506 s / 0.632, mini-batch 1813 s / "
        "0.639 (MATLAB; absolute times do not transfer).",
        "",
    ]
    checks.append(
        Check(
            "solver RMSEs agree",
            "within 5 %",
            f"spread {spread:.2%} (oracle {r['eigh']:.3f} N)",
            spread <= 0.05,
        )
    )
    t = sol["time_s"]
    checks.append(
        Check(
            "time mini-batch / batch GD",
            "≤ 1.5",
            f"{t['minibatch'] / t['batch']:.3f}",
            t["minibatch"] <= 1.5 * t["batch"],
        )
    )
    checks.append(
        Check(
            "time single-sample SGD / mini-batch",
            "≥ 3",
            f"{t['sgd'] / t['minibatch']:.1f}",
            t["sgd"] >= 3 * t["minibatch"],
        )
    )

    # ---- adaptation ---------------------------------------------------------------------
    ad, ad_history = adaptation(data)
    md += [
        "## Online growth (beyond the thesis)",
        "",
        "Fitted on OC1 only, then OC2's and OC3's training runs streamed through "
        "`partial_fit`; FAR on each condition's test runs after each stage (node "
        "statistics from the streamed data, no calibration runs):",
        "",
        md_table(ad, ".4f"),
        "",
        "Growth decisions in order: "
        + "; ".join(
            f"{h.n_nodes} nodes, ζ = [{', '.join(f'{z:.2f}' for z in h.zeta)}] → {h.decision}"
            for h in ad_history
        )
        + ".",
        "",
    ]
    first, after2, after3 = ad.iloc[0], ad.iloc[1], ad.iloc[2]
    checks.append(
        Check(
            "OC2 streamed: node added",
            "nodes increase",
            f"{first['nodes']} → {after2['nodes']}",
            after2["nodes"] > first["nodes"],
        )
    )
    checks.append(
        Check(
            "OC2 FAR after adaptation",
            "≤ 2 × OC1 FAR",
            f"{after2['far_OC2']:.4f} vs 2 × {after2['far_OC1']:.4f}",
            after2["far_OC2"] <= 2 * after2["far_OC1"],
        )
    )
    checks.append(
        Check(
            "OC3 (held out) streamed: node added",
            "nodes increase",
            f"{after2['nodes']} → {after3['nodes']}",
            after3["nodes"] > after2["nodes"],
        )
    )
    checks.append(
        Check(
            "OC3 FAR after adaptation",
            "≤ 2 × OC1 FAR",
            f"{after3['far_OC3']:.4f} vs 2 × {after3['far_OC1']:.4f}",
            after3["far_OC3"] <= 2 * after3["far_OC1"],
        )
    )
    if after3["nodes"] == after2["nodes"]:
        md += [
            "**Why OC3 adds no node.** Growth is driven by how badly the local relations "
            "fit (the loss share ζ and the loss improvement), not by distance in the "
            "partition space. OC3 (0.75 m/s, 145 N) lies between OC1 and OC2 and has the "
            "same A-B relation; its samples join an existing node, whose relation and "
            "statistics, re-fitted on the pooled data, fit it "
            f"(OC3 FAR {after2['far_OC3']:.3f} → {after3['far_OC3']:.3f}). The check "
            "'node added' fails as stated; the FAR check passes.",
            "",
        ]

    # ---- masking by a partition on the faulty sensor --------------------------------------
    mask_est = fitted(GSMMS, {**STUDY, "partition_features": [A]}, data)
    p20 = data.faults["OC1", 0.20]
    oc2_nodes = set(
        np.unique(
            np.concatenate(
                [mask_est.score(x)["bmu"].to_numpy() for x in data.healthy["OC2", "test"]]
            )
        )
    )
    moved = float(
        np.mean(
            np.concatenate(
                [
                    np.isin(mask_est.score(x)["bmu"].to_numpy()[steady(x)], list(oc2_nodes))
                    for x in p20
                ]
            )
        )
    )
    mrow = detection_row("GSMMS partitioned on sensor A (thesis)", mask_est, data)
    md += [
        "## Masking: partitioning on the sensor that fails (the thesis's choice)",
        "",
        "The thesis partitions on a state estimated from sensor A. Partitioned on A's "
        "reading instead of the set-points:",
        "",
        md_table(pd.DataFrame([rows[0], mrow]).set_index("model"), ".4f"),
        "",
        f"In the OC1 runs with a 20 % degradation (A reads about 156 N, near OC2's "
        f"160 N), **{moved:.1%}** of the full-size samples are judged by a node that OC2's "
        "healthy samples use.",
        "",
        "![masking](masking_map.png)",
        "",
        "![masking residual](masking_residuals.png)",
        "",
    ]
    save(
        plot_gsmms_map(
            mask_est,
            data.healthy["OC1", "test"][:2] + data.healthy["OC2", "test"][:2] + p20[:1],
            "sp.line_speed_m_s",
            A,
            title="partition on sensor A: OC1 P20 slides into OC2's nodes",
        ),
        out / "masking_map.png",
    )
    save(
        plot_gsmms_residuals(
            mask_est, {"OC1 A degradation P20, partition on A": p20[0]}, title="masking"
        ),
        out / "masking_residuals.png",
    )

    # ---- sensor-A and sensor-B faults, study configuration against the default ---------------
    if not plan.quick:
        md += configuration_section(root, data, plan)

    # ---- a second product (beyond the issue) ------------------------------------------------
    if data.healthy.get(("P2", "train")):
        md += product_section(data)

    # ---- within-run regime changes --------------------------------------------------------
    if data.switching:
        sw = switching_table(est, data.switching)
        md += [
            "## Within-run regime change (switching runs, OC1 → OC2 at 100 s)",
            "",
            md_table(sw, ".4f"),
            "",
        ]
        save(
            plot_gsmms_residuals(
                est,
                {
                    f"switching {k}": x
                    for k, x in zip(
                        sw.index[:1].tolist() + sw.index[-1:].tolist(),
                        data.switching[:1] + data.switching[-1:],
                        strict=True,
                    )
                },
                title="switching runs",
            ),
            out / "switching.png",
        )
        md += ["![switching](switching.png)", ""]
    else:
        md += ["## Within-run regime change", "", "No switching dataset (quick version).", ""]

    # ---- summary ------------------------------------------------------------------------
    if plan.quick:
        for c in checks:
            c.asserted = c.name.startswith(QUICK_ASSERTED)
    md[1:1] = (
        ["", "| assertion | threshold | measured | result |", "|---|---|---|---|"]
        + [f"| {c.name} | {c.threshold} | {c.measured} | {c.result} |" for c in checks]
        + [
            "",
            report_note([c.result for c in checks], EXPECTED_FAILURES),
            "",
            "Results in parentheses are reported, not asserted (the quick version: too few "
            "runs for them)."
            if plan.quick
            else "",
            f"Run time: {time.perf_counter() - t_start:.0f} s (reading the data included).",
        ]
    )
    (out / "report.md").write_text("\n".join(md) + "\n")
    return checks


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", required=True, type=Path, help="report directory")
    ap.add_argument("--quick", action="store_true", help="a reduced version (CI)")
    ap.add_argument(
        "--data",
        type=Path,
        help="directory holding healthy/, faults/ "
        "(and switching/) sweep datasets of scenarios/thesis_realistic",
    )
    ap.add_argument("--workers", type=int, default=1, help="simulation workers")
    args = ap.parse_args(argv)
    plan = QUICK if args.quick else FULL
    args.output.mkdir(parents=True, exist_ok=True)
    if args.data is not None:
        for name in ("healthy", "faults"):
            if not (args.data / name).is_dir():
                ap.error(f"--data {args.data}: no {name}/ dataset in it")
        root = args.data
    else:
        root = simulate(args.output, plan, args.workers)
    checks = study(root, args.output, plan)
    width = max(len(c.name) for c in checks)
    for c in checks:
        print(f"{c.result:<6}  {c.name:<{width}}  {c.measured}  (required {c.threshold})")
    print(summary([c.name for c in checks], [c.result for c in checks], EXPECTED_FAILURES))
    print(f"report: {args.output / 'report.md'}")
    return exit_status(c.result for c in checks)


if __name__ == "__main__":
    sys.exit(main())
