"""P_D against fault size, with the null rate, from `r2rsim bench -o` or `r2rsim diagnose -o`
results: does a method's detection probability ever fall as a fault grows?

For every method (bench label, with its study), condition and fault stratum run at several
magnitudes, the magnitudes are taken per sign in increasing |magnitude|. P_D is said to
**fall** between two consecutive sizes when the larger size's P_D lies below the smaller
size's P_D by more than the bootstrap intervals allow: the larger size's upper bound
(``ci_high``) is below the smaller size's P_D. A fall inside the intervals is sampling noise
(5 runs per cell give intervals of about ±0.4). Exit status 1 when any fall is found.

The pooled condition ``all`` is left out of the verdict (``--pooled`` counts it): its
magnitude rows mix operating points whose faults are sized differently (a 15 % offset is
19.5 N in OC1 and 24 N in OC2), so their order by size is not a fault-size sweep of one line.

    python benchmarks/detection_by_size.py results/thesis_realistic results/thesis_methods
    python benchmarks/detection_by_size.py RESULTS --metric pd_cal --table
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

NULL_OF = {"pd": "pd_null", "pd_cal": "pd_null_cal"}


def read(path: Path) -> pd.DataFrame:
    """The long results table of a bench or diagnose output directory."""
    for name in ("results.parquet", "metrics.parquet"):
        if (path / name).is_file():
            t = pd.read_parquet(path / name)
            break
    else:
        raise SystemExit(f"{path}: no results.parquet or metrics.parquet")
    if "label" not in t.columns:
        t["label"] = t["method"]
    if "study" not in t.columns:
        t["study"] = t.get("split", "")
    return t


def by_size(table: pd.DataFrame, metric: str) -> pd.DataFrame:
    """One row per (study, label, condition, fault, magnitude): P_D with its interval and its
    null rate."""
    keys = ["study", "label", "condition", "fault", "magnitude"]
    rows = table[table["magnitude"].notna()]
    pd_ = rows[rows["metric"] == metric].set_index(keys)[["value", "ci_low", "ci_high", "n_runs"]]
    null = rows[rows["metric"] == NULL_OF[metric]].set_index(keys)["value"]
    out = pd_.join(null.rename("null"), how="left").reset_index()
    out["abs"] = out["magnitude"].abs()
    out["sign"] = np.sign(out["magnitude"])
    return out.sort_values(["study", "label", "condition", "fault", "sign", "abs"])


def falls(sizes: pd.DataFrame) -> pd.DataFrame:
    """The consecutive pairs of sizes (same sign) where P_D falls beyond the interval."""
    found = []
    for _, g in sizes.groupby(["study", "label", "condition", "fault", "sign"], sort=False):
        g = g.reset_index(drop=True)
        for i in range(1, len(g)):
            small, large = g.iloc[i - 1], g.iloc[i]
            if large["ci_high"] < small["value"]:
                found.append(
                    {
                        **{k: large[k] for k in ("study", "label", "condition", "fault")},
                        "smaller": small["magnitude"],
                        "pd_smaller": small["value"],
                        "larger": large["magnitude"],
                        "pd_larger": large["value"],
                        "ci_high_larger": large["ci_high"],
                    }
                )
    return pd.DataFrame(found)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path, help="bench -o or diagnose -o directories")
    ap.add_argument("--metric", choices=sorted(NULL_OF), default="pd")
    ap.add_argument("--table", action="store_true", help="also print P_D and pd_null by size")
    ap.add_argument(
        "--pooled",
        action="store_true",
        help="also judge the pooled condition 'all' (mixes operating points)",
    )
    args = ap.parse_args(argv)
    sizes = pd.concat([by_size(read(p), args.metric) for p in args.results], ignore_index=True)
    if args.table:
        with pd.option_context("display.width", 200, "display.max_rows", None):
            print(sizes.drop(columns=["abs", "sign"]).to_string(index=False, float_format="%.3g"))
    pooled = sizes["condition"] == "all"
    print(
        f"pooled condition 'all': {len(falls(sizes[pooled]))} falls (not judged"
        f"{'; --pooled judges it' if not args.pooled else ''}: sizes of different operating "
        f"points)"
    )
    if not args.pooled:
        sizes = sizes[~pooled]
    bad = falls(sizes)
    n_pairs = int(
        sum(
            max(len(g) - 1, 0)
            for _, g in sizes.groupby(["study", "label", "condition", "fault", "sign"])
        )
    )
    print(
        f"{args.metric}: {n_pairs} consecutive size pairs over "
        f"{sizes.groupby(['study', 'label', 'condition', 'fault']).ngroups} strata; "
        f"{len(bad)} fall beyond the bootstrap interval"
    )
    if len(bad):
        print(bad.to_string(index=False, float_format="%.3g"))
    return 1 if len(bad) else 0


if __name__ == "__main__":
    sys.exit(main())
