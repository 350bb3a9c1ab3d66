"""The ``parity`` plug-in configured from the run's line (issue 35 items 1 and 2): roles
inferred on both shipped registration lines, the preset, the one-line refusals of a wrong,
missing or ambiguous role and of data without a line, the loud mismatch between the fitted
line and a scored one, and an end-to-end evaluation on the second line with the defaults."""

from __future__ import annotations

import copy
import json
import warnings

import numpy as np
import pandas as pd
import pytest
import yaml

from r2rsim import run_scenario
from r2rsim.dataset.read import read_runs
from r2rsim.diagnostics.base import _frame
from r2rsim.diagnostics.line import LINE_ATTR
from r2rsim.diagnostics.parity import ParitySpaceDetector, find_roles
from r2rsim.diagnostics.registry import get
from r2rsim.errors import InputError
from r2rsim.evaluate.harness import evaluate
from r2rsim.schema.loader import load_line, read_yaml

from conftest import REPO

REG = REPO / "lines" / "registration_realistic.yaml"
SECOND = REPO / "lines" / "second_registration_line.yaml"

THESIS_ROLES = {
    "span": "registration",
    "drive": "reg_drive",
    "downstream": "reg_idler",
    "pitch_sensor": "sensor_B",
    "load_cell": "sensor_A",
    "upstream_load_cell": "lc_unwind",
    "drive_encoder": "u_drive",
    "downstream_encoder": "u_out",
}
SECOND_ROLES = {
    "span": "print_span",
    "drive": "infeed",
    "downstream": "print_idler",
    "pitch_sensor": "sensor_B",
    "load_cell": "sensor_A",
    "upstream_load_cell": "lc_infeed",
    "drive_encoder": "enc_infeed",
    "downstream_encoder": "enc_print_idler",
}
THESIS_COLUMNS = {
    "sensor_a": "meas.sensor_A.tension_N",
    "sensor_b": "meas.sensor_B.pitch_m",
    "drive_speed": "meas.u_drive.speed_rad_s",
    "downstream_speed": "meas.u_out.speed_rad_s",
    "upstream_tension": "meas.lc_unwind.tension_N",
}
NUMBERS = {
    "web_EA_N": 112.5e3,
    "span_length_m": 1.5,
    "drive_radius_m": 0.10,
    "downstream_radius_m": 0.05,
}


def _mapping(path=REG) -> dict:
    return read_yaml(path)


def _with_line(frame, mapping):
    """A copy of ``frame`` carrying ``mapping`` as its run's line."""
    f = frame.copy()
    f.attrs = {LINE_ATTR: json.dumps(mapping, default=str)}
    return f


def _empty(mapping):
    return _with_line(pd.DataFrame({"t_s": [0.0]}), mapping)


def _sensor(mapping, sid):
    return next(s for s in mapping["sensors"] if s["id"] == sid)


@pytest.mark.parametrize(
    "path, roles, closed",
    [
        (
            REG,
            THESIS_ROLES,
            {
                "web_EA_N": 4.5e9 * 50e-6 * 0.5,
                "span_length_m": 1.5,
                "relaxed_pitch_m": 0.25,
                "drive_radius_m": 0.10,
                "downstream_radius_m": 0.05,
            },
        ),
        (
            SECOND,
            SECOND_ROLES,
            {
                "web_EA_N": 6e9 * 80e-6 * 0.8,
                "span_length_m": 2.0,
                "relaxed_pitch_m": 0.3175,
                "drive_radius_m": 0.125,
                "downstream_radius_m": 0.06,
            },
        ),
    ],
)
def test_roles_and_numbers_are_inferred_from_the_line(path, roles, closed):
    assert find_roles(load_line(path)) == roles
    est = ParitySpaceDetector().configure([_empty(_mapping(path))])
    assert est.roles_ == roles
    assert est.line_numbers_ == pytest.approx(closed, rel=1e-12)
    ph = {k: v for k, v in closed.items() if k != "relaxed_pitch_m"}
    assert {k: est.physical_[k] for k in ph} == pytest.approx(ph, rel=1e-12)
    assert est.physical_["relaxed_pitch_m"] is None  # calibrated by fit
    assert est.sources_ == {
        "web_EA_N": "line",
        "span_length_m": "line",
        "relaxed_pitch_m": "calibrated",
        "drive_radius_m": "line",
        "downstream_radius_m": "line",
    }
    assert est.columns_ == {
        "sensor_a": f"meas.{roles['load_cell']}.tension_N",
        "sensor_b": f"meas.{roles['pitch_sensor']}.pitch_m",
        "drive_speed": f"meas.{roles['drive_encoder']}.speed_rad_s",
        "downstream_speed": f"meas.{roles['downstream_encoder']}.speed_rad_s",
        "upstream_tension": f"meas.{roles['upstream_load_cell']}.tension_N",
    }


