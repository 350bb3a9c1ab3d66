"""The record families of the flat arrays (compile/layout.py) and their views on a compiled
line: every field is declared once, the sizes are the enums' lengths, and the views read and
write the arrays the kernel reads."""

import ast
from enum import IntEnum

import numpy as np
import pytest

import r2rsim
from r2rsim.compile import layout
from r2rsim.compile.layout import H, MoverP, NodeI, NodeP, SpanI, SpanP

from conftest import REPO

FAMILIES = {
    "NODE_I": layout.NodeI,
    "NODE_P": layout.NodeP,
    "SPAN_I": layout.SpanI,
    "SPAN_P": layout.SpanP,
    "SENSOR_I": layout.SensorI,
    "SENSOR_P": layout.SensorP,
    "CTRL_I": layout.CtrlI,
    "CTRL_P": layout.CtrlP,
    "MOVER_I": layout.MoverI,
    "MOVER_P": layout.MoverP,
    "JOINT_P": layout.JointP,
    "FAULT_P": layout.FaultP,
    "TABLE_I": layout.TableI,
    "EVENT_I": layout.EventI,
}


def test_record_fields_are_dense_and_sized_by_their_enum():
    for name, enum in FAMILIES.items():
        assert issubclass(enum, IntEnum)
        assert [int(f) for f in enum] == list(range(len(enum))), name
        assert getattr(layout, f"N_{name}") == len(enum), name
    assert max(H) < layout.HEADER
    assert list(layout.RUNTIME_MODE) == [int(m) for m in layout.Mode]


def test_views_of_a_compiled_line_are_the_kernel_arrays():
    cl = r2rsim.compile_line(r2rsim.load_line(REPO / "lines" / "pet_film_line_dancer.yaml"))
    nN, nS, nM = len(cl.node_ids), len(cl.span_ids), len(cl.mover_ids)
    assert cl.node_p.shape == (nN, len(NodeP)) and cl.node_i.shape == (nN, len(NodeI))
    assert cl.span_p.shape == (nS, len(SpanP)) and cl.span_i.shape == (nS, len(SpanI))
    assert cl.mover_p.shape == (nM, len(MoverP)) and nM > 0
    for view, arr in (
        (cl.node_p, cl.P),
        (cl.node_i, cl.I),
        (cl.span_p, cl.P),
        (cl.mover_p, cl.P),
        (cl.ctrl_p, cl.P),
        (cl.sensor_p, cl.P),
    ):
        assert np.shares_memory(view, arr)
    k = nN // 2
    assert cl.node_p[k, NodeP.R] == cl.P[cl.I[H.OFF_NP] + k * len(NodeP) + NodeP.R]
    assert cl.node_param(k, "TEFF") == 1.0
    cl.set_node_param(k, "TEFF", 0.5)
    assert cl.P[cl.I[H.OFF_NP] + k * len(NodeP) + NodeP.TEFF] == 0.5
    for i in range(nS):  # span i runs from node i to node i + 1
        assert cl.span_i[i, SpanI.UP] == i and cl.span_i[i, SpanI.DN] == i + 1
        assert cl.node_i[i, NodeI.SPAN_DN] == i


