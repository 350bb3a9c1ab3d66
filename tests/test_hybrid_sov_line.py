"""hybrid-sov on any staged line: the roles of the model (unwind, dancer, driven roller, the
stage idlers and seven sensors) found from the ``stage:`` keys and sensor positions, or named
by the plug-in's role parameters; lines that lack a role refused with one line saying what
is missing (docs/diagnostics.md §9.1, "What a line needs"). Modified copies of the Ch. 2 test
bed are written to tmp_path."""

from __future__ import annotations

import copy
import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim
from r2rsim.dataset.read import read_runs
from r2rsim.diagnostics.hybrid_sov import ROLES, HybridSoV, load_stages
from r2rsim.diagnostics.line import LINE_ATTR, attach_line
from r2rsim.errors import InputError

from conftest import REPO

LINE = REPO / "lines" / "thesis_testbed_realistic.yaml"

#: every id of the test bed renamed (elements, spans, sensors, controllers)
RENAME = {
    "unwind": "payoff",
    "s2a": "g1",
    "s2b": "g2",
    "s2c": "g3",
    "dancer": "arm",
    "s3_out": "g4",
    "drive4": "capstan",
    "r5a": "g5",
    "r5b": "g6",
    "rewind": "takeup",
    "registration": "camspan",
    "dia_unwind": "sonar",
    "speed_s2a": "encA",
    "speed_unwind": "encB",
    "speed_drive4": "encC",
    "lc_stage2": "force1",
    "dancer_angle": "pot1",
    "pitch4": "vision1",
    "rewind_speed": "c1",
    "drive4_speed": "c2",
    "unwind_speed": "c3",
    "dancer_loop": "c4",
    "pitch_tension": "c5",
}

#: the roles of the renamed copy, named by parameter
ROLE_IDS = {
    "unwind": "payoff",
    "dancer": "arm",
    "driven": "capstan",
    "diameter_sensor": "sonar",
    "unwind_encoder": "encB",
    "idler_encoder": "encA",
    "driven_encoder": "encC",
    "load_cell": "force1",
    "dancer_sensor": "pot1",
    "pitch_sensor": "vision1",
}


def _data() -> dict:
    return yaml.safe_load(LINE.read_text())


