"""``r2rsim diagnose`` and ``r2rsim bench`` on bad datasets and broken plug-ins: every problem
is one ``error:`` line naming the dataset/file or plug-in/method, a non-zero exit code, no
traceback (unless --debug) and nothing written. Datasets changed after they were written are
refused by their manifest.json checksums (``--no-verify`` overrides)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from importlib.metadata import EntryPoint

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import r2rsim
from r2rsim.cli import main
from r2rsim.dataset.read import read_runs
from r2rsim.dataset.validate import validate_dataset
from r2rsim.diagnostics import registry
from r2rsim.errors import InputError, PluginError
from r2rsim.evaluate.results import REPORT_MARKER

from conftest import REPO

THESIS = REPO / "scenarios" / "thesis"
DURATION = 22.0  # the sensor-A offset starts at 20 s


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Healthy OC1 runs h1, h2 (train) and h3 (test), and sensor A +15 % from 20 s (f5)."""
    d = tmp_path_factory.mktemp("robust_data")
    for name, scen, seed in (
        ("h1", "oc1_nominal", 1),
        ("h2", "oc1_nominal", 2),
        ("h3", "oc1_nominal", 3),
        ("f5", "sensor_a_offset_P15", 5),
    ):
        r2rsim.run_scenario(THESIS / f"{scen}.yaml", output=d / name, seed=seed, duration=DURATION)
    return d


def copy(data, tmp_path, name="f5"):
    return shutil.copytree(data / name, tmp_path / name)


def samples_file(ds):
    return next((ds / "samples").glob("run_id=*/part-0.parquet"))


def diagnose(data, test, out, *extra, method="pca"):
    return main(
        [
            "diagnose",
            "--method",
            method,
            "--train",
            str(data / "h1"),
            str(data / "h2"),
            "--test",
            str(data / "h3"),
            str(test),
            "--n-boot",
            "20",
            "-o",
            str(out),
            *extra,
        ]
    )


def one_error_line(capsys, *words):
    """stderr is exactly one 'error:' line holding every word; returns it."""
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err, err
    assert "Traceback" not in err
    for w in words:
        assert str(w) in err, (w, err)
    return err


# --------------------------------------------------------------------------- checksums


def tamper_labels_and_onset(ds):
    """What the issue did: erase the fault labels and move the onset (20 s -> 10 s)."""
    f = samples_file(ds)
    t = pq.read_table(f)
    i = t.column_names.index("label.is_faulty")
    pq.write_table(t.set_column(i, "label.is_faulty", pa.array([False] * t.num_rows)), f)
    faults = pq.read_table(ds / "faults.parquet")
    i = faults.column_names.index("onset_t_s")
    pq.write_table(faults.set_column(i, "onset_t_s", pa.array([10.0])), ds / "faults.parquet")


def test_tampered_labels_are_refused_unless_no_verify(data, tmp_path, capsys):
    ds = copy(data, tmp_path)
    tamper_labels_and_onset(ds)
    # before: diagnose used the tampered labels silently (far_ff 0.0188 -> 0.216 in the issue)
    assert diagnose(data, ds, tmp_path / "out") == 2
    err = one_error_line(
        capsys, ds, "faults.parquet", "manifest.json", "--no-verify", "r2rsim validate"
    )
    assert "refusing" in err
    assert not (tmp_path / "out").exists()
    with pytest.raises(InputError, match="manifest.json"):
        read_runs(ds)
    # the override: the tampered labels are used, and change the metrics
    assert diagnose(data, ds, tmp_path / "forced", "--no-verify") == 0
    assert diagnose(data, data / "f5", tmp_path / "clean") == 0
    capsys.readouterr()
    m = {k: pd.read_parquet(tmp_path / k / "metrics.parquet") for k in ("forced", "clean")}
    far = {
        k: v.loc[(v.metric == "far_ff") & (v.condition == "OC1"), "value"].iloc[0]
        for k, v in m.items()
    }
    assert far["forced"] != far["clean"]