def test_fields_by_name_on_a_compiled_line():
    cl = r2rsim.compile_line(r2rsim.load_line(REPO / "lines" / "battery_foil_line.yaml"))
    k = cl.node_ids.index("dancer")
    m = cl.mover_ids.index("dancer")
    # every family's fields by name are the views' entries, and writes reach P
    assert cl.param("node", k, "R") == cl.node_p[k, NodeP.R]
    assert cl.param_index("node", k, "TEFF") == cl.I[H.OFF_NP] + k * len(NodeP) + NodeP.TEFF
    assert cl.field("mover", m, "Q") == cl.mover_i[m, layout.MoverI.Q]
    assert cl.field("span", 1, "DN") == 2
    cl.set_param("mover", m, "FRICF", 2.0)
    assert cl.mover_p[m, MoverP.FRICF] == 2.0
    c = [c.id for c in cl.line.controllers].index("rewind_tension")
    cl.set_param("ctrl", c, "SETP", 61.0)
    assert cl.ctrl_p[c, layout.CtrlP.SETP] == 61.0
    assert cl.field("event", 0, "KIND") == cl.event_kinds[0]
    assert cl.header("NN") == len(cl.node_ids)
    # kinds by name
    assert cl.kind("node", 0) == "UNWIND" and cl.kind("node", k) == "ROLLER"
    assert cl.kind("node", 0, "DRIVE") == "TORQUE"
    assert cl.kind("mover", m) == "PIVOT"
    assert cl.kind("ctrl", c) == "TENSION_TORQUE"
    assert [cl.kind("event", e) for e in range(len(cl.event_kinds))] == [
        layout.EventKind(v).name for v in cl.event_kinds
    ]
    # a typo names the family and its fields
    with pytest.raises(KeyError, match="node records have no float field 'TEF'.*TEFF"):
        cl.param("node", k, "TEF")
    with pytest.raises(KeyError, match="mover records have no int field 'QQ'.*QD"):
        cl.field("mover", m, "QQ")
    with pytest.raises(KeyError, match="no float record family 'nodes'.*node"):
        cl.param("nodes", k, "TEFF")
    with pytest.raises(KeyError, match="no int record family 'joint'"):
        cl.field("joint", 0, "ACTIVE")
    with pytest.raises(KeyError, match="header has no field"):
        cl.header("NNN")
    with pytest.raises(IndexError):
        cl.param("node", len(cl.node_ids), "R")


def _layout_imports(text: str, pkg: tuple) -> list[str]:
    """The imports of r2rsim.compile.layout (absolute or relative) in the source ``text`` of
    a module of package ``pkg`` (e.g. ``("r2rsim", "solve")``)."""
    tree = ast.parse(text)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.startswith("r2rsim.compile.layout")]
        elif isinstance(node, ast.ImportFrom):
            base = list(pkg[: len(pkg) - node.level + 1]) if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            names = [f"{mod}.{a.name}" if mod else a.name for a in node.names]
            if mod.startswith("r2rsim.compile.layout") or "r2rsim.compile.layout" in names:
                found.append(mod)
    return found


def test_solve_imports_no_record_layout():
    # the solver names record fields by string through CompiledLine (param, field, kind,
    # ...); the integrator takes its evaluation mode from compile.kernels
    files = sorted((REPO / "r2rsim" / "solve").rglob("*.py"))
    assert files
    offenders = {
        str(f.relative_to(REPO)): _layout_imports(
            f.read_text(encoding="utf-8"), f.relative_to(REPO).parts[:-1]
        )
        for f in files
    }
    assert {f: v for f, v in offenders.items() if v} == {}
    # the check itself sees both spellings
    for text in (
        "from ...compile.layout import H\n",
        "from ...compile import layout\n",
        "import r2rsim.compile.layout as L\n",
        "def f():\n    from r2rsim.compile.layout import NodeP\n",
    ):
        assert _layout_imports(text, ("r2rsim", "solve", "backends")), text
    assert not _layout_imports(
        "from ...compile.kernels import evaluate\n", ("r2rsim", "solve", "backends")
    )


def test_the_kernel_reads_plain_int_twins_of_the_enums():
    """The kernel's field names are namedtuples of ints with the enums' values: numba < 0.64
    (the lowest supported is 0.59) refuses an IntEnum member as an array index."""
    from r2rsim.compile import layout
    from r2rsim.compile.model import base

    for name, twin in layout.FROZEN.items():
        enum = getattr(layout, name)
        assert getattr(base, name) is twin
        assert isinstance(twin, tuple) and not isinstance(twin[0], IntEnum)
        assert twin._fields == tuple(enum.__members__)
        assert [type(v) for v in twin] == [int] * len(enum)
        assert list(twin) == [int(m) for m in enum]
