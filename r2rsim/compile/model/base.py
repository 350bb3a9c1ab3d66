"""What every phase of the line kernel shares: the ``kernel`` decorator, record and scratch
views, gradient ids, and the sparse chain-rule helpers.

Conventions of a phase (see ``docs/model.md``, "Adding an element kind"):

* A phase is a ``@kernel`` function ``phase(t, y, yd, JJ, mode, I, P, W, GI, GC, GV)`` (a
  phase that needs the line speed takes ``V, A`` after ``t``). It reads the records of its
  family through views (``node_i, node_p = nodes(I, P)``), the intermediates of earlier
  phases through :func:`scratch` (``w.tension[i]``), and writes its own.
* With ``mode`` JAC or TOUCH it also records, for each intermediate it computes, a short
  sparse gradient with respect to the states (:func:`g_add`, :func:`g_axpy` into quantity
  ``qid.<name> + i``), and adds the chain rule of each state derivative it writes into the
  Jacobian (:func:`j_add`, :func:`j_axpy`). Every dependency is recorded whichever branch is
  taken (with a zero derivative where it is inactive), so the sparsity pattern the compiler
  obtains with TOUCH is the same at every state.
* Nothing allocates and nothing touches a Python object.

``kernel`` compiles with ``forceinline``: LLVM inlines every phase into the orchestrator
:func:`r2rsim.compile.kernels.evaluate`, so splitting the physics into functions costs no
calls. Without it (measured 2026-11-27, quickstart) the phase calls, each passing eleven
arrays, made the right-hand side about twice as slow.
"""

from __future__ import annotations

from collections import namedtuple

from numba import njit
from numba.core import cgutils, types
from numba.core.caching import FunctionCache
from numba.core.datamodel.models import ArrayModel
from numba.extending import intrinsic, register_model
from numba.np.arrayobj import make_array, populate_array

from ..layout import FROZEN, RECORD_BLOCKS
from ..stamp import kernel_stamp

# the record fields and kinds as plain-int namedtuples: numba reads them as constants with
# every supported numba version (layout.frozen says why not the IntEnums themselves)
CtrlI = FROZEN["CtrlI"]
CtrlKind = FROZEN["CtrlKind"]
CtrlP = FROZEN["CtrlP"]
DriveKind = FROZEN["DriveKind"]
EventI = FROZEN["EventI"]
EventKind = FROZEN["EventKind"]
FaultP = FROZEN["FaultP"]
H = FROZEN["H"]
JointP = FROZEN["JointP"]
Mode = FROZEN["Mode"]
MoverI = FROZEN["MoverI"]
MoverKind = FROZEN["MoverKind"]
MoverP = FROZEN["MoverP"]
NodeI = FROZEN["NodeI"]
NodeKind = FROZEN["NodeKind"]
NodeP = FROZEN["NodeP"]
SensorI = FROZEN["SensorI"]
SensorKind = FROZEN["SensorKind"]
SensorP = FROZEN["SensorP"]
Shape = FROZEN["Shape"]
SpanI = FROZEN["SpanI"]
SpanP = FROZEN["SpanP"]
TableI = FROZEN["TableI"]
TableKind = FROZEN["TableKind"]


# --------------------------------------------------------------------------- numba's cache
class StampedCache(FunctionCache):
    """numba's cache of one function, with the stamp of the kernel's sources in its key."""

    def __init__(self, py_func, stamp: int):
        super().__init__(py_func)
        self._stamp = stamp

    def _index_key(self, sig, codegen):
        return (*super()._index_key(sig, codegen), self._stamp)


#: hash of every module of the kernel and of layout.py: the record fields are compiled in as
#: constants and the phases are inlined into the cached kernel, which numba's own key (a
#: function's own file time stamp and bytecode) does not see; see :mod:`..stamp`
STAMP = kernel_stamp()


def kernel(fn=None, *, inline: bool = True, python: bool = False):
    """``numba.njit`` for the line kernel.

    With ``inline`` (the default) the function is inlined by LLVM into every compiled
    caller, and it is neither cached nor given the wrappers that let Python call it (unless
    ``python``): only its callers' machine code is ever run, and those are cached (a cached
    :func:`r2rsim.compile.kernels.evaluate` needs none of its phases compiled again).
    Otherwise it is cached under :data:`STAMP`.
    """

    def wrap(f):
        if inline:
            opts: dict = {"forceinline": True}
            if not python:
                opts.update(no_cpython_wrapper=True, no_cfunc_wrapper=True)
            return njit(**opts)(f)
        # forceinline=False said explicitly: numba passes a caller's forceinline on to the
        # functions it calls unless they set it, which inlined every helper everywhere (the
        # kernel's code grew 2.8-fold and so did the compile time of its callers)
        disp = njit(cache=True, forceinline=False)(f)
        disp._cache = StampedCache(f, STAMP)
        return disp

    return wrap if fn is None else wrap(fn)