def test_preset_explicit_numbers_and_columns():
    # the thesis ids without a line: the numbers must then be given
    est = ParitySpaceDetector(preset="thesis_registration", **NUMBERS).configure(
        [pd.DataFrame({"t_s": [0.0]})]
    )
    assert est.roles_ == THESIS_ROLES and est.columns_ == THESIS_COLUMNS
    assert set(est.sources_.values()) == {"parameter", "calibrated"}
    # on the thesis line the preset names what inference finds
    assert (
        ParitySpaceDetector(preset="thesis_registration").configure([_empty(_mapping())]).roles_
        == THESIS_ROLES
    )
    # the preset's ids are checked against the line
    with pytest.raises(InputError) as e:
        ParitySpaceDetector(preset="thesis_registration").configure([_empty(_mapping(SECOND))])
    assert e.value.message == (
        "parity: span 'registration' is not a span of the line "
        "(spans: span1, span2, span3, span4, print_span, span6, span7)"
    )
    # a role given overrides the preset and inference; explicit numbers and columns the line
    est = ParitySpaceDetector(
        load_cell="lc_unwind", span_length_m=1.25, drive_speed="meas.x.speed_rad_s"
    ).configure([_empty(_mapping())])
    assert est.roles_["load_cell"] == "lc_unwind"
    assert est.columns_["sensor_a"] == "meas.lc_unwind.tension_N"
    assert est.columns_["drive_speed"] == "meas.x.speed_rad_s"
    assert est.physical_["span_length_m"] == 1.25
    assert est.sources_["span_length_m"] == "parameter"
    with pytest.raises(InputError, match="preset must be one of thesis_registration or null"):
        ParitySpaceDetector(preset="thesis").configure([_empty(_mapping())])


def _no_pitch(m):
    m["sensors"] = [s for s in m["sensors"] if s["type"] != "pitch_length"]
    m["controllers"] = [c for c in m.get("controllers", []) if c.get("sensor") != "sensor_B"]


def _two_pitch(m):
    m["sensors"].append({**copy.deepcopy(_sensor(m, "sensor_B")), "id": "camera_2"})


def _no_load_cell(m):
    m["sensors"] = [s for s in m["sensors"] if s["id"] != "sensor_A"]


@pytest.mark.parametrize(
    "edit, params, message",
    [
        (
            _no_pitch,
            {},
            "parity: pitch_sensor: the line has no pitch-length sensor, needed for "
            "the pitch y_B (pitch-length sensors: none); name one with "
            "pitch_sensor=<id>",
        ),
        (
            _two_pitch,
            {},
            "parity: pitch_sensor: the line has 2 pitch-length sensors (sensor_B on "
            "registration, camera_2 on registration); name one with "
            "pitch_sensor=<id>",
        ),
        (
            None,
            {"drive": "reg_driver"},
            "parity: drive 'reg_driver' is not a roller of the line "
            "(rollers: in_idler, reg_drive, reg_idler)",
        ),
        (
            None,
            {"span": "print_span"},
            "parity: span 'print_span' is not a span of the line "
            "(spans: span1, span2, registration, span4)",
        ),
        (
            None,
            {"load_cell": "u_out"},
            "parity: load_cell 'u_out' is not a load cell of the line "
            "(load cells: lc_unwind, sensor_A)",
        ),
        (
            None,
            {"drive_encoder": "sensor_A"},
            "parity: drive_encoder 'sensor_A' is not an encoder "
            "of the line (encoders: u_drive, u_in, u_out)",
        ),
        (
            _no_load_cell,
            {},
            "parity: load_cell: the line has no load cell on the downstream roller "
            "'reg_idler', needed for the span tension y_A (load cells: lc_unwind "
            "on in_idler); name one with load_cell=<id>",
        ),
    ],
)
def test_a_wrong_missing_or_ambiguous_role_is_one_line(edit, params, message):
    m = _mapping()
    if edit is not None:
        edit(m)
    with pytest.raises(InputError) as e:
        ParitySpaceDetector(**params).configure([_empty(m)])
    assert e.value.message == message
    assert "\n" not in e.value.format()


