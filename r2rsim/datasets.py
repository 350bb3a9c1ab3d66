"""The canonical benchmark datasets, generated on first use into a cache directory.

Like :mod:`sklearn.datasets`, one call gives the data and its split::

    from r2rsim import datasets
    data = datasets.load_first_benchmark()
    data.split.train          # fault-free runs to fit on
    data.split.test[0].samples  # a test run's samples (pandas.DataFrame)

The datasets are not downloaded: r2rsim simulates them from the sweep files in its source
tree, the first time they are asked for, into :func:`get_data_home` (one directory per
dataset). The same seeds give the same bytes, so every copy of a dataset is the same data.
Later calls reuse the cache: the sweep is reopened (a sweep file changed since, or a new
r2rsim version, simulates the runs it changes), and every file read is checked against the
sizes and sha256 of the dataset's ``manifest.json`` and every run's labels against its
``faults.parquet``, as ``r2rsim diagnose`` reads a dataset. An interrupted generation
continues where it stopped on the next call.

The datasets (:data:`DATASETS`):

* :func:`load_first_benchmark`: the registration process in OC1 and OC2, fault-free and with
  three fault families, 40 runs of 20 s (about 10 s of CPU to generate).
* :func:`load_thesis_realistic`: the calibrated thesis set, the healthy sweep and the 42
  sensor-fault cases, 300 runs of 300 s (about 5 min of CPU to generate; the runs of a study
  take about 8 GB of memory once read).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import InputError

if TYPE_CHECKING:
    from .evaluate.splits import Split

__all__ = [
    "BenchmarkData",
    "DATASETS",
    "get_data_home",
    "load_first_benchmark",
    "load_thesis_realistic",
]

#: the environment variable that moves the cache (as ``data_home=`` does for one call)
DATA_HOME_ENV = "R2RSIM_DATA"

#: name -> (the file it is made from, relative to the source tree; what it is)
DATASETS = {
    "first_benchmark": (
        "sweeps/first_benchmark.yaml",
        "registration process, OC1/OC2, fault-free and three fault families, "
        "5 seeds: 40 runs of 20 s, split by seed",
    ),
    "thesis_realistic": (
        "benchmarks/thesis_realistic.yaml",
        "the calibrated thesis set (healthy and sensor-fault sweeps of "
        "scenarios/thesis_realistic/), split as a study of the benchmark "
        "spec",
    ),
}
#: the studies of benchmarks/thesis_realistic.yaml
THESIS_STUDIES = ("local", "global", "global_products")


@dataclass
class BenchmarkData:
    """A canonical dataset: its runs and their split.

    Attributes
    ----------
    name : str
        The dataset's name (a key of :data:`DATASETS`).
    split : r2rsim.evaluate.splits.Split
        ``train`` (fault-free runs to fit on), ``val`` (fault-free runs to calibrate a
        threshold on) and ``test`` (every faulty run and the other fault-free ones).
    paths : list of Path
        The dataset directories in the cache.
    description : str
    """

    name: str
    split: Split
    paths: list[Path] = field(default_factory=list)
    description: str = ""

    @property
    def runs(self) -> list:
        """Every run, train, val and test in that order (:class:`r2rsim.dataset.read.Run`)."""
        return [*self.split.train, *self.split.val, *self.split.test]

    def __repr__(self) -> str:
        return f"BenchmarkData({self.name!r}: {self.split.describe()})"


def get_data_home(data_home: str | os.PathLike | None = None) -> Path:
    """The directory the datasets are generated into.

    Parameters
    ----------
    data_home : str or path-like, optional
        Used as given. Default: the environment variable ``R2RSIM_DATA``, else
        ``$XDG_CACHE_HOME/r2rsim/datasets``, else ``~/.cache/r2rsim/datasets``.

    Returns
    -------
    Path
        The directory (created if missing).
    """
    if data_home is None:
        data_home = os.environ.get(DATA_HOME_ENV)
    if data_home is None:
        cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
        data_home = Path(cache) / "r2rsim" / "datasets"
    path = Path(data_home).expanduser()
    path.mkdir(parents=True, exist_ok=True)
    return path


def _source_file(name: str) -> Path:
    """The shipped file a dataset is made from; an error if r2rsim is not installed from its
    source tree (the sweep files are not part of the package)."""
    rel = DATASETS[name][0]
    path = Path(__file__).resolve().parent.parent / rel
    if not path.is_file():
        raise InputError(
            f"dataset {name!r} is generated from {rel} of r2rsim's source tree, "
            f"which is not next to this installation ({path.parent.parent}); "
            f"install r2rsim from a checkout: pip install -e ."
        )
    return path


def _announce(name: str, where: Path, quiet: bool) -> None:
    if not quiet:
        print(
            f"r2rsim.datasets: {name}: simulating what is not yet in {where} (first use only)",
            file=sys.stderr,
        )


def load_first_benchmark(
    *, data_home: str | os.PathLike | None = None, workers: int | None = None, quiet: bool = False
) -> BenchmarkData:
    """The first benchmark: a small labelled sweep, generated on first use.

    The registration process of the calibrated thesis set (realistic sensors, process
    disturbances, run-to-run variability) in two operating conditions (OC1 0.5 m/s and
    130 N, OC2 1.0 m/s and 160 N), fault-free and with a sensor offset (sensor A), a sensor
    gain (sensor B, in the registration loop) and a draw error (registration roller), 5 seeds
    each: 40 runs of 20 s, faults from 10 s (``sweeps/first_benchmark.yaml``). The same data
    as ``r2rsim sweep sweeps/first_benchmark.yaml``.

    Parameters
    ----------
    data_home : str or path-like, optional
        The cache directory (:func:`get_data_home`).
    workers : int, optional
        Worker processes when it is generated (default: as ``r2rsim sweep``).
    quiet : bool
        Say nothing on stderr when it is generated.

    Returns
    -------
    BenchmarkData
        Split as ``r2rsim diagnose --data`` splits it (:func:`r2rsim.evaluate.splits.
        split_by_seed`): every faulty run is a test run; the fault-free runs of each
        condition go 60/20/20 to train, val and test.

    Raises
    ------
    r2rsim.InputError
        If the cached dataset fails its checks (a file differs from its manifest.json) or
        the sweep file is not there (r2rsim not installed from its source tree).
    """
    from .dataset.read import read_runs
    from .evaluate.splits import split_by_seed
    from .sweep import run_sweep

    name = "first_benchmark"
    sweep = _source_file(name)
    out = get_data_home(data_home) / name
    if not (out / "manifest.json").is_file():
        _announce(name, out, quiet)
    summary = run_sweep(sweep, output=out, workers=workers)
    if not summary.ok:
        raise InputError(
            f"dataset {name!r}: {summary.failed + summary.skipped_failed} run(s) "
            f"of {sweep} failed in {out}"
        )
    try:
        runs = read_runs(out)
    except InputError as exc:  # the cache was changed after r2rsim wrote it
        raise InputError(
            f"{exc.message}; the cached dataset {out} is not what r2rsim wrote: "
            f"delete it to generate it again"
        ) from exc
    split = split_by_seed(runs)
    return BenchmarkData(name, split, [out], DATASETS[name][1])


def load_thesis_realistic(
    study: str = "global", *, data_home: str | os.PathLike | None = None, quiet: bool = False
) -> BenchmarkData:
    """The calibrated thesis set, split as one study of ``benchmarks/thesis_realistic.yaml``.

    The registration process with realistic sensors, disturbances and run-to-run
    variability: the healthy sweep (OC1, OC2, OC3 and a second product P2, 20 seeds, 80 runs
    of 300 s) and the sensor-fault sweep (42 cases in OC1 and OC2 and a fault-free case in
    each, 5 seeds, 220 runs of 300 s); with ``global_products`` also the faults of P2.
    Generated on first use, into the same directories ``r2rsim bench
    benchmarks/thesis_realistic.yaml --workdir DATA_HOME/thesis_realistic`` uses. Measured on
    the 2-core development machine while it also ran other work (load average 3): the first
    call of the ``global`` study took 7 min of wall time and 5.4 min of CPU, a later one 26 s
    (reading and checking 260 runs); the runs held 8.3 GB of memory.

    Parameters
    ----------
    study : {"local", "global", "global_products"}
        ``local``: train and val on healthy OC1, test on healthy runs of every condition.
        ``global``: train and val on healthy OC1 and OC2 (seeds 1-10 and 11-15), test on their
        seeds 16-20 and the fault sweep. ``global_products``: the same with product P2.
    data_home : str or path-like, optional
        The cache directory (:func:`get_data_home`).
    quiet : bool
        Say nothing on stderr when it is generated.

    Returns
    -------
    BenchmarkData

    Raises
    ------
    r2rsim.InputError
        For an unknown study, a cached dataset that fails its checks, or r2rsim not installed
        from its source tree.
    """
    name = "thesis_realistic"
    if study not in THESIS_STUDIES:
        raise InputError(f"unknown study {study!r} of {name}; one of {', '.join(THESIS_STUDIES)}")
    return _load_study(name, _source_file(name), study, get_data_home(data_home) / name, quiet)


def _load_study(
    name: str, spec_path: Path, study: str, workdir: Path, quiet: bool
) -> BenchmarkData:
    """The runs of one study of a benchmark spec, simulated into ``workdir`` or reused from
    it exactly as ``r2rsim bench SPEC --workdir WORKDIR`` does."""
    from .bench import load_spec, study_runs
    from .evaluate.splits import Split

    spec = load_spec(spec_path)
    chosen = next((s for s in spec.studies if s.name == study), None)
    if chosen is None:
        raise InputError(f"{spec_path}: no study {study!r}")
    workdir.mkdir(parents=True, exist_ok=True)
    if not any(workdir.iterdir()):
        _announce(name, workdir, quiet)
    roles = study_runs(
        spec_path,
        spec,
        chosen,
        workdir,
        log=(lambda m: None) if quiet else (lambda m: print(m, file=sys.stderr)),
    )
    paths = sorted({r.path for runs in roles.values() for r in runs})
    return BenchmarkData(
        name,
        Split(roles["train"], roles["val"], roles["test"], study),
        paths,
        DATASETS.get(name, ("", ""))[1],
    )
