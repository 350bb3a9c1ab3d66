"""The plug-in contract (docs/diagnostics.md §2.1) as checks a plug-in's author runs, the way
scikit-learn ships ``check_estimator``: r2rsim's own tests run :func:`check_plugin` on every
registered plug-in, and a third-party package runs the same function in its tests.

The checks call the plug-in as the harness does (a clone, the visible columns of each run,
the outputs checked by :meth:`r2rsim.evaluate.harness._Scored.outputs`), plus what the harness
cannot see in one evaluation: parameters stored untouched, nothing fitted before ``fit``,
inputs left unchanged, determinism, and no column an algorithm may not see.
"""

from __future__ import annotations

import copy
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from sklearn.base import clone

from ..dataset.read import Run, read_runs
from ..diagnostics.base import Diagnostic
from ..diagnostics.line import attach_line
from ..diagnostics.registry import get
from ..errors import InputError
from .harness import _Scored

#: prefixes of the columns no plug-in may learn from (drive data is allowed only under the
#: ``drive_data`` protocol)
HIDDEN = ("true.", "state.", "label.")
#: tolerance of the causality check (a statistic computed on a shorter frame may differ in
#: the last bits, e.g. through a different summation order)
CAUSAL_RTOL, CAUSAL_ATOL = 1e-7, 1e-9
#: the false-alarm rates at which calibrate is checked
CALIBRATION_ALPHAS = (0.01, 0.1)
DRIVE = ("act.", "cmd.", "ctrl.")

#: the line and scenario of :func:`example_runs`: an unwind, a load-cell idler, a pull roller
#: and a rewind; 20 s at 2 m/s, 50 Hz; the faulty run has a +20 N load-cell offset from 10 s
_LINE = {
    "name": "check_plugin_line",
    "web": {"material": "PET", "thickness": "50 um", "width": "1 m"},
    "elements": [
        {
            "id": "unwind",
            "type": "unwind",
            "roll": {"core_radius": "76 mm", "outer_radius": "0.3 m", "core_inertia": 0.5},
        },
        {"id": "idler1", "type": "idler", "radius": 0.05, "inertia": 0.011},
        {"id": "pull", "type": "driven", "radius": 0.1, "inertia": 0.2},
        {
            "id": "rewind",
            "type": "rewind",
            "roll": {"core_radius": "76 mm", "outer_radius": "0.1 m", "core_inertia": 0.5},
        },
    ],
    "spans": [{"length": "1.5 m"}, {"length": 1.0}, {"length": 1.0}],
    "sensors": [
        {"id": "lc", "type": "load_cell", "element": "idler1", "noise": "2 N"},
        {"id": "enc", "type": "encoder", "element": "pull", "noise": "0.05 rad/s"},
    ],
    "controllers": [
        {"id": "speed", "type": "speed_pi", "element": "pull", "master": True, "kp": 25, "ki": 790},
        {
            "id": "tens",
            "type": "tension_pi",
            "element": "unwind",
            "sensor": "lc",
            "setpoint": "200 N",
            "kp": 0.1,
            "ki": 0.5,
        },
    ],
}
_SCENARIO = {
    "line": "line.yaml",
    "duration": "20 s",
    "record_rate": "50 Hz",
    "warmup": "1 s",
    "initial": {"state": "steady"},
    "programme": [{"at": 0, "line_speed": "2 m/s"}],
}
_FAULT = {
    "id": "lc_offset",
    "type": "sensor.offset",
    "target": "lc",
    "onset": "10 s",
    "magnitude": "20 N",
}


