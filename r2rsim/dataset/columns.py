"""Column naming of the samples table: ``<kind>.<component>.<quantity>_<unit>``.

kinds: ``meas`` (measured: what algorithms see), ``true`` (noise-free shadow of a measured
channel; never for algorithms), ``state`` (hidden physical states), ``act``/``cmd`` (applied
and commanded actuation), ``sp`` (set-points), ``ctrl`` (controller internals), ``label``.
"""

from __future__ import annotations

from ..compile.compiler import CompiledLine

_NODE_DESC = {
    "surface_speed_m_s": "surface speed of the web on the element",
    "speed_rad_s": "angular speed",
    "radius_m": "radius (roll radius for unwind/rewind)",
    "inertia_kg_m2": "rotating inertia J(R)",
    "web_mass_kg": "mass of web wound on the roll",
    "torque_N_m": "drive torque applied at the shaft",
    "torque_command_N_m": "drive torque commanded by the controllers (before saturation/lag)",
    "tension_ratio": "T_hi/T_lo of the two spans (capstan margin)",
}


_MOVER_DESC = {
    "position": "dancer travel / arm angle / festoon carriage position",
    "velocity": "rate of the position",
    "web_force": "generalised force of the web on the dancer or carriage",
    "static_force": "web plus load force at rest (pushes into a stop when latched)",
    "stop_state": "0 free, -1 at the lower stop, +1 at the upper stop, 2 seized",
}


def true_state_columns(cl: CompiledLine) -> list[dict]:
    """Describe each algebraic output written to the samples table.

    Returns a list of dicts: ``aux`` (column in ``cl.outputs``), ``column``, ``kind``,
    ``component``, ``quantity``, ``unit``, ``description``.
    """
    out = []
    for j, name in enumerate(cl.aux_names):
        comp, _, q = name.partition(".")
        unit = cl.aux_units[j]
        mq = (
            q.split("_")[0]
            if not q.startswith(("web_", "static_", "stop_"))
            else "_".join(q.split("_")[:2])
        )
        if comp in cl.mover_ids and mq in _MOVER_DESC:
            kind, desc = "state", _MOVER_DESC[mq]
        elif comp.startswith("splice_joint"):
            kind = "state"
            desc = {
                "lead_m": "unstretched web length from the unwind to the joint's leading "
                "edge (NaN: no joint on the line)",
                "span_index": "index of the span holding the joint's leading edge (-1: none)",
            }[q]
        elif comp in cl.span_ids:
            kind = "state"
            desc = {
                "tension_N": "span tension (true)",
                "geometric_strain": "geometric strain L/l - 1 (< 0: slack)",
                "length_m": "span path length (changes with a dancer or festoon)",
            }[q]
        elif comp in cl.node_ids:
            if q == "tension_ratio" and comp in (cl.node_ids[0], cl.node_ids[-1]):
                continue  # an end roll has one span: no capstan ratio
            kind = {"torque_N_m": "act", "torque_command_N_m": "cmd"}.get(q, "state")
            desc = _NODE_DESC[q]
            if kind != "state":
                q = "torque_N_m"
        elif comp == "setpoint":
            kind = "sp"
            desc = "set-point from the operating programme"
            comp, _, q = q.rpartition(".") if "." in q else ("line", "", q)
        elif any(comp == s.id for s in cl.sensors):
            if "_seen_" in q:
                kind, desc = "ctrl", "signal the controllers see (calibrated, filtered, no noise)"
            elif q == "force_N":
                if next(s for s in cl.sensors if s.id == comp).type != "load_cell":
                    continue
                kind, desc = "state", "bearing force along the load-cell axis (true)"
            else:
                continue  # the true shadow is written by the measurement stage
        else:
            kind = "ctrl"
            desc = {
                "error": "controller error",
                "output": "controller output",
                "integral": "integrator state",
            }[q.split("_")[0]]
        col = f"{kind}.{comp}.{q}" if comp != "line" else f"{kind}.{q}"
        out.append(
            {
                "aux": j,
                "column": col,
                "kind": kind,
                "component": comp,
                "quantity": q,
                "unit": unit,
                "description": desc,
            }
        )
    return out
