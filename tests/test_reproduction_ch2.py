"""The machinery of benchmarks/reproduction/ch2_hybrid_sov.py (its full and --quick runs are
in CI and docs/reproduction/hybrid_sov/): arguments, cycles and roll-change windows from
events, the bootstrap over cycles and the whiteness tests."""

from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd
import pytest

from conftest import REPO

_spec = importlib.util.spec_from_file_location(
    "ch2_hybrid_sov", REPO / "benchmarks" / "reproduction" / "ch2_hybrid_sov.py")
ch2 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ch2)


def test_arguments():
    a = ch2.parse_args(["-o", "x", "--quick"])
    assert a.quick and a.n_boot == 500 and a.data is None
    assert ch2.parse_args(["-o", "x"]).n_boot == 2000
    with pytest.raises(SystemExit):
        ch2.parse_args(["--quick"])                     # -o is required
    with pytest.raises(SystemExit):
        ch2.parse_args(["-o", "x", "--n-boot", "5"])


def test_cycles_and_windows_from_events():
    ev = pd.DataFrame({"t_s": [10, 16, 17, 18, 22, 60, 66, 67, 68, 72, 110, 116, 117, 118],
                       "state": ["fill", "brake", "dwell", "swap", "complete"] * 2
                       + ["fill", "brake", "dwell", "swap"]})
    t = np.arange(0, 130, 0.5)
    cyc = ch2.cycles_of(t, ev)
    assert len(cyc) == 2                                  # swap to swap: 18-68, 68-118
    assert t[cyc[0]].min() == 18 and t[cyc[0]].max() == 67.5
    assert ch2.windows(ev, "fill", "brake") == [(10, 16), (60, 66), (110, 116)]
    assert ch2.windows(ev, "fill", "complete") == [(10, 22), (60, 72)]
    m = ch2.in_windows(t, [(10, 16)])
    assert m.sum() == 13


def test_bootstrap_improvement_over_cycles():
    rng = np.random.default_rng(0)
    eh = [rng.normal(0, 1.0, 500) for _ in range(3)]
    ed = [rng.normal(0, 2.0, 500) for _ in range(3)]
    pt, lo, hi = ch2.bootstrap_improvement(eh, ed, 500)
    assert pt == pytest.approx(0.5, abs=0.03) and lo < pt < hi and lo > 0.4
    pt, lo, hi = ch2.bootstrap_improvement(ed, ed, 200)
    assert pt == lo == hi == 0.0


def test_whiteness_and_arch():
    rng = np.random.default_rng(2)
    white = [rng.normal(size=2000) for _ in range(3)]
    w = ch2.whiteness(white)
    assert w["lag_samples"] == 1 and w["ljung_box_p"] > 0.001 and w["arch_p"] > 0.001
    # an AR(1) with coefficient 0.9 decorrelates (ACF < 1/e) after about 10 samples
    ar = np.zeros(20000)
    e = rng.normal(size=ar.size)
    for k in range(1, ar.size):
        ar[k] = 0.9 * ar[k - 1] + e[k]
    assert 8 <= ch2.decorrelation_lag(ar) <= 12
    # ARCH(1) errors: the LM test rejects
    x = np.zeros(5000)
    z = rng.normal(size=x.size)
    for k in range(1, x.size):
        x[k] = z[k] * np.sqrt(0.2 + 0.7 * x[k - 1] ** 2)
    assert ch2.arch_lm_p(x, 5) < 1e-6
