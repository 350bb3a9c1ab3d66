"""The element kinds (r2rsim/schema/kinds/): one module per kind found by the registry, each
kind's hooks, and a roller kind defined here, registered as a plug-in would, that a line
uses end to end (validated, compiled, simulated)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Annotated, Any, Literal

import numpy as np
import pytest
from pydantic import Field

import r2rsim
from r2rsim.cli import _kinds_in_source
from r2rsim.cli import main as cli_main
from r2rsim.compile import Programme
from r2rsim.compile.compiler import _Fields
from r2rsim.compile.layout import NodeP
from r2rsim.errors import InputError
from r2rsim.schema import kinds
from r2rsim.schema.kinds import ElementKind, kind_named, kind_of, register, unregister
from r2rsim.schema.line import Line
from r2rsim.schema.parts import ElementBase, PosLength
from r2rsim.schema.quantities import Mass

from conftest import REPO

SHIPPED = ("unwind", "rewind", "idler", "driven", "nip", "dancer", "pivot_dancer")


class Record(dict):
    """A record writer as the compiler passes one: fields by name."""


def _web(**kw):
    return SimpleNamespace(**{"thickness": 1e-4, "width": 1.0, "density": 1000.0, **kw})


def _element(kind: str, **keys):
    return kind_named(kind).model.model_validate({"id": "x", "type": kind, **keys})


# ---- the registry ------------------------------------------------------------------------------
def test_the_registry_finds_the_seven_shipped_kinds_in_order():
    assert kinds.kind_names() == SHIPPED
    assert [k.name for k in kinds.kinds_in_family("roll")] == ["unwind", "rewind"]
    assert [k.name for k in kinds.kinds_in_family("roller")] == ["idler", "driven", "nip"]
    assert [k.name for k in kinds.kinds_in_family("mover")] == ["dancer", "pivot_dancer"]
    for k in kinds.all_kinds():
        assert isinstance(k, ElementKind)
        assert k.model.model_fields["type"].annotation == Literal[k.name]
        assert k.summary
    with pytest.raises(KeyError, match="no element kind 'toy'; known: unwind, rewind"):
        kind_named("toy")
    with pytest.raises(ValueError, match="already registered"):
        register(kind_named("idler"))

    class Mislabelled(ElementKind):
        name = "mislabelled"
        model = kind_named("idler").model
        summary = "an idler's model under another name"

    with pytest.raises(ValueError, match=r'its model Idler needs type: Literal\["mislabelled"\]'):
        register(Mislabelled())
    assert "mislabelled" not in kinds.kind_names()


def test_derived_facts_of_the_shipped_kinds():
    drive = {k.name for k in kinds.all_kinds() if k.has_drive}
    assert drive == {"unwind", "rewind", "driven", "nip"}
    assert [k.name for k in kinds.all_kinds() if k.pays_out] == ["unwind"]
    assert {k.name: k.coordinate_unit for k in kinds.kinds_in_family("mover")} == {
        "dancer": "m",
        "pivot_dancer": "rad",
    }
    assert kind_named("pivot_dancer").coordinate_dimension == "angle"
    assert kind_named("dancer").mover_kind == "LINEAR"
    assert kind_named("pivot_dancer").mover_kind == "PIVOT"
    from r2rsim.schema.line import DANCERS, ROTATING_WITH_DRIVE

    assert DANCERS == ("dancer", "pivot_dancer")
    assert ROTATING_WITH_DRIVE == ("unwind", "rewind", "driven", "nip")


def test_the_quick_listing_reads_the_same_kinds_from_source():
    # `r2rsim list elements` reads the kind modules' source when the registry is not loaded
    # (it must not import pydantic): the same rows as the registry's
    rows = _kinds_in_source(REPO / "r2rsim" / "schema" / "kinds")
    assert sorted(rows) == [(k.order, k.name, k.summary) for k in kinds.all_kinds()]


def test_fault_targets_are_what_faults_py_decided_per_kind():
    targets = {k.name: k.fault_targets for k in kinds.all_kinds()}
    assert targets["unwind"] == {"drive", "roller", "unwind", "splicer"}
    assert targets["rewind"] == {"drive", "roller"}
    assert targets["idler"] == {"roller", "eccentric"}
    assert targets["driven"] == targets["nip"] == {"drive", "roller", "eccentric", "speed_node"}
    assert targets["dancer"] == targets["pivot_dancer"] == {"roller", "eccentric", "dancer"}


def test_the_union_accepts_every_shipped_line():
    paths = sorted((REPO / "lines").glob("*.yaml"))
    assert len(paths) >= 10
    seen = set()
    for path in paths:
        line = r2rsim.load_line(path)
        for e in line.elements:
            assert isinstance(e, kind_of(e).model)
            seen.add(e.type)
    assert seen == set(SHIPPED)


# ---- each kind's hooks ------------------------------------------------------------------------
ROLL = {"core_radius": 0.08, "outer_radius": 0.4, "core_inertia": 0.5}


@pytest.mark.parametrize("name", ["unwind", "rewind"])
def test_roll_kinds_pack_the_roll_geometry(name):
    kind = kind_named(name)
    e = _element(name, roll={**ROLL, "wound_in_strain": [0.001, 0.002]})
    node = Record()
    kind.pack_node(e, node, _web())
    assert node == {
        "R0": 0.4,
        "RC": 0.08,
        "JC": 0.5,
        "CW": 1e-4,  # the web thickness: no build_per_wrap
        "RHOW": 1000.0,  # rho·t_w / c_w · w
        "EPSW": 0.001,
        "EPSW1": 0.002,
        "EPSW2": 0.0,
        "R": 0.4,
    }
    assert kind.surface_radius(e) == 0.4
    assert kind.smallest_radius(e) == (0.08, "roll.core_radius")
    J = kind.drive_inertia(e, _web())
    assert J == pytest.approx(0.5 + 0.5 * math.pi * 1000.0 * (0.4**4 - 0.08**4))
    assert kind.node_kind == name.upper() and kind.is_roll


def test_an_unwind_with_a_splicer_packs_its_trigger_radius():
    e = _element(
        "unwind",
        roll=ROLL,
        spare_roll=ROLL,
        splicer={"type": "flying", "trigger_radius": 0.1},
    )
    node = Record()
    kind_of(e).pack_node(e, node, _web())
    assert node["RTRIG"] == 0.1


@pytest.mark.parametrize("name", ["idler", "driven"])
def test_plain_rollers_pack_radius_and_inertia(name):
    e = _element(name, radius=0.05, inertia=0.011)
    node = Record()
    kind_of(e).pack_node(e, node, _web())
    assert node == {"R": 0.05, "J": 0.011}
    assert kind_of(e).drive_inertia(e, _web()) == 0.011
    assert kind_of(e).frictions(e) == [("friction", e.friction)]
    assert kind_of(e).rest_tension(e, None) is None


def test_a_nip_packs_the_pair_as_one_degree_of_freedom():
    e = _element(
        "nip",
        radius=0.1,
        inertia=0.2,
        friction={"viscous": 0.01, "coulomb": 0.1},
        pressure_roller={
            "radius": 0.05,
            "inertia": 0.03,
            "friction": {"viscous": 0.002, "coulomb": 0.05},
        },
    )
    kind, node = kind_of(e), Record()
    kind.pack_node(e, node, _web())
    assert node == {
        "R": 0.1,
        "J": 0.2 + 0.03 * 2.0**2,
        "B": 0.01 + 0.002 * 2.0**2,
        "TC": 0.1 + 0.05 * 2.0,
    }
    assert kind.drive_inertia(e, _web()) == 0.2 + 0.03 * 2.0**2
    assert [k for k, _ in kind.frictions(e)] == ["friction", "pressure_roller.friction"]


DANCER = {
    "radius": 0.05,
    "inertia": 0.001,
    "position": [1.0, 0.5],
    "wrap": "cw",
    "direction": [0.0, -2.0],
    "travel_range": [-0.1, 0.2],
    "initial_travel": 0.05,
    "mass": 4.0,
    "load_force": -60.0,
    "spring_stiffness": 100.0,
    "spring_free_travel": 0.01,
}


def test_a_dancer_packs_its_carriage_and_guesses_half_its_load():
    e = _element("dancer", **DANCER)
    kind, mover = kind_of(e), Record()
    kind.pack_mover(e, mover)
    assert mover == {
        "CX": 1.0,
        "CY": 0.5,
        "NX": 0.0,
        "NY": -1.0,  # normalised
        "MASS": 4.0,
        "QMIN": -0.1,
        "QMAX": 0.2,
        "F0": 4.0 * 9.81,  # gravity (0, -9.81) along (0, -1)
        "FAIR": -60.0,
        "K": 100.0,
        "Q0": 0.01,
    }
    assert kind.centre(e, 0.1) == (1.0, 0.4)
    assert kind.mover_range(e) == (-0.1, 0.2) and kind.mover_start(e) == 0.05
    assert kind.rest_tension(e, None) == 0.5 * abs(-60.0 + 4.0 * 9.81)
    assert kind.check(e, "elements[2]") == []
    bad = _element("dancer", **{**DANCER, "initial_travel": 0.3})
    ((where, message),) = kind.check(bad, "elements[2]")
    assert where == "elements[2].initial_travel"
    assert message.endswith("outside the travel range [-0.1, 0.2]")


PIVOT = {
    "radius": 0.05,
    "inertia": 0.001,
    "wrap": "cw",
    "pivot": [1.0, 0.0],
    "arm_length": 0.5,
    "arm_angle": 0.0,
    "angle_range": [-0.5, 0.5],
    "arm_inertia": 0.2,
    "roller_mass": 2.0,
    "arm_mass": 1.0,
    "torque": 3.0,
    "torsion_spring": {"stiffness": 10.0, "free_angle": 0.1},
    "cylinder": {"force": 50.0, "fixed_point": [1.2, -0.3], "arm_point": 0.25},
}


def test_a_pivot_dancer_packs_its_arm_and_balances_moments():
    e = _element("pivot_dancer", **PIVOT)
    kind, mover = kind_of(e), Record()
    kind.pack_mover(e, mover)
    lever = 2.0 * 0.5 + 1.0 * 0.25  # roller at the arm's end, arm mass at half its length
    assert mover == {
        "CX": 1.0,
        "CY": 0.0,
        "NX": 0.5,
        "MASS": 0.2 + 2.0 * 0.5**2,
        "QMIN": -0.5,
        "QMAX": 0.5,
        "F0": 3.0,
        "G1": lever * -9.81,
        "G2": -lever * 0.0,
        "K": 10.0,
        "Q0": 0.1,
        "CYLF": 50.0,
        "CYLX": 1.2,
        "CYLY": -0.3,
        "CYLA": 0.25,
    }
    assert kind.centre(e, math.pi / 2) == pytest.approx((1.0, 0.5))
    # the moment balance is the compiled line's (its kernel's load and span geometry)
    cl = SimpleNamespace(mover_ids=["x"], mover_q0=[0.0], mover_balance=lambda m, q: (12.0, 0.3))
    assert kind.rest_tension(e, cl) == 12.0 / 0.3
    cl.mover_balance = lambda m, q: (12.0, 0.0)
    assert kind.rest_tension(e, cl) is None
    bad = _element("pivot_dancer", **{**PIVOT, "position": [0.0, 0.0]})
    assert kind.check(bad, "elements[3]")[0][0] == "elements[3].position"


def test_a_record_writer_names_an_unknown_field():
    row = np.zeros(len(NodeP))
    node = _Fields(row, NodeP, "node")
    node["J"] = 2.5
    assert row[NodeP.J] == 2.5
    with pytest.raises(KeyError, match="the node record has no field 'RADIUS'; fields: R, J, B, "):
        node["RADIUS"] = 1.0


# ---- a roller kind from outside the package ---------------------------------------------------
class ToyRoller(ElementBase):
    """A roller given by its mass (a solid cylinder): J = m·R²/2."""

    type: Literal["toy_roller"] = Field(description="selects a toy roller")
    radius: PosLength = Field(description="roller radius [m]")
    mass: Annotated[Mass, Field(gt=0)] = Field(description="roller mass [kg]")

    @property
    def inertia(self) -> float:
        return 0.5 * self.mass * self.radius**2


class ToyRollerKind(ElementKind):
    name = "toy_roller"
    model = ToyRoller
    summary = "a solid-cylinder roller: radius, mass (J = m·R²/2)"

    def pack_node(self, e: Any, node, web: Any) -> None:
        node["R"] = e.radius
        node["J"] = e.inertia


TOY_LINE = """\
name: toy
web: {thickness: 100 um, width: 1 m, modulus: 1 GPa, density: 1390 kg/m^3, break_stress: 5 MPa}
elements:
  - id: unwind
    type: unwind
    roll: {core_radius: 76 mm, outer_radius: 0.4 m, core_inertia: 0.5 kg*m^2}
    drive: {type: ideal_speed}
  - {id: toy, type: toy_roller, radius: 0.06 m, mass: 3 kg}
  - id: rewind
    type: rewind
    roll: {core_radius: 76 mm, outer_radius: 0.1 m, core_inertia: 0.5 kg*m^2}
    drive: {type: ideal_speed, draw: 0.001}
