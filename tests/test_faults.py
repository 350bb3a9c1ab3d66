"""Fault injection: every sensor fault type against its definition, inside the loop (V21) and
on the record, and the labels derived from faults.parquet."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim
from r2rsim.errors import InputError

from conftest import REPO, write

RATE = 100.0


def fault_line(tmp_path):
    """Line A plus a monitoring-only load cell (no noise, no filter, at the record rate)."""
    d = yaml.safe_load((REPO / "lines" / "pet_film_line.yaml").read_text())
    for s in d["sensors"]:
        s.pop("noise", None)  # exact comparisons with the true channel
    d["sensors"].append(
        {"id": "lc_mon", "type": "load_cell", "element": "idler1", "wrap_angle": "90 deg"}
    )
    return write(tmp_path / "line.yaml", yaml.safe_dump(d))


def scenario(tmp_path, faults, *, duration=12.0, programme=None, name="f", seed=3, extra=None):
    line = fault_line(tmp_path)
    d = {
        "name": name,
        "line": str(line),
        "duration": duration,
        "record_rate": RATE,
        "seed": seed,
        "warmup": 1.0,
        "initial": {"state": "steady"},
        "programme": programme or [{"at": 0, "line_speed": 5.0}],
        "faults": faults,
    }
    d.update(extra or {})
    return write(tmp_path / f"{name}.yaml", yaml.safe_dump(d))


def run(tmp_path, faults, **kw):
    path = scenario(tmp_path, faults, **kw)
    out = tmp_path / f"out_{kw.get('name', 'f')}_{kw.get('seed', 3)}"
    r2rsim.run_scenario(path, output=out, overwrite=True)  # tests rerun the same name and seed
    s = pd.read_parquet(out / "samples")
    f = pd.read_parquet(out / "faults.parquet")
    return s, f, out


def test_v21_offset_and_gain_act_inside_the_tension_loop(tmp_path):
    # V21: indicated tension y = g·T + b under integral control settles at (T_ref - b)/g;
    # 260 N, b = +20 N, g = 1.10 -> 240.00, 236.36, 218.18 N (tolerance 0.1 %)
    cases = {
        "offset": (
            [
                {
                    "id": "b",
                    "type": "sensor.offset",
                    "target": "lc_rewind",
                    "onset": 2.0,
                    "magnitude": "20 N",
                }
            ],
            240.00,
        ),
        "gain": (
            [
                {
                    "id": "g",
                    "type": "sensor.gain",
                    "target": "lc_rewind",
                    "onset": 2.0,
                    "magnitude": 0.10,
                }
            ],
            236.36,
        ),
        "both": (
            [
                {
                    "id": "b",
                    "type": "sensor.offset",
                    "target": "lc_rewind",
                    "onset": 2.0,
                    "magnitude": "20 N",
                    "compose": "superpose",
                },
                {
                    "id": "g",
                    "type": "sensor.gain",
                    "target": "lc_rewind",
                    "onset": 2.0,
                    "magnitude": 0.10,
                    "compose": "superpose",
                },
            ],
            218.18,
        ),
    }
    clean, _, _ = run(tmp_path, [], duration=40.0, name="clean")
    before = clean.t_s < 2.0
    for name, (faults, expected) in cases.items():
        s, _, _ = run(tmp_path, faults, duration=40.0, name=name)
        T = s["state.span5.tension_N"].to_numpy()  # the span the rewind loop controls
        assert T[-1] == pytest.approx(expected, rel=1e-3), name
        assert s["meas.lc_rewind.tension_N"].iloc[-1] == pytest.approx(260.0, rel=1e-3)
        assert s["true.lc_rewind.tension_N"].iloc[-1] == pytest.approx(expected, rel=1e-3)
        # nothing changes before the onset (the solver restarts there, so the earlier
        # samples agree to its tolerance, not bit for bit)
        assert np.allclose(
            T[before], clean["state.span5.tension_N"].to_numpy()[before], rtol=1e-5, atol=0
        )


def test_monitoring_sensor_fault_leaves_the_process_alone(tmp_path):
    s0, _, _ = run(tmp_path, [], name="clean")
    s1, _, _ = run(
        tmp_path,
        [{"id": "b", "type": "sensor.offset", "target": "lc_mon", "onset": 2.0, "magnitude": 50.0}],
        name="mon",
    )
    state = [c for c in s0.columns if c.startswith(("state.", "true."))]
    pd.testing.assert_frame_equal(s0[state], s1[state])
    dm = s1["meas.lc_mon.tension_N"] - s1["true.lc_mon.tension_N"]
    after = s1.t_s >= 2.0
    assert np.allclose(dm[after], 50.0, atol=1e-3) and np.allclose(dm[~after], 0.0, atol=1e-3)


def test_record_only_fault_on_a_loop_sensor_leaves_the_process_alone(tmp_path):
    """record_only: the same offset that V21 shows acting in the loop now shifts only the
    recorded reading of the loop's sensor; the plant is bit-identical to the clean run and
    faults.parquet keeps the option."""
    fault = {
        "id": "b",
        "type": "sensor.offset",
        "target": "lc_rewind",
        "onset": 2.0,
        "magnitude": "20 N",
    }
    s0, _, _ = run(tmp_path, [], name="clean")
    s1, f1, out = run(tmp_path, [{**fault, "record_only": True}], name="rec")
    s2, _, _ = run(tmp_path, [fault], name="loop")
    state = [c for c in s0.columns if c.startswith(("state.", "true."))]
    pd.testing.assert_frame_equal(s0[state], s1[state])
    assert not np.allclose(s0["state.span5.tension_N"], s2["state.span5.tension_N"])
    dm = s1["meas.lc_rewind.tension_N"] - s0["meas.lc_rewind.tension_N"]
    after = s1.t_s >= 2.0
    assert np.allclose(dm[after], 20.0, atol=1e-4) and np.allclose(dm[~after], 0.0, atol=1e-4)
    assert '"record_only": true' in f1.params_json.iloc[0]
    assert s1["label.ch.lc_rewind.tension_N"][after].all()
    from r2rsim.dataset.validate import validate_dataset

    assert validate_dataset(out) == []


def _err(s):
    return (s["meas.lc_mon.tension_N"] - s["true.lc_mon.tension_N"]).to_numpy(), s.t_s.to_numpy()


@pytest.mark.parametrize("shape", ["step", "ramp", "exp", "intermittent"])
def test_offset_profiles(tmp_path, shape):
    prof = {
        "step": {},
        "ramp": {"ramp": 2.0},
        "exp": {"ramp": 1.5},
        "intermittent": {"period": 2.0, "duty": 0.25},
    }[shape]
    s, f, _ = run(
        tmp_path,
        [
            {
                "id": "f1",
                "type": "sensor.offset",
                "target": "lc_mon",
                "onset": 3.0,
                "end": 9.0,
                "profile": {"shape": shape, **prof},
                "magnitude": 10.0,
            }
        ],
    )
    e, t = _err(s)
    dt = t - 3.0
    p = {
        "step": np.ones_like(t),
        "ramp": np.clip(dt / 2.0, 0, 1),
        "exp": 1 - np.exp(-np.maximum(dt, 0) / 1.5),
        "intermittent": (np.mod(np.maximum(dt, 0), 2.0) < 0.5 - 1e-9).astype(float),
    }[shape]
    p = np.where((t >= 3.0) & (t < 9.0), p, 0.0)
    # the in-loop reading is integrated by the solver: exact to its tolerance (1e-6 rel)
    assert np.max(np.abs(e - 10.0 * p)) < 1e-3
    if shape == "ramp":  # full magnitude exactly at onset + ramp
        assert e[np.searchsorted(t, 5.0)] == pytest.approx(10.0, abs=1e-3)
    # labels follow faults.parquet exactly
    row = f.iloc[0]
    present = (t >= row.onset_t_s) & (t < row.end_t_s)
    assert (s["label.is_faulty"].to_numpy() == present).all()
    assert (s["label.ch.lc_mon.tension_N"].to_numpy() == (p > 0)).all()
    assert np.allclose(s["label.severity"].to_numpy(), p, atol=1e-6)
    assert row.onset_k == int(np.argmax(present))
    assert list(s["label.fault_ids"].iloc[int(5 * RATE)]) == ["f1"]
    assert (s["label.primary_type"][present] == "sensor.offset").all()
    assert (s["label.phase"][~present & (t >= 1.0)] == "normal").all()


def test_gain_drift_stuck_dropout(tmp_path):
    ramp = [{"at": 0, "line_speed": 5.0}, {"at": 4.0, "line_speed": 6.0, "ramp": 4.0}]
    faults = [
        {
            "id": "g",
            "type": "sensor.gain",
            "target": "lc_mon",
            "onset": 2.0,
            "end": 3.0,
            "magnitude": 0.2,
        },
        {
            "id": "d",
            "type": "sensor.drift",
            "target": "lc_mon",
            "onset": 3.0,
            "end": 4.0,
            "magnitude": "5 N/s",
        },
        {"id": "s", "type": "sensor.stuck", "target": "lc_mon", "onset": 4.0, "end": 6.0},
        {"id": "x", "type": "sensor.dropout", "target": "lc_mon", "onset": 7.0, "end": 8.0},
    ]
    s, f, _ = run(tmp_path, faults, programme=ramp)
    e, t = _err(s)
    m, tr = s["meas.lc_mon.tension_N"].to_numpy(), s["true.lc_mon.tension_N"].to_numpy()
    w = (t >= 2.0) & (t < 3.0)
    assert np.allclose(m[w], 1.2 * tr[w], rtol=1e-5)
    w = (t >= 3.0) & (t < 4.0)
    assert np.allclose(e[w], 5.0 * (t[w] - 3.0), atol=1e-3)
    w = (t >= 4.0) & (t < 6.0)  # stuck: holds the value at onset while the tension moves
    assert np.ptp(m[w]) < 1e-6 and m[w][0] == pytest.approx(tr[w][0], abs=1e-3)
    assert np.ptp(tr[w]) > 1.0
    w = (t >= 7.0) & (t < 8.0)
    assert np.isnan(m[w]).all() and not np.isnan(m[~w]).any()
    assert s["label.ch.lc_mon.tension_N"][w].all()
    assert (s["label.fault_ids"].apply(len).to_numpy() == ((t >= 2) & (t < 6) | w)).all()


def test_record_side_faults(tmp_path):
    faults = [
        {
            "id": "n",
            "type": "sensor.noise",
            "target": "lc_mon",
            "onset": 1.0,
            "end": 4.0,
            "magnitude": 2.0,
        },
        {
            "id": "k",
            "type": "sensor.spike",
            "target": "lc_mon",
            "onset": 4.0,
            "end": 8.0,
            "magnitude": 30.0,
            "rate": 5.0,
        },
        {
            "id": "q",
            "type": "sensor.quantization",
            "target": "lc_mon",
            "onset": 8.0,
            "end": 10.0,
            "magnitude": 4.0,
        },
        {"id": "d", "type": "sensor.delay", "target": "lc_mon", "onset": 10.0, "magnitude": 0.25},
    ]
    ramp = [{"at": 0, "line_speed": 5.0}, {"at": 9.0, "line_speed": 6.0, "ramp": 3.0}]
    s, f, _ = run(tmp_path, faults, programme=ramp, duration=12.0)
    e, t = _err(s)
    m, tr = s["meas.lc_mon.tension_N"].to_numpy(), s["true.lc_mon.tension_N"].to_numpy()
    w = (t >= 1.0) & (t < 4.0)  # 300 draws: the sample std is within 15 % of sigma
    assert np.std(e[w]) == pytest.approx(2.0, rel=0.15) and abs(np.mean(e[w])) < 0.5
    assert np.all(e[(t < 1.0)] == pytest.approx(0.0, abs=1e-3))
    w = (t >= 4.0) & (t < 8.0)
    spikes = np.abs(e[w]) > 15
    assert np.allclose(np.abs(e[w][spikes]), 30.0, atol=1e-3)
    assert 8 <= spikes.sum() <= 35  # Poisson, mean 20
    assert not (np.abs(e[(t >= 8.0)]) > 15).any()
    w = (t >= 8.0) & (t < 10.0)
    assert np.allclose(np.mod(m[w] + 1e-9, 4.0), 0.0, atol=1e-6)
    assert np.max(np.abs(e[w])) <= 2.0 + 1e-6
    w = t >= 10.5  # delayed by 0.25 s = 25 samples
    idx = np.nonzero(w)[0]
    assert np.allclose(m[idx], tr[idx - 25], atol=1e-3)


def test_same_seed_same_data_and_noise_seed_only_touches_measurements(tmp_path):
    faults = [
        {
            "id": "n",
            "type": "sensor.noise",
            "target": "lc_mon",
            "onset": 2.0,
            "magnitude": {"uniform": [1.0, 3.0]},
        },
        {
            "id": "o",
            "type": "sensor.offset",
            "target": "lc_rewind",
            "onset": {"uniform": [3.0, 5.0]},
            "magnitude": "5 N",
        },
    ]
    s1, f1, o1 = run(tmp_path, faults, name="a", seed=7)
    s2, f2, o2 = run(tmp_path, faults, name="a", seed=7)
    pd.testing.assert_frame_equal(s1, s2)
    pd.testing.assert_frame_equal(f1, f2)
    s3, f3, _ = run(tmp_path, faults, name="a", seed=8)
    assert not f3.equals(f1)  # onsets and magnitudes are drawn from the seed
    # the record side of noise is drawn from the measurement stream only: redraw it with
    # another stream and the true channels stay identical
    from r2rsim.compile.faults import realise_faults
    from r2rsim.measure import MeasurementModel

    scen, line, _ = r2rsim.load_scenario(scenario(tmp_path, faults, name="a", seed=7))
    insts = realise_faults(scen, line, np.random.SeedSequence(7).spawn(3)[2])
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    res = r2rsim.simulate(
        cl, 6.0, RATE, r2rsim.steady_state(cl, r2rsim.nominal_state(cl)), faults=insts
    )
    a = MeasurementModel(cl, RATE, np.random.SeedSequence(1), insts).measure(res.t, res.outputs)
    b = MeasurementModel(cl, RATE, np.random.SeedSequence(2), insts).measure(res.t, res.outputs)
    for k in a:
        if k.startswith("true."):
            assert np.array_equal(a[k], b[k])
    assert not np.array_equal(a["meas.lc_mon.tension_N"], b["meas.lc_mon.tension_N"])


@pytest.mark.parametrize(
    "faults, message",
    [
        (
            [
                {
                    "id": "a",
                    "type": "sensor.offset",
                    "target": "lc_mon",
                    "onset": 2.0,
                    "magnitude": 1.0,
                },
                {
                    "id": "b",
                    "type": "sensor.gain",
                    "target": "lc_mon",
                    "onset": 5.0,
                    "magnitude": 0.1,
                },
            ],
            "faults 'a' and 'b' can overlap on 'lc_mon' (from 5 s); declare compose: superpose",
        ),
        (
            [
                {
                    "id": "a",
                    "type": "sensor.stuck",
                    "target": "lc_mon",
                    "onset": 2.0,
                    "compose": "superpose",
                },
                {
                    "id": "b",
                    "type": "sensor.offset",
                    "target": "lc_mon",
                    "onset": 1.0,
                    "end": 3.0,
                    "magnitude": 1.0,
                    "compose": "superpose",
                },
            ],
            "cannot be superposed",
        ),
        (
            [
                {
                    "id": "a",
                    "type": "sensor.offset",
                    "target": "nope",
                    "onset": 2.0,
                    "magnitude": 1.0,
                }
            ],
            "no sensor 'nope'",
        ),
        (
            [
                {
                    "id": "a",
                    "type": "sensor.offset",
                    "target": "lc_mon",
                    "onset": 2.0,
                    "magnitude": "3 m",
                }
            ],
            "expected a force",
        ),
        (
            [
                {
                    "id": "a",
                    "type": "sensor.stuck",
                    "target": "lc_mon",
                    "onset": 2.0,
                    "magnitude": 1.0,
                }
            ],
            "takes no magnitude",
        ),
        (
            [
                {
                    "id": "a",
                    "type": "sensor.noise",
                    "target": "lc_mon",
                    "onset": 2.0,
                    "magnitude": 1.0,
                    "record_only": True,
                }
            ],
            "record_only applies to sensor faults that "
            "act in the loop; sensor.noise acts on the record",
        ),
        (
            [
                {
                    "id": "a",
                    "type": "sensor.offset",
                    "target": "lc_mon",
                    "onset": {"uniform": [2, 30]},
                    "magnitude": 1.0,
                }
            ],
            "after the end of the run",
        ),
    ],
)
def test_bad_faults_are_rejected(tmp_path, faults, message):
    path = scenario(tmp_path, faults)
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        r2rsim.load_scenario(path)


@pytest.mark.parametrize(
    "change, ypath, message",
    [
        (
            {"magnitude": "3 m"},
            "faults[0].magnitude",
            "'3 m' has dimension [length], expected a force",
        ),
        ({"onset": {"uniform": ["1 N", "3 N"]}}, "faults[0].onset", "expected a time"),
        ({"onset": 30.0}, "faults[0].onset", "onset is 30 s, after the end of the run (12 s)"),
        ({"onset": {"uniform": [2, 30]}}, "faults[0].onset", "onset can be 30 s, after the end"),
        (
            {"onset": {"uniform": [2, 8]}, "end": 5.0},
            "faults[0].end",
            "end 5 s can come before the onset, which is drawn up to 8 s",
        ),
    ],
)
def test_a_bad_fault_value_is_named_by_its_own_path(tmp_path, change, ypath, message):
    # the message names the key at fault (magnitude or onset), not only faults[0]; a fixed
    # onset "is", a drawn one "can be"
    fault = {
        "id": "a",
        "type": "sensor.offset",
        "target": "lc_mon",
        "onset": 2.0,
        "magnitude": 1.0,
        **change,
    }
    with pytest.raises(InputError) as info:
        r2rsim.load_scenario(scenario(tmp_path, [fault]))
    assert info.value.path == ypath and message in info.value.message, info.value.format()


def test_validator_rederives_every_label_from_faults_parquet(tmp_path, capsys):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from r2rsim.cli import main
    from r2rsim.dataset.validate import validate_dataset

    _, _, out = run(
        tmp_path,
        [
            {
                "id": "f1",
                "type": "sensor.offset",
                "target": "lc_mon",
                "onset": 3.0,
                "magnitude": 10.0,
            }
        ],
    )
    assert validate_dataset(out) == []
    assert main(["validate", str(out)]) == 0
    # a fault label one sample before the onset, as in the mislabelled TEP files
    part = next((out / "samples").glob("*/part-0.parquet"))
    table = pq.read_table(part)
    flags = table.column("label.is_faulty").to_numpy(zero_copy_only=False).copy()
    flags[299] = True
    i = table.column_names.index("label.is_faulty")
    pq.write_table(table.set_column(i, "label.is_faulty", pa.array(flags)), part)
    problems = validate_dataset(out)
    assert any(
        "label.is_faulty at k = 299 is True; faults.parquet gives False" in p for p in problems
    ), problems
    assert any("fault labels before the first onset" in p for p in problems)
    assert any("checksum differs" in p for p in problems)
    assert main(["validate", str(out)]) == 2


@pytest.mark.parametrize(
    "row, ids, shown",
    [
        (299, ["f1"], "['f1']"),  # before the onset
        (400, ["f2"], "['f2']"),  # the wrong id
        (400, [], "[]"),
    ],
)  # a lost id
def test_validator_rederives_fault_id_lists(tmp_path, row, ids, shown):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from r2rsim.dataset.validate import validate_dataset

    _, _, out = run(
        tmp_path,
        [
            {
                "id": "f1",
                "type": "sensor.offset",
                "target": "lc_mon",
                "onset": 3.0,
                "magnitude": 10.0,
            }
        ],
    )
    part = next((out / "samples").glob("*/part-0.parquet"))
    table = pq.read_table(part)
    lists = table.column("label.fault_ids").to_pylist()
    assert lists[299] == [] and lists[400] == ["f1"]
    lists[row] = ids
    i = table.column_names.index("label.fault_ids")
    pq.write_table(
        table.set_column(i, "label.fault_ids", pa.array(lists, type=pa.list_(pa.string()))), part
    )
    problems = validate_dataset(out)
    assert any(f"label.fault_ids at k = {row} is {shown}" in p for p in problems), problems


def test_list_faults_and_channels(repo, capsys):
    from r2rsim.cli import main
    from r2rsim.schema.faults import CATALOGUE

    assert main(["list", "faults"]) == 0
    text = capsys.readouterr().out
    assert all(name in text for name in CATALOGUE)
    assert main(["list", "channels", str(repo / "lines" / "registration.yaml")]) == 0
    text = capsys.readouterr().out
    assert "meas.sensor_B.pitch_m" in text and "state.registration.tension_N" in text
    assert main(["list", "channels"]) == 2


def test_list_channels_gives_the_units_of_channels_parquet(repo, tmp_path, capsys):
    # `r2rsim list channels` shows each sensor channel's unit as the dataset records it
    # (rad/s, not the rad_s of the column name)
    from r2rsim.cli import main

    assert main(["list", "channels", str(repo / "lines" / "pet_film_line.yaml")]) == 0
    listed = {}
    for row in capsys.readouterr().out.splitlines()[1:]:
        name, unit = row.split()[:2]
        listed[name] = unit
    r2rsim.run_scenario(repo / "scenarios" / "quickstart.yaml", output=tmp_path / "q", duration=0.5)
    channels = pd.read_parquet(tmp_path / "q" / "channels.parquet")
    sensors = channels[channels.kind.isin(["measured", "true"])]
    assert listed["meas.enc_pull.speed_rad_s"] == "rad/s"
    assert {n: listed[n] for n in sensors.channel} == dict(
        zip(sensors.channel, sensors.unit, strict=True)
    )


def test_range_clipping_is_flagged_and_channels_describe_every_column(tmp_path):
    path = scenario(
        tmp_path,
        [{"id": "o", "type": "sensor.offset", "target": "lc_mon", "onset": 4.0, "magnitude": 10.0}],
    )
    d = yaml.safe_load(fault_line(tmp_path).read_text())
    for s in d["sensors"]:
        if s["id"] == "lc_mon":
            s["range"] = [0.0, 265.0]
    write(tmp_path / "line_r.yaml", yaml.safe_dump(d))
    d = yaml.safe_load(path.read_text())
    d["line"] = str(tmp_path / "line_r.yaml")
    write(path, yaml.safe_dump(d))
    out = tmp_path / "clip"
    r2rsim.run_scenario(path, output=out)
    s = pd.read_parquet(out / "samples")
    m = s["meas.lc_mon.tension_N"].to_numpy()
    flag = s["flag.lc_mon.clipped"].to_numpy()
    # 260 N + 10 N offset reads 270 N: above the range, recorded as 265 N and flagged
    assert (
        flag == (s["true.lc_mon.tension_N"].to_numpy() + np.where(s.t_s >= 4.0, 10.0, 0) > 265.0)
    ).all()
    assert flag.any() and np.all(m[flag] == 265.0)
    ch = pd.read_parquet(out / "channels.parquet").set_index("channel")
    assert list(ch.index) == ["run_id", *pq_columns(out)]
    assert ch.loc["meas.enc_pull.speed_rad_s", "unit"] == "rad/s"
    assert ch.loc["true.lc_mon.tension_N", "rate_hz"] == RATE
    ev = pd.read_parquet(out / "events.parquet")
    assert ((ev.kind == "fault") & (ev.state == "start") & (ev.t_s == 4.0)).sum() == 1


def pq_columns(out):
    import pyarrow.parquet as pq

    return pq.read_schema(next((out / "samples").glob("*/part-0.parquet"))).names


def test_record_side_faults_do_not_depend_on_the_chunking(tmp_path):
    # the measurement model's draws are per sensor tick, whatever the chunks the solver hands
    # over: a run cut into ~100-sample chunks measures what a run in one chunk measures
    faults = [
        {
            "id": "n",
            "type": "sensor.noise",
            "target": "lc_mon",
            "onset": 1.0,
            "magnitude": 2.0,
            "compose": "superpose",
        },
        {
            "id": "k",
            "type": "sensor.spike",
            "target": "lc_mon",
            "onset": 1.0,
            "magnitude": 30.0,
            "rate": 20.0,
            "compose": "superpose",
        },
    ]
    one, _, _ = run(tmp_path, faults, duration=6.0, name="one")
    many, _, _ = run(
        tmp_path, faults, duration=6.0, name="many", extra={"solver": {"chunk_memory_mb": 0.05}}
    )
    e1, e2 = (
        (s["meas.lc_mon.tension_N"] - s["true.lc_mon.tension_N"]).to_numpy() for s in (one, many)
    )
    assert (np.abs(e1) > 15).sum() >= 40  # spikes were drawn (Poisson, mean 100)
    # the true tension itself moves by ~1e-5 N with the solver's restarts at chunk ends
    # (tests/test_solver.py): compare what the faults added, to float32's resolution
    np.testing.assert_allclose(e2, e1, rtol=0, atol=1e-3)