def test_same_size_change_is_caught_by_sha256(data, tmp_path, capsys):
    ds = copy(data, tmp_path)
    f = samples_file(ds)
    raw = bytearray(f.read_bytes())
    raw[len(raw) // 2] ^= 0xFF  # one byte, same size: only the sha256 sees it
    f.write_bytes(bytes(raw))
    assert diagnose(data, ds, tmp_path / "out") == 2
    one_error_line(
        capsys,
        ds,
        "run thesis_sensor_a_offset_P15__s5",
        f.relative_to(ds).as_posix(),
        "checksum differs from manifest.json",
    )
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- broken files


def _missing(f):
    f.unlink()


def _truncated(f):
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])


def _random_bytes(f):
    f.write_bytes(os.urandom(f.stat().st_size))


@pytest.mark.parametrize("damage", [_missing, _truncated, _random_bytes])
@pytest.mark.parametrize("verify", [True, False])
def test_broken_samples_file(data, tmp_path, capsys, damage, verify):
    ds = copy(data, tmp_path)
    f = samples_file(ds)
    damage(f)
    extra = [] if verify else ["--no-verify"]
    assert diagnose(data, ds, tmp_path / "out", *extra) == 2
    err = one_error_line(capsys, f"dataset {ds}", "run thesis_sensor_a_offset_P15__s5")
    if verify:
        assert "manifest.json" in err
    elif damage is _missing:
        assert "no samples file" in err and "not a complete r2rsim dataset" in err
    else:
        assert "not a readable Parquet file" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("verify", [True, False])
def test_non_parquet_runs_file(data, tmp_path, capsys, verify):
    ds = copy(data, tmp_path)
    (ds / "runs.parquet").write_text("run_id,seed\nx,1\n")
    extra = [] if verify else ["--no-verify"]
    assert diagnose(data, ds, tmp_path / "out", *extra) == 2
    err = one_error_line(capsys, f"dataset {ds}", "runs.parquet")
    assert ("manifest.json" if verify else "not a readable Parquet file") in err


@pytest.mark.parametrize("verify", [True, False])
def test_missing_faults_file_names_dataset_and_file(data, tmp_path, capsys, verify):
    ds = copy(data, tmp_path)
    (ds / "faults.parquet").unlink()
    extra = [] if verify else ["--no-verify"]
    assert diagnose(data, ds, tmp_path / "out", *extra) == 2
    one_error_line(
        capsys, f"dataset {ds}", "faults.parquet is missing", "not a complete r2rsim dataset"
    )


def test_missing_manifest_is_refused_unless_no_verify(data, tmp_path, capsys):
    ds = copy(data, tmp_path)
    (ds / "manifest.json").unlink()
    assert diagnose(data, ds, tmp_path / "out") == 2
    one_error_line(capsys, ds, "no manifest.json", "--no-verify")
    assert diagnose(data, ds, tmp_path / "out", "--no-verify") == 0