spans:
  - {id: span1, length: 2 m}
  - {id: span2, length: 1 m}
"""


@pytest.fixture
def toy_kind():
    kind = register(ToyRollerKind())
    yield kind
    unregister("toy_roller")


def test_an_unregistered_kind_is_an_unknown_type(tmp_path):
    path = tmp_path / "toy.yaml"
    path.write_text(TOY_LINE)
    with pytest.raises(InputError, match=r"unknown type 'toy_roller' \(expected one of: 'unwind'"):
        r2rsim.load_line(path)


def test_a_registered_roller_kind_runs_in_a_line(tmp_path, toy_kind):
    path = tmp_path / "toy.yaml"
    path.write_text(TOY_LINE)
    line = r2rsim.load_line(path)
    assert kind_of(line.element("toy")) is toy_kind
    cl = r2rsim.compile_line(line, Programme.constant(line, line_speed=1.0))
    k = cl.node_ids.index("toy")
    assert cl.param("node", k, "J") == 0.5 * 3.0 * 0.06**2  # exactly m·R²/2
    assert cl.param("node", k, "R") == 0.06
    y0 = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    res = r2rsim.simulate(cl, 0.5, 100.0, y0, r2rsim.SolverSettings(rtol=1e-9))
    omega = res.states[-1, cl.index("toy.speed")]
    # a frictionless roller turns with the web; the web there runs at the rewind's surface
    # speed, line speed x (1 + draw), as both spans hold the same strain
    assert omega == pytest.approx(1.0 * 1.001 / 0.06, rel=1e-9)


def test_a_registered_kind_is_listed_and_its_keys_are_checked(tmp_path, toy_kind, capsys):
    assert cli_main(["list", "elements"]) == 0
    out = capsys.readouterr().out
    assert "toy_roller        a solid-cylinder roller: radius, mass (J = m·R²/2)" in out
    assert out.index("pivot_dancer") < out.index("toy_roller") < out.index("festoon (span)")
    path = tmp_path / "toy.yaml"
    path.write_text(TOY_LINE.replace("mass: 3 kg", "mas: 3 kg"))
    with pytest.raises(InputError, match=r"unknown key 'mas' \(did you mean 'mass'\?\)"):
        r2rsim.load_line(path)


def test_unregistering_restores_the_shipped_union(toy_kind):
    assert "toy_roller" in kinds.kind_names()
    schema = Line.model_json_schema()
    assert "ToyRoller" in schema["$defs"]
    unregister("toy_roller")
    try:
        assert kinds.kind_names() == SHIPPED
        assert "ToyRoller" not in Line.model_json_schema()["$defs"]
    finally:
        register(toy_kind)  # the fixture unregisters it


def test_a_mover_kind_must_say_its_geometry():
    class HalfMover(ElementKind):
        name = "toy_roller"
        model = ToyRoller
        summary = "a mover kind without its geometry"
        family = "mover"

    with pytest.raises(ValueError, match="mover kind and needs mover_kind, coordinate_unit"):
        register(HalfMover())
    assert "toy_roller" not in kinds.kind_names()


# ---- kinds registered in a sweep's process reach its worker processes -------------------------
TOY_SCENARIO = """\
name: toy
line: toy.yaml
duration: 1 s
record_rate: 50 Hz
seed: 1
initial: {state: steady}
programme:
  - {at: 0 s, line_speed: 1 m/s}