def test_no_line_and_no_numbers_is_refused():
    frame = pd.DataFrame({"t_s": [0.0]})
    with pytest.raises(InputError) as e:
        ParitySpaceDetector().configure([frame])
    assert e.value.message == (
        "parity: the frames carry no line and line= is not given, so nothing gives web_EA_N, "
        "span_length_m, drive_radius_m, downstream_radius_m, sensor_a, sensor_b, drive_speed, "
        "downstream_speed, upstream_tension: give line=<line file>, or "
        "preset=thesis_registration with web_EA_N, span_length_m, drive_radius_m and "
        "downstream_radius_m, or those numbers with the columns sensor_a, sensor_b, "
        "drive_speed, downstream_speed and upstream_tension"
    )
    with pytest.raises(InputError, match=r"nothing gives span_length_m: give line="):
        ParitySpaceDetector(
            preset="thesis_registration", **{**NUMBERS, "span_length_m": None}
        ).configure([frame])
    # line= stands in for the frames' line
    est = ParitySpaceDetector(line=str(REG)).configure([frame])
    assert est.roles_ == THESIS_ROLES and est.physical_["span_length_m"] == 1.5


# ---- fitted on thesis-line runs ---------------------------------------------------------------


@pytest.fixture(scope="module")
def thesis_runs(tmp_path_factory):
    """Three healthy 20 s runs of the calibrated registration line in OC1 (seeds 1-3)."""
    d = tmp_path_factory.mktemp("parity_line")
    base = yaml.safe_load(
        (REPO / "scenarios" / "thesis_realistic" / "registration.yaml").read_text(encoding="utf-8")
    )
    sc = {**base, "line": str(REG), "duration": "20 s"}
    (d / "oc1.yaml").write_text(yaml.safe_dump(sc), encoding="utf-8")
    out = []
    for seed in (1, 2, 3):
        run_scenario(d / "oc1.yaml", output=d / f"s{seed}", seed=seed)
        out.append(read_runs(d / f"s{seed}")[0])
    return out


@pytest.fixture(scope="module")
def fitted(thesis_runs):
    return ParitySpaceDetector().fit(thesis_runs[:2])


def test_defaults_configure_from_the_runs_line(fitted, thesis_runs):
    est = fitted
    assert est.roles_ == THESIS_ROLES and est.columns_ == THESIS_COLUMNS
    assert {k: est.physical_[k] for k in NUMBERS} == pytest.approx(NUMBERS, rel=1e-12)
    assert est.sources_["relaxed_pitch_m"] == "calibrated"
    # the same model as with the thesis numbers and columns given explicitly
    ref = ParitySpaceDetector(**NUMBERS, **THESIS_COLUMNS).fit(
        [r.visible() for r in thesis_runs[:2]]
    )
    assert np.allclose(est.omega_, ref.omega_, rtol=1e-9, atol=1e-12)
    assert est.threshold_ == pytest.approx(ref.threshold_, rel=1e-9)
    assert set(ref.sources_.values()) == {"parameter", "calibrated"}
    scores = est.score(thesis_runs[2])
    assert np.isfinite(scores["statistic"]).any()


def _scored(run, edit):
    m = json.loads(_frame(run).attrs[LINE_ATTR])
    edit(m)
    return _with_line(run.visible(), m)


def _set(path, value):
    def edit(m):
        if path[0] == "elements" or path[0] == "spans" or path[0] == "sensors":
            item = next(x for x in m[path[0]] if x.get("id") == path[1])
            if len(path) == 4:
                item[path[2]][path[3]] = value
            else:
                item[path[2]] = value
        else:
            m[path[0]][path[1]] = value

    return edit