def test_validate_reports_unreadable_files_without_traceback(data, tmp_path, capsys):
    ds = copy(data, tmp_path)
    (ds / "runs.parquet").write_bytes(b"not parquet")
    problems = validate_dataset(ds)
    assert any("runs.parquet: not a readable Parquet file" in p for p in problems)
    assert main(["validate", str(ds)]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_an_oversized_manifest_is_refused_without_reading_it(data, tmp_path, capsys):
    ds = copy(data, tmp_path)
    with open(ds / "manifest.json", "wb") as f:  # sparse: no disk, 256 MiB + 1 byte
        f.truncate((256 << 20) + 1)
    assert diagnose(data, ds, tmp_path / "out") == 2
    one_error_line(capsys, ds, "manifest.json", "larger than 256 MiB")
    assert main(["validate", str(ds)]) == 2
    err = capsys.readouterr().err
    assert "larger than 256 MiB" in err and "Traceback" not in err


# --------------------------------------------------------------------------- parameters


def test_param_of_the_wrong_type_names_parameter_and_type(data, tmp_path, capsys):
    assert diagnose(data, data / "f5", tmp_path / "out", "--param", "n_components=banana") == 2
    one_error_line(capsys, "--param n_components", "pca", "a number", "'banana'")
    assert diagnose(data, data / "f5", tmp_path / "out", "--param", "lags=1.5", method="dpca") == 2
    one_error_line(capsys, "lags", "an integer", "1.5")
    assert not (tmp_path / "out").exists()


def test_unbounded_values_are_refused_before_anything_is_written(data, tmp_path, capsys):
    # --n-boot 1e12 ran into a MemoryError traceback; lags 1e12 hung the fit
    assert diagnose(data, data / "f5", tmp_path / "out", "--n-boot", "1000000000000") == 2
    one_error_line(capsys, "n_boot must be from 0 to 100000")
    assert (
        diagnose(
            data, data / "f5", tmp_path / "out", "--param", "lags=1000000000000", method="dpca"
        )
        == 2
    )
    one_error_line(capsys, "dpca", "lags must be an integer from 0 to 50")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "flag, value, words",
    [
        ("--vus-buffer", "1e9", "vus_buffer must be from 0 to 60 s"),  # hung: 1e11 buffer lengths
        ("--seed", "-1", "seed must be an integer from 0 to 2**64 - 1, got -1"),  # numpy traceback
        ("--seed", str(2**64), "seed must be an integer from 0 to 2**64 - 1"),
    ],
)
def test_settings_are_refused_before_any_dataset_is_read(tmp_path, capsys, flag, value, words):
    # the test dataset does not exist: a setting checked later would report that instead
    assert (
        main(
            [
                "diagnose",
                "--method",
                "residual",
                "--train",
                str(tmp_path / "nosuch"),
                "--test",
                str(tmp_path / "nosuch"),
                "-o",
                str(tmp_path / "out"),
                flag,
                value,
            ]
        )
        == 2
    )
    one_error_line(capsys, *words.split(", "))
    assert not (tmp_path / "out").exists()


def test_iforest_seed_is_checked_before_the_fit():
    # scikit-learn refused -1 inside the fit: a plug-in crash, exit 1, parameter not named
    frame = pd.DataFrame(
        {"t_s": np.arange(50.0), "meas.x": np.random.default_rng(0).normal(size=50)}
    )
    with pytest.raises(
        InputError,
        match="iforest: random_state must be null or an integer from 0 to 4294967295, got -1",
    ):
        registry.get("iforest")(random_state=-1).fit([frame])
    assert registry.get("iforest")(random_state=2**32 - 1).fit([frame]).threshold_ > 0


def test_check_param_converts_numbers_given_as_text():
    pca = registry.get("pca")
    assert registry.check_param(pca, "alpha", "1e-3") == 0.001  # YAML reads 1e-3 as text
    assert registry.check_param(pca, "n_components", 3) == 3
    assert registry.check_param(pca, "limits", "empirical") == "empirical"
    iforest = registry.get("iforest")
    assert registry.check_param(iforest, "random_state", None) is None
    with pytest.raises(InputError, match="an integer or null"):
        registry.check_param(iforest, "random_state", "x")
    with pytest.raises(InputError, match="expects a number for alpha, got True"):
        registry.check_param(pca, "alpha", True)


def test_bench_spec_param_of_the_wrong_type(tmp_path, capsys):
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        textwrap.dedent(f"""\
        name: bad
        studies:
          - name: s
            train: [{{scenario: {THESIS / "oc1_nominal.yaml"}, seeds: [1]}}]
            test: [{{scenario: {THESIS / "oc1_nominal.yaml"}, seeds: [2]}}]
        methods:
          - {{method: pca, params: {{n_components: banana}}}}
        """)
    )
    assert main(["bench", str(spec), "--workdir", str(tmp_path / "w")]) == 2
    one_error_line(capsys, spec, "methods[0].params.n_components", "a number")
    assert not (tmp_path / "w").exists() or not any((tmp_path / "w").iterdir())


# --------------------------------------------------------------------------- broken plug-ins