"""

TOY_SWEEP = """\
name: toy_sweep
scenario: toy_scenario.yaml
axes:
  - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 2 m/s]}
seeds: 1
"""


def _toy_sweep(tmp_path) -> Path:
    (tmp_path / "toy.yaml").write_text(TOY_LINE)
    (tmp_path / "toy_scenario.yaml").write_text(TOY_SCENARIO)
    (tmp_path / "toy_sweep.yaml").write_text(TOY_SWEEP)
    return tmp_path / "toy_sweep.yaml"


def test_added_kinds_are_the_ones_registered_from_outside(toy_kind):
    assert kinds.added_kinds() == (toy_kind,)
    idler = kind_named("idler")
    register(idler, replace=True)  # the package's own object again: nothing added
    assert kinds.added_kinds() == (toy_kind,)
    unregister("toy_roller")
    assert kinds.added_kinds() == ()
    register(toy_kind)  # the fixture unregisters it


@pytest.mark.parametrize(
    "executor", [{"workers": 2}, {"workers": 1, "scheduler": "local"}], ids=["local", "dask"]
)
def test_a_sweeps_workers_know_the_kinds_registered_in_its_process(tmp_path, toy_kind, executor):
    """A worker process imports r2rsim afresh: the kinds registered in the sweep's process
    are sent to it. Before, every run failed there (unknown type 'toy_roller')."""
    from r2rsim.dataset.validate import validate_dataset
    from r2rsim.sweep import run_sweep

    sweep = _toy_sweep(tmp_path)
    in_workers = run_sweep(sweep, tmp_path / "workers", **executor)
    here = run_sweep(sweep, tmp_path / "here", workers=0)
    assert (in_workers.done, in_workers.failed, in_workers.ok) == (2, 0, True), in_workers
    assert here.ok
    assert validate_dataset(tmp_path / "workers") == []
    files = sorted(f for f in (tmp_path / "here" / "samples").rglob("*") if f.is_file())
    assert len(files) == 2
    for f in files:
        there = tmp_path / "workers" / f.relative_to(tmp_path / "here")
        assert there.read_bytes() == f.read_bytes()


def test_kinds_the_workers_cannot_load_stop_the_sweep_with_one_message(tmp_path):
    """Kind classes the workers cannot import (here: their module is gone; in practice a
    notebook's or a script's `if __name__ == "__main__":` block) stop the sweep with one
    message saying what to do, rather than failing every run."""
    import importlib
    import sys

    from r2rsim.sweep import run_sweep
    from r2rsim.sweep._execute import WorkerSetupError

    (tmp_path / "gone_kinds.py").write_text(
        "from test_element_kinds import ToyRoller, ToyRollerKind\n\n\n"
        "class GoneKind(ToyRollerKind):\n    pass\n"
    )
    sys.path.insert(0, str(tmp_path))
    try:
        gone = importlib.import_module("gone_kinds")
        register(gone.GoneKind())
        (tmp_path / "gone_kinds.py").unlink()
        with pytest.raises(WorkerSetupError, match="cannot load the element kinds registered"):
            run_sweep(_toy_sweep(tmp_path), tmp_path / "ds", workers=1)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("gone_kinds", None)
        unregister("toy_roller")
    assert not (tmp_path / "ds" / "manifest.json").exists()


def test_kinds_that_cannot_be_pickled_are_refused_before_anything_is_written(tmp_path):
    from r2rsim.sweep import run_sweep
    from r2rsim.sweep._execute import kinds_for_workers

    class LocalKind(ToyRollerKind):  # a class inside a function: not picklable
        pass

    register(LocalKind())
    sweep = _toy_sweep(tmp_path)
    try:
        with pytest.raises(InputError, match=r"\('toy_roller'\) cannot be sent to the sweep"):
            run_sweep(sweep, tmp_path / "ds", workers=1)
        assert not (tmp_path / "ds").exists()
        assert run_sweep(sweep, tmp_path / "here", workers=0).ok  # in this process: fine
    finally:
        unregister("toy_roller")
    assert kinds_for_workers() == b""