# --------------------------------------------------------------------------- record views
class Borrowed(types.Array):
    """numba type of a view that borrows the memory of an array it does not own (the record
    and scratch views below): an array whose data model has no reference count, so numba
    emits no NRT incref/decref for it (for an array it does, even when the meminfo is null,
    and it did so hundreds of times per evaluation once the phases were separate functions:
    the right-hand side was ~40 % slower). A view must not outlive the array it borrows from,
    which holds for views made and dropped inside one kernel call."""

    def __init__(self, dtype, ndim, layout):
        super().__init__(dtype, ndim, layout, name=f"borrowed({dtype}, {ndim}d, {layout})")

    def copy(self, dtype=None, ndim=None, layout=None, readonly=None):
        """A borrowed view's derived types (a slice, a row) are borrowed too."""
        if readonly:
            return super().copy(dtype, ndim, layout, readonly)
        return Borrowed(
            self.dtype if dtype is None else dtype,
            self.ndim if ndim is None else ndim,
            self.layout if layout is None else layout,
        )


@register_model(Borrowed)
class _BorrowedModel(ArrayModel):
    """An array's data model whose meminfo numba does not track (see :class:`Borrowed`)."""

    def traverse(self, builder):
        return []


@intrinsic
def records(typingctx, a, start, n, size):
    """Zero-copy C-contiguous (n, size) view of the ``n`` records of ``size`` fields at
    ``a[start:]`` (``a`` a 1-D C array): ``node_p = records(P, o, nN, N_NODE_P)`` reads
    ``node_p[k, NodeP.R]``.

    Not ``a[start:stop].reshape(n, size)``: numba's reshape checks the new shape at run time,
    which made an evaluation ~400 ns slower (12 views; quickstart and newsprint_splice, the
    right-hand side +65-90 %); and not ``as_strided``: its 'A'-layout view made the Jacobian
    ~65 % slower (measured 2026-11-27). This only fills the array structure. The view holds
    no reference (its meminfo is null): it must not outlive ``a``, which holds for views made
    and dropped inside one kernel call.
    """
    if not (isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C"):
        return None
    sig = Borrowed(a.dtype, 2, "C")(a, start, n, size)
    return sig, _view_codegen(2)


@intrinsic
def block(typingctx, a, start, n):
    """Zero-copy view ``a[start:start + n]`` of a 1-D C array, without a reference (as
    :func:`records`): the scratch blocks of :func:`scratch`."""
    if not (isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C"):
        return None
    return Borrowed(a.dtype, 1, "C")(a, start, n), _view_codegen(1)


@intrinsic
def borrow(typingctx, a):
    """``a`` itself, typed :class:`Borrowed`: what the orchestrator passes to the phases, so
    that a phase's array arguments cost no reference counting (numba increfs and decrefs an
    array argument of a function that can raise, on every call)."""
    if not isinstance(a, types.Array) or isinstance(a, Borrowed):
        return None
    sig = Borrowed(a.dtype, a.ndim, a.layout)(a)

    def codegen(context, builder, sig, args):
        return args[0]  # the same structure: only the type changes

    return sig, codegen


def _view_codegen(ndim):
    def codegen(context, builder, sig, args):
        aryty = sig.args[0]
        ary = make_array(aryty)(context, builder, args[0])
        vals = [
            context.cast(builder, v, t, types.intp)
            for v, t in zip(args[1:], sig.args[1:], strict=True)
        ]
        start_, shape = vals[0], vals[1:]
        itemsize = ary.itemsize
        strides = [itemsize] if ndim == 1 else [builder.mul(shape[1], itemsize), itemsize]
        out = make_array(sig.return_type)(context, builder)
        populate_array(
            out,
            data=builder.gep(ary.data, [start_]),
            shape=cgutils.pack_array(builder, shape),
            strides=cgutils.pack_array(builder, strides),
            itemsize=itemsize,
            meminfo=None,
        )
        return out._getvalue()

    return codegen


def _header(context, builder, sig, args, slot):
    """I[slot] (I is the first argument) as an intp, in generated code."""
    ary = make_array(sig.args[0])(context, builder, args[0])
    return builder.load(builder.gep(ary.data, [context.get_constant(types.intp, int(slot))]))


def _view(context, builder, aryty, ary, start, n, size=None):
    """A borrowed view of ``n`` records (rows of ``size``; 1-D without it) at ``start``."""
    retty = Borrowed(aryty.dtype, 1 if size is None else 2, "C")
    dims = [n] if size is None else [n, context.get_constant(types.intp, size)]
    sig = retty(aryty, *([types.intp] * (1 + len(dims))))
    return _view_codegen(retty.ndim)(context, builder, sig, [ary, start, *dims])


#: the record families by view name (``node_p``): (array, 0 for I or 1 for P, header slot of
#: the offset, of the count, fields per record), from layout.RECORD_BLOCKS
RECORDS = {
    f"{family}_{array.lower()}": (0 if array == "I" else 1, off, count, len(fields))
    for (family, array), (off, count, fields) in RECORD_BLOCKS.items()
}


def _family(*names, doc):
    """An intrinsic ``f(I, P)`` returning the views of the record families ``names`` (one
    view, or a tuple of them). An intrinsic, not a compiled function: it costs no
    compilation of its own (each compiled kernel function cost ~0.1-0.9 s)."""

    def typer(typingctx, I, P):
        arrays = (I, P)
        views = [Borrowed(arrays[RECORDS[n][0]].dtype, 2, "C") for n in names]
        retty = views[0] if len(views) == 1 else types.Tuple(views)

        def codegen(context, builder, sig, args):
            out = []
            for n in names:
                which, off, count, size = RECORDS[n]
                start = _header(context, builder, sig, args, off)
                num = _header(context, builder, sig, args, count)
                out.append(_view(context, builder, sig.args[which], args[which], start, num, size))
            if len(out) == 1:
                return out[0]
            return context.make_tuple(builder, sig.return_type, out)

        return retty(I, P), codegen

    typer.__name__ = "_".join(names)
    typer.__doc__ = doc
    return intrinsic(typer)


nodes = _family("node_i", "node_p", doc="(node_i, node_p): the records of rolls and rollers.")
spans = _family("span_i", "span_p", doc="(span_i, span_p): the records of the spans.")
sensors = _family("sensor_i", "sensor_p", doc="(sensor_i, sensor_p): the sensors' records.")
controllers = _family("ctrl_i", "ctrl_p", doc="(ctrl_i, ctrl_p): the controllers' records.")
movers = _family("mover_i", "mover_p", doc="(mover_i, mover_p): dancers and festoon carriages.")
joints = _family("joint_p", doc="joint_p(I, P): the splice-joint slots.")
fault_slots = _family("fault_p", doc="fault_p(I, P): the fault parameter slots.")
events = _family("event_i", doc="event_i(I, P): the event records.")


# --------------------------------------------------------------------------- scratch
#: the intermediates one evaluation computes: one block of the scratch array W each, in this
#: order, of (header count, per record) entries
SCRATCH = {
    "tension": (H.NS, 1),  # T [N]
    "strain_web": (H.NS, 1),  # strain carried through the nodes, T/EA of the plain web
    "length": (H.NS, 1),  # L [m]
    "length_rate": (H.NS, 1),  # dL/dt [m/s]
    "dlength_dq": (H.NS, 1),  # dL/dq of a mover's span
    "d2length_dq2": (H.NS, 1),  # d2L/dq2
    "ea_eff": (H.NS, 1),  # E·A of the span, softened by a splice joint in it [N]
    "speed": (H.NN, 1),  # surface speed v [m/s]
    "radius": (H.NN, 1),  # R [m]
    "omega": (H.NN, 1),  # angular speed [rad/s]
    "inertia": (H.NN, 1),  # J(R) [kg m2]
    "speed_trim": (H.NN, 1),  # trim of an imposed or controlled speed [m/s]
    "torque_cmd": (H.NN, 1),  # commanded motor torque [N m]
    "torque": (H.NN, 1),  # applied motor torque [N m]
    "raw": (H.NSE, 1),  # sensor reading before its filter
    "seen": (H.NSE, 1),  # reading the controllers see
    "ctrl_out": (H.NC, 1),  # controller output
    "ctrl_err": (H.NC, 1),  # controller error
    "mover_force": (H.NM, 1),  # net force on a mover without friction
    "mover_web": (H.NM, 1),  # the web's share of it
    "joint_factor": (H.NN, 1),  # EA/EA_joint on the strain a node carries (1: no joint)
    "raw_true": (H.NSE, 1),  # fault-free raw reading (the true channel)
    "wound_strain": (H.NN, 2),  # an unwind's wound-in strain and its d/dR
    "drag_cache": (H.NN, 7),  # bearing-drag cache: three times, their torques, next slot
}
Scratch = namedtuple("Scratch", list(SCRATCH))  # type: ignore[misc]
DRAG_CACHE = SCRATCH["drag_cache"][1]

#: gradient quantities (a short sparse gradient each), ``qid.tension + i``, of (header count)
QUANTITIES = {
    "tension": H.NS,
    "length": H.NS,
    "length_rate": H.NS,
    "speed": H.NN,
    "radius": H.NN,
    "omega": H.NN,
    "speed_trim": H.NN,
    "torque_cmd": H.NN,
    "torque": H.NN,
    "raw": H.NSE,
    "seen": H.NSE,
    "ctrl_out": H.NC,
    "ctrl_err": H.NC,
}
Quantities = namedtuple("Quantities", [*QUANTITIES, "count"])  # type: ignore[misc]


def scratch_blocks(I) -> dict[str, tuple[int, int]]:
    """(start, length) in W of every :data:`SCRATCH` block of a compiled line (Python)."""
    out, start = {}, 0
    for name, (count, per) in SCRATCH.items():
        out[name] = (start, int(I[count]) * per)
        start += out[name][1]
    return out


def scratch_layout(I) -> tuple[int, int]:
    """(start of the drag cache, length W needs): the compiler sizes W with them and marks
    the cache empty."""
    start, n = scratch_blocks(I)["drag_cache"]
    return start, start + n


def quantity_offsets(I) -> Quantities:
    """First gradient quantity of each block, and their count (Python)."""
    out, q = [], 0
    for count in QUANTITIES.values():
        out.append(q)
        q += int(I[count])
    return Quantities._make([*out, q])


@intrinsic
def scratch(typingctx, I, W):
    """The :data:`SCRATCH` blocks of W as borrowed views (``w.tension[i]``)."""
    view = Borrowed(W.dtype, 1, "C")
    retty = types.NamedUniTuple(view, len(SCRATCH), Scratch)

    def codegen(context, builder, sig, args):
        start = context.get_constant(types.intp, 0)
        views = []
        for count, per in SCRATCH.values():
            n = _header(context, builder, sig, args, count)
            if per != 1:
                n = builder.mul(n, context.get_constant(types.intp, per))
            views.append(_view(context, builder, sig.args[1], args[1], start, n))
            start = builder.add(start, n)
        return context.make_tuple(builder, sig.return_type, views)

    return retty(I, W), codegen


@intrinsic
def quantity_ids(typingctx, I):
    """First gradient quantity of each block (:data:`Quantities`), in compiled code."""
    retty = types.NamedUniTuple(types.intp, len(Quantities._fields), Quantities)

    def codegen(context, builder, sig, args):
        q = context.get_constant(types.intp, 0)
        out = []
        for count in QUANTITIES.values():
            out.append(q)
            q = builder.add(q, _header(context, builder, sig, args, count))
        return context.make_tuple(builder, sig.return_type, [*out, q])

    return retty(I), codegen


# --------------------------------------------------------------------------- sparse gradients
@kernel(inline=False)
def g_add(GI, GC, GV, maxd, q, idx, val):
    """Add ``val`` to d(quantity q)/d(state idx)."""
    base = q * maxd
    n = GC[q]
    for m in range(n):
        if GI[base + m] == idx:
            GV[base + m] += val
            return
    if n >= maxd:
        raise RuntimeError("r2rsim kernel: too many dependencies for one quantity")
    GI[base + n] = idx
    GV[base + n] = val
    GC[q] = n + 1


@kernel(inline=False)
def g_axpy(GI, GC, GV, maxd, qdst, a, qsrc):
    """Add ``a`` times the gradient of quantity ``qsrc`` to that of ``qdst``."""
    base = qsrc * maxd
    for m in range(GC[qsrc]):
        g_add(GI, GC, GV, maxd, qdst, GI[base + m], a * GV[base + m])


@kernel(inline=False)
def j_add(JJ, mode, row, col, val):
    """Add ``val`` to the Jacobian entry (row, col) (TOUCH: mark it)."""
    if mode == Mode.TOUCH:
        JJ[row, col] = 1.0
    else:
        JJ[row, col] += val


@kernel(inline=False)
def j_axpy(JJ, mode, row, a, GI, GC, GV, maxd, q):
    """Add ``a`` times the gradient of quantity ``q`` to Jacobian row ``row``."""
    base = q * maxd
    for m in range(GC[q]):
        j_add(JJ, mode, row, GI[base + m], a * GV[base + m])