PLUGINS = """
import pandas as pd
from r2rsim.diagnostics import Diagnostic


class RaisesInFit(Diagnostic):
    name = "raises-fit"

    def fit(self, runs):
        raise RuntimeError("boom in fit\\nsecond line")


class RaisesInScore(Diagnostic):
    name = "raises-score"

    def fit(self, runs):
        self.threshold_ = 1.0
        return self

    def score(self, run):
        raise ZeroDivisionError("boom in score")


class NoStatistic(RaisesInScore):
    name = "no-statistic"

    def score(self, run):
        return pd.DataFrame({"x": 0.0}, index=run.index)


def not_a_class():
    pass


class NotADiagnostic:
    pass
"""

BROKEN = {
    "raises-fit": "rt_plugins:RaisesInFit",
    "raises-score": "rt_plugins:RaisesInScore",
    "no-statistic": "rt_plugins:NoStatistic",
    "broken-import": "rt_plugins_no_such_module:Thing",
    "not-a-class": "rt_plugins:not_a_class",
    "not-diagnostic": "rt_plugins:NotADiagnostic",
}


@pytest.fixture
def extra_plugins(tmp_path, monkeypatch):
    """The test plug-ins registered next to the real ones (in this process)."""
    (tmp_path / "rt_plugins.py").write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(tmp_path))
    real = registry.entry_points

    def eps(group):
        return [*real(group=group), *(EntryPoint(n, v, group) for n, v in BROKEN.items())]

    monkeypatch.setattr(registry, "entry_points", eps)
    yield
    sys.modules.pop("rt_plugins", None)


@pytest.mark.parametrize(
    "method, words",
    [
        ("raises-fit", ["plug-in 'raises-fit'", "fit raised RuntimeError: boom in fit"]),
        (
            "raises-score",
            ["plug-in 'raises-score'", "score (run ", "ZeroDivisionError: boom in score"],
        ),
        ("no-statistic", ["plug-in 'no-statistic'", "without a 'statistic' column"]),
        (
            "broken-import",
            [
                "plug-in 'broken-import'",
                "rt_plugins_no_such_module:Thing",
                "cannot be loaded",
                "ModuleNotFoundError",
            ],
        ),
        ("not-a-class", ["plug-in 'not-a-class'", "is not a class"]),
        ("not-diagnostic", ["plug-in 'not-diagnostic'", "not a subclass"]),
    ],
)
def test_broken_plugin_is_one_error_line(data, tmp_path, capsys, extra_plugins, method, words):
    assert diagnose(data, data / "f5", tmp_path / "out", method=method) == 1
    err = one_error_line(capsys, *words)
    assert "second line" not in err
    assert not (tmp_path / "out").exists()


def test_debug_shows_the_plugins_traceback(data, tmp_path, extra_plugins):
    with pytest.raises(PluginError) as info:
        diagnose(data, data / "f5", tmp_path / "out", "--debug", method="raises-fit")
    assert isinstance(info.value.__cause__, RuntimeError)  # the original, chained


def test_list_and_diagnose_survive_a_broken_plugin(data, tmp_path, capsys, extra_plugins):
    assert main(["list", "plugins", "--load"]) == 0  # every plug-in imported and checked
    out, err = capsys.readouterr()
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    assert {"residual", "pca", "dpca", "iforest", "raises-fit"} <= set(rows)
    assert "BROKEN" in rows["broken-import"] and "ModuleNotFoundError" in rows["broken-import"]
    assert "BROKEN" in rows["not-a-class"] and "BROKEN" not in rows["pca"]
    assert err.startswith("warning: 3 ") and "registered plug-ins cannot be loaded" in err
    # without --load, from the metadata and source: what is certain without importing (a
    # module that is not there); a name that is not a class shows only when loaded
    assert main(["list", "plugins"]) == 0
    out, err = capsys.readouterr()
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:-1]}
    assert {"residual", "pca", "dpca", "iforest", "raises-fit"} <= set(rows)
    assert "BROKEN" in rows["broken-import"] and "ModuleNotFoundError" in rows["broken-import"]
    assert "BROKEN" not in rows["pca"] and "BROKEN" not in rows["not-a-class"]
    assert err.startswith("warning: 1 registered plug-in cannot be loaded")
    assert set(registry.plugins()) >= {"pca", "raises-fit"}
    assert "broken-import" not in registry.plugins()
    assert diagnose(data, data / "f5", tmp_path / "out") == 0
    assert (tmp_path / "out" / "metrics.parquet").is_file()


