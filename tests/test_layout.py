"""The record families of the flat arrays (compile/layout.py) and their views on a compiled
line: every field is declared once, the sizes are the enums' lengths, and the views read and
write the arrays the kernel reads."""

from enum import IntEnum

import numpy as np

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