def example_runs() -> tuple[list[Run], Run]:
    """Two healthy runs (seeds 1 and 2) and one with a load-cell offset (seed 3) of a small
    built-in line, simulated in a temporary directory: the default data of
    :func:`check_plugin`, with ``meas.*`` and ``sp.*`` channels (a load cell and an encoder).

    Returns
    -------
    train : list of Run
        The healthy runs.
    test : Run
        The faulty run (+20 N on the load cell from 10 s of 20 s).
    """
    from ..run import run_scenario

    runs = []
    with tempfile.TemporaryDirectory(prefix="r2rsim-check-") as tmp:
        d = Path(tmp)
        (d / "line.yaml").write_text(yaml.safe_dump(_LINE), encoding="utf-8")
        for seed, faults in ((1, []), (2, []), (3, [_FAULT])):
            scen = d / f"s{seed}.yaml"
            scen.write_text(
                yaml.safe_dump({**_SCENARIO, "seed": seed, "faults": faults}), encoding="utf-8"
            )
            run_scenario(scen, output=d / f"run{seed}")
            runs += read_runs(d / f"run{seed}", verify=False)  # samples are read in memory
    return runs[:2], runs[2]


def _fail(name: str, rule: str) -> AssertionError:
    return AssertionError(
        f"plug-in '{name}' breaks the contract (docs/diagnostics.md §2.1): {rule}"
    )


def check_plugin(
    plugin: str | type[Diagnostic],
    train: Sequence[Run] | None = None,
    test: Run | None = None,
    *,
    params: dict | None = None,
    drive_data: bool = False,
) -> list[str]:
    """Check a diagnostic plug-in against the contract the harness relies on.

    Parameters
    ----------
    plugin : str or type
        A registered name (``r2rsim list plugins``) or a :class:`Diagnostic` subclass.
    train : sequence of Run, optional
        Healthy runs to fit on (:func:`r2rsim.dataset.read.read_runs`); default: the two
        healthy runs of :func:`example_runs`. Give runs with the channels the plug-in
        ``requires`` when the small built-in line does not have them.
    test : Run, optional
        A run to score; default: the faulty run of :func:`example_runs`.
    params : dict, optional
        Constructor parameters; ``random_state=0`` is added where the plug-in has one.
    drive_data : bool
        The plug-in reads drive data (``act.*``, ``cmd.*``, ``ctrl.*``: the ``--drive-data``
        protocol): show it those columns and allow it to learn from them.

    Returns
    -------
    list of str
        The checks made, in order (all passed).

    Raises
    ------
    AssertionError
        At the first rule the plug-in breaks, naming the plug-in and the rule.
    InputError
        For a plug-in name that is not registered, or data without a column it requires.
    """
    cls = get(plugin) if isinstance(plugin, str) else plugin
    if not (isinstance(cls, type) and issubclass(cls, Diagnostic)):
        raise InputError(
            f"check_plugin: {plugin!r} is neither a registered plug-in name "
            f"nor a subclass of r2rsim.diagnostics.Diagnostic"
        )
    if train is None or test is None:
        default_train, default_test = example_runs()
        train = default_train if train is None else train
        test = default_test if test is None else test
    params = dict(params or {})
    if "random_state" in cls(**params).get_params():
        params.setdefault("random_state", 0)
    name = getattr(cls, "name", None) or cls.__name__
    checks = _CheckRun(cls, name, params, list(train), test, drive_data)
    return checks.all()