def test_a_broken_installed_plugin_in_a_subprocess(data, tmp_path):
    """The same through a real dist-info on PYTHONPATH, as an installed package would be."""
    site = tmp_path / "site"
    site.mkdir()
    info = site / "rt_broken-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: rt-broken\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[r2rsim.diagnostics]\nbroken = rt_broken_missing_module:Detector\n"
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(site), env.get("PYTHONPATH")]))

    def cli(*args):
        return subprocess.run(
            [sys.executable, "-m", "r2rsim.cli", *map(str, args)],
            env=env,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
        )

    ls = cli("list", "plugins")
    assert ls.returncode == 0, ls.stderr
    assert "broken" in ls.stdout and "BROKEN" in ls.stdout and "pca" in ls.stdout
    assert "Traceback" not in ls.stderr
    ok = cli(
        "diagnose",
        "--method",
        "residual",
        "--train",
        data / "h1",
        "--test",
        data / "f5",
        "--n-boot",
        0,
        "-o",
        tmp_path / "out",
    )
    assert ok.returncode == 0, ok.stderr
    bad = cli(
        "diagnose",
        "--method",
        "broken",
        "--train",
        data / "h1",
        "--test",
        data / "f5",
        "--n-boot",
        0,
        "-o",
        tmp_path / "out2",
    )
    assert bad.returncode == 1 and "Traceback" not in bad.stderr
    assert "plug-in 'broken'" in bad.stderr and "ModuleNotFoundError" in bad.stderr
    assert not (tmp_path / "out2").exists()


# --------------------------------------------------------------------------- bench workdir


@pytest.fixture(scope="module")
def bench_spec(tmp_path_factory):
    d = tmp_path_factory.mktemp("robust_bench")
    spec = d / "spec.yaml"
    spec.write_text(
        textwrap.dedent(f"""\
        name: robust
        duration: {DURATION} s
        studies:
          - name: s
            train: [{{scenario: {THESIS / "oc1_nominal.yaml"}, seeds: [1]}}]
            test: [{{scenario: {THESIS / "sensor_a_offset_P15.yaml"}, seeds: [5]}}]
        methods:
          - {{method: residual}}
        evaluation: {{n_boot: 0}}
        """)
    )
    work = d / "work"
    assert main(["bench", str(spec), "--workdir", str(work), "-o", str(d / "r0")]) == 0
    return spec, work, pd.read_csv(d / "r0" / "results.csv")


def workdir_copy(bench_spec, tmp_path, prefix):
    """A copy of the bench's work directory, and the dataset in it named ``prefix__...``."""
    spec, work, _ = bench_spec
    work = shutil.copytree(work, tmp_path / "work")
    (ds,) = [p for p in work.iterdir() if p.name.startswith(f"{prefix}__")]
    return spec, work, ds


def test_bench_resimulates_a_corrupted_workdir_dataset(bench_spec, tmp_path, capsys):
    spec, work, faulty = workdir_copy(bench_spec, tmp_path, "sensor_a_offset_P15")
    before = bench_spec[2]
    capsys.readouterr()
    _truncated(samples_file(faulty))
    assert main(["bench", str(spec), "--workdir", str(work), "-o", str(tmp_path / "r1")]) == 0
    err = capsys.readouterr().err
    assert f"warning: bench workdir: dataset {faulty}" in err and "simulating it again" in err
    assert validate_dataset(faulty) == []
    after = pd.read_csv(tmp_path / "r1" / "results.csv")
    cols = ["study", "label", "condition", "fault", "metric", "value"]
    timing = ["fit_s", "exec_s_per_sim_h"]
    pd.testing.assert_frame_equal(
        after[~after.metric.isin(timing)][cols], before[~before.metric.isin(timing)][cols]
    )
    # an incomplete one (no manifest.json) is simulated again too
    (faulty / "manifest.json").unlink()
    assert main(["bench", str(spec), "--workdir", str(work)]) == 0
    assert "incomplete (no manifest.json)" in capsys.readouterr().err
    assert validate_dataset(faulty) == []


