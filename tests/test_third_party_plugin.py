"""A third-party diagnostic plug-in is discovered and scored with no change to r2rsim: the
example package in tests/example_plugin, registered through its ``r2rsim.diagnostics`` entry
point, run through the ``r2rsim`` command line."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib

import numpy as np
import pandas as pd
import pytest

import r2rsim
from r2rsim.dataset.read import read_runs

from conftest import REPO

EXAMPLE = REPO / "tests" / "example_plugin"
GROUP = "r2rsim.diagnostics"
NAME = "example-ewma"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A directory that, on sys.path, holds the example as an installed distribution: its
    package and a minimal dist-info with the entry points of its shipped pyproject.toml (as
    `pip install` would write, without pip, the network or touching this environment)."""
    d = tmp_path_factory.mktemp("site")
    shutil.copytree(
        EXAMPLE / "r2rsim_example_plugin",
        d / "r2rsim_example_plugin",
        ignore=shutil.ignore_patterns("__pycache__"),
    )
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    eps = project["entry-points"][GROUP]
    assert NAME in eps
    info = d / f"{project['name'].replace('-', '_')}-{project['version']}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n",
        encoding="utf-8",
    )
    (info / "entry_points.txt").write_text(
        f"[{GROUP}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()), encoding="utf-8"
    )
    return d


def cli(*args, site=None, cwd):
    """``r2rsim ARGS`` in a subprocess (its own entry-point cache), ``site`` on PYTHONPATH."""
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(site), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", "r2rsim.cli", *map(str, args)],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Healthy OC1 runs (seeds 1, 2 train; 3 val; 4 test) and sensor A +15 % at 20 s (seed 5)."""
    d = tmp_path_factory.mktemp("third_party_data")
    for name, scen, seed in (
        ("h1", "oc1_nominal", 1),
        ("h2", "oc1_nominal", 2),
        ("h3", "oc1_nominal", 3),
        ("h4", "oc1_nominal", 4),
        ("f5", "sensor_a_offset_P15", 5),
    ):
        r2rsim.run_scenario(
            REPO / "scenarios" / "thesis" / f"{scen}.yaml",
            output=d / name,
            seed=seed,
            duration=30.0,
        )
    return d


def diagnose(site, data, out, *params):
    return cli(
        "diagnose",
        "--method",
        NAME,
        "--train",
        data / "h1",
        data / "h2",
        "--val",
        data / "h3",
        "--test",
        data / "h4",
        data / "f5",
        *params,
        "-o",
        data / out,
        "--n-boot",
        50,
        site=site,
        cwd=data,
    )


@pytest.fixture(scope="module")
def diagnosed(site, data):
    return diagnose(site, data, "out_lam02", "--param", "lam=0.2")


def test_plugin_is_listed_only_when_registered(site, tmp_path):
    without = cli("list", "plugins", cwd=tmp_path)
    with_ = cli("list", "plugins", site=site, cwd=tmp_path)
    assert without.returncode == 0 and with_.returncode == 0, without.stderr + with_.stderr
    names = [{ln.split()[0] for ln in p.stdout.splitlines()[1:-1]} for p in (without, with_)]
    assert NAME not in names[0]
    assert names[1] == names[0] | {NAME} and {"residual", "pca", "dpca", "iforest"} <= names[1]
    assert "r2rsim_example_plugin.EwmaDetector" in with_.stdout


def test_diagnose_scores_the_plugin(diagnosed, data):
    assert diagnosed.returncode == 0, diagnosed.stderr
    out = data / "out_lam02"
    assert all(
        (out / f).is_file() for f in ("predictions.parquet", "metrics.parquet", "metrics.csv")
    )
    m = pd.read_parquet(out / "metrics.parquet")
    assert set(m["method"]) == {NAME}
    assert set(pd.read_csv(out / "metrics.csv")["method"]) == {NAME}
    # one stratum: the healthy test run with the faulty one; observed pd = dr = roc_auc = 1,
    # a delay of 0 s, far_ff = 0 at the plug-in's own threshold and 0.007 at theta (M6)
    v = m[m["fault"] == "sensor.offset:sensor_A"].set_index("metric")["value"]
    assert v["pd"] == 1.0 and v["n_missed"] == 0
    assert v["dr"] > 0.95 and v["roc_auc"] > 0.99 and v["dd_median_s"] <= 1.0
    assert v["far_ff"] < 0.05 and v["far_pre"] < 0.05 and v["far_ff_cal"] < 0.05
    # predictions: one row per sample of each test run, in order
    p = pd.read_parquet(out / "predictions.parquet")
    assert set(p["method"]) == {NAME}
    for name in ("h4", "f5"):
        run = read_runs(data / name)[0]
        k = p.loc[p["run_id"] == run.run_id, "k"].to_numpy()
        assert len(k) == len(run.samples)  # 3001 samples: 30 s at 100 Hz
        np.testing.assert_array_equal(k, run.samples["k"].to_numpy())


def test_params_reach_the_plugin(site, data, diagnosed):
    assert '"lam": 0.2' in diagnosed.stdout  # the header names the fitted parameters
    bad = diagnose(site, data, "out_bad", "--param", "nosuch=1")
    assert bad.returncode == 2
    assert "nosuch" in bad.stderr and NAME in bad.stderr and "lam" in bad.stderr
    assert not (data / "out_bad").exists()
    # the default lam = 0.1 smooths more: a different statistic on the same runs
    default = diagnose(site, data, "out_default")
    assert default.returncode == 0, default.stderr
    s02 = pd.read_parquet(data / "out_lam02" / "predictions.parquet")["statistic"]
    s01 = pd.read_parquet(data / "out_default" / "predictions.parquet")["statistic"]
    assert len(s01) == len(s02) and not np.allclose(s01, s02)


def test_the_installed_plugin_passes_the_shipped_checks(site, tmp_path):
    # what docs/diagnostics.md §2.1 tells a plug-in's author to run: r2rsim's own checks,
    # on the built-in data, from an installed r2rsim (no checkout of r2rsim's tests needed)
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")])),
    )
    code = (
        "from r2rsim.evaluate import check_plugin\n"
        f"for check in check_plugin({NAME!r}):\n    print('ok:', check)\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("ok: ") == 9 and "deterministic" in res.stdout, res.stdout
    assert "causal as declared" in res.stdout and "calibrate(runs, alpha, masks)" in res.stdout