class _CheckRun:
    """One plug-in, its data and the checks in the order they build on each other."""

    def __init__(self, cls, name, params, train, test, drive_data) -> None:
        self.cls, self.name, self.params = cls, name, params
        self.train, self.test, self.drive_data = train, test, drive_data
        self.frames = [attach_line(r.visible(drive_data), r) for r in train]
        self.frame = attach_line(test.visible(drive_data), test)
        self.done: list[str] = []

    def all(self) -> list[str]:
        est = self.cls(**self.params)
        self.stores_parameters_only(est)
        self.refuses_to_score_unfitted(est)
        scores = self.fits_and_scores(est)
        self.outputs_as_the_harness_checks(est)
        self.is_deterministic(scores)
        self.learns_only_visible_columns(est)
        self.is_causal_as_declared(est, scores)
        self.calibrates_its_own_threshold()
        self.refuses_data_without_its_columns()
        return self.done

    def _ok(self, check: str) -> None:
        self.done.append(check)

    def stores_parameters_only(self, est) -> None:
        rule = (
            "__init__ must store each parameter under its own name and do nothing else "
            "(clone(est) must round-trip get_params())"
        )
        try:
            same = clone(est).get_params() == est.get_params()
        except RuntimeError as exc:  # scikit-learn's clone checks this too
            raise _fail(self.name, f"{rule}: {exc}") from None
        if not same:
            raise _fail(self.name, rule)
        fitted = [k for k in vars(est) if k.endswith("_") and not k.startswith("_")]
        if fitted:
            raise _fail(
                self.name,
                f"__init__ set fitted attributes {fitted}; only fit sets attributes ending in '_'",
            )
        self._ok("__init__ stores its parameters only (clone round-trips them)")

    def refuses_to_score_unfitted(self, est) -> None:
        try:
            est.score(self.frame)
        except RuntimeError as exc:
            if "not fitted" in str(exc):
                self._ok("score before fit raises RuntimeError('... not fitted ...')")
                return
            raise _fail(
                self.name,
                f"score before fit raised RuntimeError({exc}) without "
                f"'not fitted' (self._check_fitted() says so)",
            ) from None
        except Exception as exc:  # noqa: BLE001 - any other exception breaks the rule
            raise _fail(
                self.name,
                f"score before fit raised {type(exc).__name__}, not "
                f"RuntimeError('... not fitted ...')",
            ) from None
        raise _fail(
            self.name,
            "score before fit returned; it must raise "
            "RuntimeError('... not fitted ...') (self._check_fitted())",
        )

    def fits_and_scores(self, est) -> pd.DataFrame:
        before = [f.copy() for f in self.frames] + [self.frame.copy()]
        if est.fit(self.frames) is not est:
            raise _fail(self.name, "fit must return self")
        scores = est.score(self.frame)
        for f, b in zip([*self.frames, self.frame], before, strict=True):
            if not f.equals(b):
                raise _fail(
                    self.name,
                    "fit and score must leave the frames they are given "
                    "unchanged (copy before changing them)",
                )
        if not isinstance(scores, pd.DataFrame) or "statistic" not in scores.columns:
            raise _fail(self.name, "score must return a DataFrame with a 'statistic' column")
        if not scores.index.equals(self.frame.index):
            raise _fail(
                self.name,
                "score must return one row per sample, indexed like the run's samples (index k)",
            )
        alarms = est.decide(scores)
        if not (
            isinstance(alarms, pd.Series)
            and alarms.dtype == bool
            and alarms.index.equals(scores.index)
        ):
            raise _fail(self.name, "decide must return a boolean Series indexed like the scores")
        self._ok(
            "fit returns self; score and decide are aligned to the samples; the "
            "inputs are left unchanged"
        )
        return scores

    def outputs_as_the_harness_checks(self, est) -> None:
        scored = _Scored(est, self.drive_data)
        scored.est = est  # the fitted estimator, not a fresh clone
        ranking = scored.outputs(self.test, rank=True)[3]
        if ranking is not None:
            names = pd.unique(ranking.to_numpy().ravel())
            meas = {c for c in self.frame.columns if c.startswith("meas.")}
            bad = [n for n in names if isinstance(n, str) and n not in meas]
            if not ranking.index.equals(self.frame.index) or bad:
                raise _fail(
                    self.name,
                    "rank_channels must return a frame indexed like the "
                    "scores whose entries are meas. channels of the run or None"
                    + (f" (got {bad[:3]})" if bad else ""),
                )
        self._ok("the harness accepts its outputs (statistic, decide, diagnose, rank_channels)")

    def is_deterministic(self, scores: pd.DataFrame) -> None:
        again = self.cls(**copy.deepcopy(self.params)).fit(self.frames).score(self.frame)
        try:
            pd.testing.assert_frame_equal(scores, again)
        except AssertionError:
            raise _fail(
                self.name,
                "two fits with the same parameters must give the same "
                "scores (take randomness from a random_state parameter)",
            ) from None
        self._ok("deterministic (random_state=0 where it has one)")

    def learns_only_visible_columns(self, est) -> None:
        hidden = HIDDEN + (() if self.drive_data else DRIVE)
        seen = [c for c in getattr(est, "columns_", []) if str(c).startswith(hidden)]
        if seen:
            raise _fail(self.name, f"columns_ holds columns an algorithm may not see: {seen[:3]}")
        self._ok("learns only visible columns")

    def is_causal_as_declared(self, est, scores: pd.DataFrame) -> None:
        """A plug-in that declares itself causal gives, on a run cut after sample k, the
        statistic it gives on the whole run at samples 0..k."""
        if not est.is_causal():
            self._ok("declares itself offline (causal False): not checked for causality")
            return
        full = scores["statistic"].to_numpy(float)
        n = len(self.frame)
        for k in sorted({n // 4, n // 2, (3 * n) // 4} - {0}):
            cut = est.score(self.frame.iloc[:k])["statistic"].to_numpy(float)
            if cut.shape != (k,) or not np.allclose(
                cut, full[:k], rtol=CAUSAL_RTOL, atol=CAUSAL_ATOL, equal_nan=True
            ):
                bad = (
                    int(
                        np.flatnonzero(
                            ~np.isclose(
                                cut, full[:k], rtol=CAUSAL_RTOL, atol=CAUSAL_ATOL, equal_nan=True
                            )
                        )[0]
                    )
                    if cut.shape == (k,)
                    else 0
                )
                raise _fail(
                    self.name,
                    f"it declares itself causal (its statistic at t uses "
                    f"samples up to t only), but scoring the run cut after sample "
                    f"{k} changes the statistic at sample {bad}: read no later "
                    f"samples, or declare causal = False (an offline method)",
                )
        self._ok(
            "causal as declared: the statistic up to t does not change when later samples are cut"
        )

    def calibrates_its_own_threshold(self) -> None:
        """After ``calibrate(runs, alpha, masks)`` on healthy runs, its own alarms on those
        runs hold the false-alarm rate alpha (the masked samples only)."""
        est = self.cls(**copy.deepcopy(self.params)).fit(self.frames)
        runs = [*self.frames, self.frame.iloc[: len(self.frame) // 2]]
        masks = [np.arange(len(f)) >= len(f) // 10 for f in runs]
        for alpha in CALIBRATION_ALPHAS:
            if est.calibrate(runs, alpha, masks) is not est:
                raise _fail(self.name, "calibrate must return self")
            alarms = np.concatenate(
                [
                    np.asarray(est.decide(est.score(f)), dtype=bool)[m]
                    for f, m in zip(runs, masks, strict=True)
                ]
            )
            if alarms.mean() > alpha + 1e-12:
                raise _fail(
                    self.name,
                    f"after calibrate(runs, alpha={alpha}) its own alarms "
                    f"flag {alarms.mean():.4f} of those runs' masked samples, more "
                    f"than alpha: calibrate must move the threshold its decide uses",
                )
        self._ok("calibrate(runs, alpha, masks) makes its own alarms hold alpha on those runs")

    def refuses_data_without_its_columns(self) -> None:
        try:
            self.cls(**self.params).fit([self.frames[0][["t_s"]]])
        except InputError as exc:
            if "no column matching" in exc.message:
                self._ok(
                    "fit on data without its columns raises InputError('no column matching ...')"
                )
                return
            raise _fail(
                self.name,
                f"fit without its columns raised InputError({exc.message})"
                f"; use self.required_columns(frame), which names the pattern",
            ) from None
        except Exception as exc:  # noqa: BLE001
            raise _fail(
                self.name,
                f"fit without its columns raised {type(exc).__name__}; "
                f"call self.required_columns(frame) in fit",
            ) from None
        raise _fail(
            self.name,
            "fit on a frame with only t_s must raise InputError('no "
            "column matching ...') (self.required_columns(frame))",
        )