def test_bench_never_deletes_what_it_did_not_write(bench_spec, tmp_path, capsys):
    spec, work, ds = workdir_copy(bench_spec, tmp_path, "oc1_nominal")
    shutil.rmtree(ds)
    ds.mkdir()
    (ds / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["bench", str(spec), "--workdir", str(work)]) == 2
    one_error_line(capsys, ds, "is not an r2rsim dataset")
    assert (ds / "notes.txt").read_text() == "mine"


def test_bench_no_verify_uses_the_workdir_as_it_is(bench_spec, tmp_path, capsys):
    spec, work, healthy = workdir_copy(bench_spec, tmp_path, "oc1_nominal")
    _random_bytes(samples_file(healthy))
    capsys.readouterr()
    assert main(["bench", str(spec), "--workdir", str(work), "--no-verify"]) == 2
    one_error_line(capsys, f"dataset {healthy}", "not a readable Parquet file")
    assert main(["bench", str(spec), "--workdir", str(work)]) == 0  # verified: re-simulated
    assert validate_dataset(healthy) == []


# --------------------------------------------------------------------------- output directories


def test_diagnose_output_replaces_only_its_own_results(data, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.csv").write_text("my own notes\n")  # was replaced without a word
    assert diagnose(data, data / "f5", out) == 2
    one_error_line(
        capsys,
        f"output directory '{out}' exists and holds files r2rsim diagnose "
        "did not write (metrics.csv)",
        "choose another directory with -o",
    )
    assert [p.name for p in out.iterdir()] == ["metrics.csv"]
    assert (out / "metrics.csv").read_text() == "my own notes\n"
    (out / "metrics.csv").unlink()  # an empty directory is filled
    assert diagnose(data, data / "f5", out) == 0
    written = sorted(p.name for p in out.iterdir())
    assert written == ["datasets.json", "metrics.csv", "metrics.parquet", "predictions.parquet"]
    capsys.readouterr()
    # its own results, and a report of them: replaced with --overwrite (the report too)
    (out / "report.html").write_text(REPORT_MARKER + "\nof the earlier results")
    assert diagnose(data, data / "f5", out) == 2
    one_error_line(capsys, "holds earlier r2rsim diagnose results; pass --overwrite")
    assert diagnose(data, data / "f5", out, "--overwrite") == 0
    assert sorted(p.name for p in out.iterdir()) == written
    capsys.readouterr()
    # anything else there: never replaced, not even with --overwrite
    (out / "notes.txt").write_text("mine")
    assert diagnose(data, data / "f5", out, "--overwrite") == 2
    one_error_line(capsys, "did not write (notes.txt)")
    (out / "notes.txt").unlink()
    (out / "metrics.csv").write_text("metric,value\n")  # r2rsim's name, not its table
    assert diagnose(data, data / "f5", out, "--overwrite") == 2
    one_error_line(capsys, "did not write (metrics.csv)")
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no temporary directory left


def test_bench_output_replaces_only_its_own_results(bench_spec, tmp_path, capsys):
    spec, work, _ = bench_spec
    out = tmp_path / "res"
    out.mkdir()
    (out / "results.csv").write_text("my own notes\n")
    # refused before anything is simulated
    assert main(["bench", str(spec), "--workdir", str(tmp_path / "w"), "-o", str(out)]) == 2
    one_error_line(
        capsys,
        f"output directory '{out}' exists and holds files r2rsim bench did not write (results.csv)",
    )
    assert not (tmp_path / "w").exists()
    assert (out / "results.csv").read_text() == "my own notes\n"
    (out / "results.csv").unlink()
    assert main(["bench", str(spec), "--workdir", str(work), "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["results.csv", "results.parquet"]
    capsys.readouterr()
    assert main(["bench", str(spec), "--workdir", str(work), "-o", str(out)]) == 2
    one_error_line(capsys, "holds earlier r2rsim bench results; pass --overwrite")
    assert main(["bench", str(spec), "--workdir", str(work), "-o", str(out), "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["results.csv", "results.parquet"]
