"""Plots of the two thesis scenarios for docs/ (needs matplotlib: pip install -e ".[plot]").

    python docs/make_plots.py

Runs scenarios/thesis_normal_cycles.yaml and scenarios/thesis_dancer_failure.yaml into a
temporary directory and draws the tension of stages 2-5 over time with the splice phases
shaded (thesis Fig. 2-13, Fig. 2-15a and b).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

import r2rsim  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STAGES = [("span3", "stage 2 (s2b-s2c)"), ("span4", "stage 2-3 (load cell -> dancer)"),
          ("span6", "stage 3-4 (-> driven roller)"), ("registration", "stage 4-5 (vision)"),
          ("span9", "stage 5 (-> rewind)")]
PHASE_COLOURS = {"fill": "#dbe9f6", "brake": "#f6d8d8", "dwell": "#f3c0c0",
                 "accelerate": "#fbe3c4", "refill": "#e1f2dc"}


def plot(name: str, title: str, out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        r2rsim.run_scenario(ROOT / "scenarios" / f"{name}.yaml", output=Path(tmp) / name)
        s = pd.read_parquet(Path(tmp) / name / "samples")
        ev = pd.read_parquet(Path(tmp) / name / "events.parquet")
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True,
                                  gridspec_kw={"height_ratios": [3, 1.2]})
    sp = ev[ev.kind == "splice"].reset_index(drop=True)
    for i, row in sp.iterrows():
        if row.state in PHASE_COLOURS:
            t1 = sp.t_s[i + 1] if i + 1 < len(sp) else s.t_s.iloc[-1]
            for a in (ax, ax2):
                a.axvspan(row.t_s, t1, color=PHASE_COLOURS[row.state], lw=0,
                          label=row.state if a is ax else None)
    for col, label in STAGES:
        ax.plot(s.t_s, s[f"state.{col}.tension_N"], lw=0.8, label=label)
    for _, row in ev[ev.kind.isin(["web_break", "dancer_seized"])].iterrows():
        ax.axvline(row.t_s, color="k", ls="--", lw=0.8)
        ax.annotate(row.kind.replace("_", " "), (row.t_s, ax.get_ylim()[1]), fontsize=8,
                    rotation=90, va="top", ha="right")
    ax.set_ylabel("tension [N]")
    ax.set_title(title)
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    ax.legend(uniq.values(), uniq.keys(), fontsize=7, ncol=3, loc="upper left")
    ax2.plot(s.t_s, s["state.unwind.surface_speed_m_s"], lw=0.8, label="unwind (stage 1)")
    ax2.plot(s.t_s, s["state.drive4.surface_speed_m_s"], lw=0.8, label="driven roller (stage 4)")
    ax2.set_ylabel("speed [m/s]")
    ax2.set_xlabel("time [s]")
    ax2.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main() -> int:
    plot("thesis_normal_cycles", "Thesis testbed, normal cycles (cf. Shui 2018 Fig. 2-13, "
         "2-15a):\nthe dancer stores web (tension climbs), then supplies stages 3-5 in the splice",
         ROOT / "docs" / "thesis_normal_cycles.png")
    plot("thesis_dancer_failure", "Thesis testbed, dancer seized before a changeover "
         "(cf. Fig. 2-15b):\nno storage, no climb; web break in the splice",
         ROOT / "docs" / "thesis_dancer_failure.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