def _write(tmp_path, data, name="line.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True))
    return path


def _renamed(data: dict) -> dict:
    d = copy.deepcopy(data)
    for group, keys in (
        ("elements", ("id",)),
        ("spans", ("id",)),
        ("sensors", ("id", "element", "span")),
        ("controllers", ("id", "element", "dancer", "sensor")),
    ):
        for item in d[group]:
            for k in keys:
                if k in item:
                    item[k] = RENAME[item[k]]
    return d


def _unstaged(data: dict) -> dict:
    d = copy.deepcopy(data)
    for e in d["elements"]:
        e.pop("stage", None)
    return d


def _stages_renamed(st):
    """The original line's stages with every id renamed as in :data:`RENAME`."""

    def ren(r):
        return dataclasses.replace(r, id=RENAME[r.id])

    return dataclasses.replace(
        st,
        unwind=RENAME[st.unwind],
        dancer=RENAME[st.dancer],
        driven=ren(st.driven),
        idlers={k: [ren(r) for r in v] for k, v in st.idlers.items()},
        sensor_ids={k: RENAME[v] if isinstance(v, str) else v for k, v in st.sensor_ids.items()},
    )


def _message(path, roles=None) -> str:
    with pytest.raises(InputError) as exc:
        load_stages(path, roles)
    return exc.value.message


# ---- the same stages however the roles are found ------------------------------------------
def test_the_roles_are_every_id_the_model_reads():
    st = load_stages(LINE)
    assert set(ROLES) == {
        "unwind",
        "dancer",
        "driven",
        "diameter_sensor",
        "unwind_encoder",
        "idler_encoder",
        "driven_encoder",
        "load_cell",
        "dancer_sensor",
        "pitch_sensor",
    }
    assert st.sensor_ids == {
        "diameter": "dia_unwind",
        "speed_unwind": "speed_unwind",
        "speed_idler": "speed_s2a",
        "speed_idler_radius": 0.05,
        "speed_driven": "speed_drive4",
        "tension": "lc_stage2",
        "angle": "dancer_angle",
        "pitch": "pitch4",
    }
    assert [r.id for r in st.idlers[3]] == ["dancer", "s3_out"]
    assert st.relaxed_pitch == pytest.approx(0.24995)
    assert st.column("angle") == "meas.dancer_angle.position_rad"
    # a translating dancer's position is a travel [m]
    assert (
        dataclasses.replace(st, dancer_position_unit="m").column("angle")
        == "meas.dancer_angle.position_m"
    )


def test_a_renamed_line_gives_the_same_stages(tmp_path):
    expected = _stages_renamed(load_stages(LINE))
    renamed = _renamed(_data())
    # found by the stage: keys and sensor positions alone
    assert load_stages(_write(tmp_path, renamed, "keys.yaml")) == expected
    # every role named by parameter, no stage: key left (the idlers from the web path)
    bare = _write(tmp_path, _unstaged(renamed), "bare.yaml")
    assert load_stages(bare, ROLE_IDS) == expected
    # naming the three elements is enough: the sensors are found where they sit
    assert load_stages(bare, {"unwind": "payoff", "dancer": "arm", "driven": "capstan"}) == expected
    # and the plug-in passes its parameters on
    est = HybridSoV(line=str(bare), **ROLE_IDS)
    assert est._roles() == ROLE_IDS
    assert load_stages(est.line, est._roles()) == expected


def test_a_role_given_by_id_overrides_the_stage_keys(tmp_path):
    # the dancer without its stage: key: refused, until named; its roller is then still one
    # of stage 3
    d = _data()
    next(e for e in d["elements"] if e["id"] == "dancer").pop("stage")
    path = _write(tmp_path, d)
    assert _message(path) == (
        "hybrid-sov: dancer: no dancer of the line has stage: 3 "
        "(dancers: dancer); mark one stage: 3 or name it with "
        "dancer=<id>"
    )
    assert load_stages(path, {"dancer": "dancer"}) == load_stages(LINE)


# ---- refusals: one line each, naming the parameter and the line's candidates --------------
def _stages_removed(d):
    return _unstaged(d)


def _no_load_cell(d):
    d["sensors"] = [s for s in d["sensors"] if s["id"] != "lc_stage2"]
    return d


def _no_pitch_sensor(d):
    d["sensors"] = [s for s in d["sensors"] if s["id"] != "pitch4"]
    d["controllers"] = [c for c in d["controllers"] if c.get("sensor") != "pitch4"]
    return d


def _pitch_one_span_late(d):
    next(s for s in d["sensors"] if s["id"] == "pitch4")["span"] = "span8"
    return d


def _two_load_cells(d):
    d["sensors"].append({"id": "lc_s2a", "type": "load_cell", "element": "s2a", "noise": "0.5 N"})
    return d


def _rewind_load_cell(d):
    d["sensors"].append(
        {"id": "lc_rewind", "type": "load_cell", "element": "rewind", "noise": "0.5 N"}
    )
    return d


def _no_unwind_encoder(d):
    d["sensors"] = [s for s in d["sensors"] if s["id"] != "speed_unwind"]
    return d


def _idler_encoder_on_stage5(d):
    next(s for s in d["sensors"] if s["id"] == "speed_s2a")["element"] = "r5a"
    return d


def _second_driven_roller(d):
    # s2a driven (and marked stage 4), its encoder gone
    e = next(e for e in d["elements"] if e["id"] == "s2a")
    e.update(
        type="driven",
        stage=4,
        radius="0.10 m",
        inertia="0.15 kg*m^2",
        drive={"torque_lag": "1 ms", "torque_max": "300 N*m"},
    )
    d["sensors"] = [s for s in d["sensors"] if s["id"] != "speed_s2a"]
    return d


REFUSALS = [
    (
        "stages removed",
        _stages_removed,
        None,
        "hybrid-sov: unwind: no unwind of the line has stage: 1 (unwinds: unwind); mark one "
        "stage: 1 or name it with unwind=<id>",
    ),
    (
        "stages removed, unwind named",
        _stages_removed,
        {"unwind": "unwind"},
        "hybrid-sov: dancer: no dancer of the line has stage: 3 (dancers: dancer); mark one "
        "stage: 3 or name it with dancer=<id>",
    ),
    (
        "missing load cell",
        _no_load_cell,
        None,
        "hybrid-sov: load_cell: the line has no load cell on a stage-2 idler (s2a, s2b, s2c), "
        "needed for the stage-2 tension T_s2 (load cells: none)",
    ),
    (
        "missing pitch sensor",
        _no_pitch_sensor,
        None,
        "hybrid-sov: pitch_sensor: the line has no pitch-length sensor on the span leaving the "
        "driven roller 'drive4' (registration), needed for the pitch Y (pitch-length sensors: "
        "none)",
    ),
    (
        "pitch sensor elsewhere",
        _pitch_one_span_late,
        None,
        "hybrid-sov: pitch_sensor: the line has no pitch-length sensor on the span leaving the "
        "driven roller 'drive4' (registration), needed for the pitch Y (pitch-length sensors: "
        "pitch4)",
    ),
    (
        "pitch sensor elsewhere, named",
        _pitch_one_span_late,
        {"pitch_sensor": "pitch4"},
        "hybrid-sov: pitch_sensor 'pitch4' is on span8, not on the span leaving the driven "
        "roller 'drive4' (registration)",
    ),
    (
        "two load cells in stage 2",
        _two_load_cells,
        None,
        "hybrid-sov: load_cell: the line has 2 load cells on a stage-2 idler (s2a, s2b, s2c): "
        "lc_stage2 on s2c, lc_s2a on s2a; name one with load_cell=<id>",
    ),
    (
        "wrong load cell id",
        _rewind_load_cell,
        {"load_cell": "lc9"},
        "hybrid-sov: load_cell 'lc9' is not a load cell of the line (load cells: lc_stage2, "
        "lc_rewind)",
    ),
    (
        "load cell not in stage 2",
        _rewind_load_cell,
        {"load_cell": "lc_rewind"},
        "hybrid-sov: load_cell 'lc_rewind' is on rewind, not on a stage-2 idler (s2a, s2b, s2c)",
    ),
    (
        "wrong dancer id",
        None,
        {"dancer": "s3_out"},
        "hybrid-sov: dancer 's3_out' is not a dancer of the line (dancers: dancer)",
    ),
    (
        "wrong driven id",
        None,
        {"driven": "rewind"},
        "hybrid-sov: driven 'rewind' is not a driven roller of the line (driven rollers: drive4)",
    ),
    (
        "encoder of the wrong role",
        None,
        {"unwind_encoder": "speed_drive4"},
        "hybrid-sov: unwind_encoder 'speed_drive4' is on drive4, not on the unwind 'unwind'",
    ),
    (
        "missing unwind encoder",
        _no_unwind_encoder,
        None,
        "hybrid-sov: unwind_encoder: the line has no encoder on the unwind 'unwind', needed "
        "for the unwind speed ω1 (encoders: speed_s2a, speed_drive4)",
    ),
    (
        "idler encoder outside stage 2",
        _idler_encoder_on_stage5,
        None,
        "hybrid-sov: idler_encoder: the line has no encoder on a stage-2 idler (s2a, s2b, s2c), "
        "needed for the web speed v (encoders: speed_s2a, speed_unwind, speed_drive4)",
    ),
    (
        "two driven rollers in stage 4",
        _second_driven_roller,
        None,
        "hybrid-sov: driven: 2 driven rollers have stage: 4 (s2a, drive4); name one with "
        "driven=<id>",
    ),
    (
        "driven roller before the dancer",
        _second_driven_roller,
        {"driven": "s2a"},
        "hybrid-sov: dancer 'dancer' is not between the unwind 'unwind' and the driven roller "
        "'s2a' along the web: the model needs unwind (stage 1), dancer (stage 3) and driven "
        "roller (stage 4) in this order",
    ),
    (
        "wrong dancer sensor id",
        None,
        {"dancer_sensor": "pitch4"},
        "hybrid-sov: dancer_sensor 'pitch4' is not a dancer-position sensor of the line "
        "(dancer-position sensors: dancer_angle)",
    ),
]


@pytest.mark.parametrize(
    "change, roles, message", [r[1:] for r in REFUSALS], ids=[r[0] for r in REFUSALS]
)
def test_a_line_without_a_role_is_refused_in_one_line(tmp_path, change, roles, message):
    path = LINE if change is None else _write(tmp_path, change(_data()))
    got = _message(path, roles)
    assert got == message
    assert "\n" not in got
    # it starts with the parameter that names the role
    assert got.split()[1].rstrip(":") in ROLES


def test_naming_one_of_two_candidates_resolves_the_ambiguity(tmp_path):
    path = _write(tmp_path, _two_load_cells(_data()))
    assert load_stages(path, {"load_cell": "lc_stage2"}) == load_stages(LINE)
    st = load_stages(path, {"load_cell": "lc_s2a"})
    assert st.column("tension") == "meas.lc_s2a.tension_N"


def test_the_stage_idlers_come_from_the_web_path_without_stage_keys(tmp_path):
    # the unwind, dancer and driven roller named; stages 2, 3 and 5 are then the idlers
    # between them and right after the driven roller (up to the rewind)
    path = _write(tmp_path, _unstaged(_data()))
    st = load_stages(path, {"unwind": "unwind", "dancer": "dancer", "driven": "drive4"})
    assert {k: [r.id for r in v] for k, v in st.idlers.items()} == {
        2: ["s2a", "s2b", "s2c"],
        3: ["dancer", "s3_out"],
        5: ["r5a", "r5b"],
    }
    assert st == load_stages(LINE)


def test_the_plugin_refuses_a_wrong_role_before_reading_the_data(tmp_path):
    path = _write(tmp_path, _rewind_load_cell(_data()))
    frame = pd.DataFrame({"t_s": np.arange(10) * 0.02, "meas.x.y": 0.0, "act.x.y": 0.0})
    with pytest.raises(InputError) as exc:
        HybridSoV(line=str(path), load_cell="lc9").fit([frame])
    assert exc.value.message == (
        "hybrid-sov: load_cell 'lc9' is not a load cell of the "
        "line (load cells: lc_stage2, lc_rewind)"
    )
    with pytest.raises(InputError) as exc:
        HybridSoV(line=str(path), load_cell=5).fit([frame])
    assert exc.value.message == (
        "hybrid-sov: load_cell must be null or the id of a sensor of the line, got 5"
    )
    with pytest.raises(InputError) as exc:
        HybridSoV(line=str(path), dancer=["dancer"]).fit([frame])
    assert exc.value.message == (
        "hybrid-sov: dancer must be null or the id of an element of the line, got ['dancer']"
    )


def test_unknown_role_is_refused():
    with pytest.raises(InputError, match="hybrid-sov: unknown role tension"):
        load_stages(LINE, {"tension": "lc_stage2"})


# ---- end to end: a renamed line fitted with its roles named --------------------------------
def _rename_columns(frame: pd.DataFrame) -> pd.DataFrame:
    def ren(c):
        parts = c.split(".")
        if len(parts) == 3 and parts[1] in RENAME:
            parts[1] = RENAME[parts[1]]
        return ".".join(parts)

    return frame.rename(columns=ren)


def test_a_renamed_unstaged_line_scores_as_the_original(tmp_path):
    # the same data with every channel renamed as the line: the same model and scores
    d = tmp_path / "tb"
    r2rsim.run_scenario(
        REPO / "scenarios" / "thesis_realistic" / "testbed.yaml", output=d, seed=1, duration=30.0
    )
    frame = read_runs(d)[0].visible(drive_data=True)
    bare = _write(tmp_path, _unstaged(_renamed(_data())))
    ref = HybridSoV(line=str(LINE)).fit([frame])
    est = HybridSoV(line=str(bare), unwind="payoff", dancer="arm", driven="capstan")
    est.fit([_rename_columns(frame)])
    assert est.model_.stage12_.selected == ref.model_.stage12_.selected
    assert est.threshold_ == ref.threshold_
    a, b = ref.score(frame), est.score(_rename_columns(frame))
    pd.testing.assert_frame_equal(a, b)
    assert est.rank_channels(b).iloc[-1].tolist()[0] in (
        "meas.force1.tension_N",
        "meas.vision1.pitch_m",
    )


def test_the_runs_own_line_configures_the_model_and_a_different_one_is_refused(tmp_path):
    # no line=: the stages come from the line the dataset recorded, the same as from the file
    d = tmp_path / "tb"
    r2rsim.run_scenario(
        REPO / "scenarios" / "thesis_realistic" / "testbed.yaml", output=d, seed=1, duration=30.0
    )
    run = read_runs(d)[0]
    own = HybridSoV().fit([run])
    ref = HybridSoV(line=str(LINE)).fit([run.visible(drive_data=True)])
    assert own.stages_ == ref.stages_
    pd.testing.assert_frame_equal(own.score(run), ref.score(run.visible(drive_data=True)))
    # the same samples said to come from a line with another web: refused, naming it
    frame = attach_line(run.visible(drive_data=True), run)
    other = json.loads(frame.attrs[LINE_ATTR])
    other["web"]["thickness"] = "60 um"
    frame.attrs[LINE_ATTR] = json.dumps(other)
    with pytest.raises(
        InputError,
        match=r"^hybrid-sov: the scored run's line differs from "
        r"the one the model was fitted on in web_thickness \(6e-05 here, "
        r"0.000125 in the model\): fit on data of this line$",
    ):
        own.score(frame)
    # a frame with no line and no line= cannot say which line it is
    with pytest.raises(InputError, match="the data carries no line"):
        HybridSoV().fit([run.visible(drive_data=True)])