def test_a_different_line_is_refused_at_score(fitted, thesis_runs):
    run = thesis_runs[2]
    for edit, message in (
        (
            _set(("spans", "registration", "length"), "2 m"),
            "parity: the scored run's line has span_length_m 2 m where the model was fitted "
            "with 1.5 m (span 'registration'): fit on data of this line",
        ),
        (
            _set(("elements", "reg_idler", "radius"), "60 mm"),
            "parity: the scored run's line has downstream_radius_m 0.06 m where the model was "
            "fitted with 0.05 m (downstream 'reg_idler'): fit on data of this line",
        ),
        (
            _set(("web", "thickness"), "75 um"),
            "parity: the scored run's line has web_EA_N 168750 N where the model was fitted "
            "with 112500 N (the web's modulus x thickness x width): fit on data of this line",
        ),
        (
            _no_load_cell,
            "parity: the scored run's line does not have the fitted roles: load_cell "
            "'sensor_A' is not a load cell of the line (load cells: lc_unwind): fit on data "
            "of this line",
        ),
    ):
        with pytest.raises(InputError) as e:
            fitted.score(_scored(run, edit))
        assert e.value.message == message
    # calibrate goes through score: refused the same way
    with pytest.raises(InputError, match="span_length_m 2 m"):
        copy.deepcopy(fitted).calibrate(
            [_scored(run, _set(("spans", "registration", "length"), "2 m"))], 0.01
        )


def test_a_different_relaxed_pitch_or_an_explicit_number_only_warns(fitted, thesis_runs):
    run = thesis_runs[2]
    edit = _set(("sensors", "sensor_B", "relaxed_pitch_law", "q0"), "0.26 m")
    with pytest.warns(
        UserWarning,
        match=r"parity: the scored run's line has relaxed_pitch_m "
        r"0.26 m where the model was fitted with 0.25 m "
        r"\(pitch_sensor 'sensor_B'\): the relaxed pitch is "
        r"calibrated",
    ):
        fitted.score(_scored(run, edit))
    est = ParitySpaceDetector(span_length_m=1.5).fit(thesis_runs[:2])
    assert est.sources_["span_length_m"] == "parameter"
    with pytest.warns(
        UserWarning,
        match=r"span_length_m 2 m where the model was fitted with "
        r"1.5 m \(span 'registration'\); span_length_m was "
        r"given as a parameter, which is used",
    ):
        est.score(_scored(run, _set(("spans", "registration", "length"), "2 m")))
    with warnings.catch_warnings():  # the same line: silent
        warnings.simplefilter("error")
        fitted.score(run)


# ---- end to end on the second line -----------------------------------------------------------


def test_defaults_detect_a_sensor_a_offset_on_the_second_line(tmp_path):
    """30 s runs of the second line in L1: two healthy to train, one to calibrate, a healthy
    one and a sensor-A offset of +10 % from 15 s to test; parity without any parameter."""
    base = yaml.safe_load(
        (REPO / "scenarios" / "second_line" / "production.yaml").read_text(encoding="utf-8")
    )
    base["line"] = str(SECOND)
    fault = [
        {
            "id": "a_offset",
            "type": "sensor.offset",
            "target": "sensor_A",
            "onset": "15 s",
            "magnitude": "20 N",
        }
    ]
    runs = {}
    for seed in range(1, 6):
        scen = {**base, "seed": seed, "faults": fault if seed == 5 else []}
        (tmp_path / f"s{seed}.yaml").write_text(yaml.safe_dump(scen), encoding="utf-8")
        out = run_scenario(
            tmp_path / f"s{seed}.yaml", tmp_path / f"run{seed}", duration=30.0
        ).output
        runs[seed] = read_runs(out, verify=False)[0]
    ev = evaluate(
        get("parity")(),
        [runs[1], runs[2]],
        [runs[4], runs[5]],
        [runs[3]],
        alpha=0.01,
        m=3,
        n_boot=0,
    )
    est = ParitySpaceDetector().fit([runs[1], runs[2]])
    assert est.roles_ == SECOND_ROLES
    assert est.physical_["web_EA_N"] == pytest.approx(384e3, rel=1e-12)
    assert est.physical_["span_length_m"] == 2.0
    m = ev.metrics
    sel = (m.fault == "sensor.offset:sensor_A") & (m.metric == "pd")
    assert sel.sum() >= 1 and (m.loc[sel, "value"] == 1.0).all()
