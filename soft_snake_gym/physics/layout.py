"""The simulator's array layout (docs/model.md §2-§5a): index constants and :class:`SimArrays`.

Conventions: positions ``q`` and velocities ``v`` are flat, interleaved arrays of length 2N
(``q[2i], q[2i+1]`` are x, y of node i) so that they index the banded Jacobian directly; the
simulator exposes them as (N, 2) views. Rest curvatures ``kbar`` (N-2) belong to the interior
nodes 1..N-2 (``kbar[j-1]`` at node j), rest lengths ``lbar`` (N-1) to the edges.

Parameters travel in one float64 vector ``prm`` (indices ``P_*``), per-robot scratch in
``buf`` (rows ``B_*``, each 2N long), integer scratch in ``ibuf`` (rows ``I_*``) and step
diagnostics in ``out`` (indices ``O_*``). :class:`SimArrays` names the arrays of one robot
(or, with a leading axis, of a batch); the kernels take it as one argument.

The float arrays are views of one block per robot, ``f`` (:func:`sim_offsets`), so that a
step's hot calls pass two arrays, ``f`` and ``ibuf``, and rebuild the views in compiled code
(:func:`sim_views`, free there): numba's dispatcher unboxes every array argument, about 0.2 µs
each. Other calls from Python pass ``tuple(arrays)`` and the kernel turns it back into
``SimArrays`` on entry (:func:`borrowed_arrays`): numba's dispatcher types a plain tuple of
arrays in C but a NamedTuple in Python, about 5 µs more per call. Both give the kernels
:func:`borrowed` views: numba keeps an atomic reference count on every view of an unboxed
array, which was a quarter of a single env's compiled step. A borrowed view still calls numba's
runtime at each count (which returns at once), so the kernels that allocate no array and return
none are compiled without counts at all (``_nrt=False``, docs/architecture.md); where they copy
one array into another they use :func:`copy_into`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic, overload
from numba.np.arrayobj import populate_array

from soft_snake_gym.physics.banded import WIDTH

# --- parameter vector ----------------------------------------------------------------------
P_EA, P_EI, P_DBEND, P_RHO, P_CF, P_CD, P_CA, P_A, P_B = 0, 1, 2, 3, 4, 5, 6, 7, 8
P_MUS, P_MUD, P_VTOL, P_G = 9, 10, 11, 12
P_H, P_SUBSTEPS, P_TOL, P_MAXIT, P_MEDIUM, P_METHOD, P_MAXSTRAIN, P_CHECKSI = (
    13,
    14,
    15,
    16,
    17,
    18,
    19,
    20,
)
P_DSTRETCH = 21
P_ADDED_MASS = 22  # ADDED_MASS_* code

P_ANISO, P_MU_FWD, P_MU_BWD, P_MU_LAT = 23, 24, 25, 26  # anisotropic kinetic friction
P_CHORD = 27  # Integrator.newton_chord_rate
P_LAG = 28  # Rod.length_lag [s]
N_PRM = 29

ADDED_MASS_CONSISTENT, ADDED_MASS_KELASIDI = 0, 1

MEDIUM_NONE, MEDIUM_WATER, MEDIUM_GROUND = 0, 1, 2
METHOD_BACKWARD_EULER, METHOD_SYMPLECTIC_EULER, METHOD_SDIRK2, METHOD_BDF2 = 0, 1, 2, 3

# --- scratch rows ----------------------------------------------------------------------------
B_R, B_DV, B_F, B_Q0, B_V0, B_VACC, B_M, B_FEXT, B_KEYS, B_A, B_P0, B_VSTEP = range(12)
# state, not scratch: the rest-length rates the length actuators have reached (the first N-1
# entries; Rod.length_lag), kept between steps and zeroed by Simulator.reset
B_LRATE = 12
# state: the position at the start of the last step (BDF2's history; NaN, set by
# Simulator.set_state, while there is none)
B_QPREV = 13
# scratch: the edges' lengths with their reciprocals and their unit tangents of the current iterate
# (geometry.edge_geometry), two rows from here (``buf[B_GEO : B_GEO + 2]``), computed once for the
# force kernels that use them
B_GEO = 14
# the reciprocals of the masses in B_M, set with them: Newton's max-norm |R|/m multiplies
B_MINV = 16
# scratch, on the ground: the velocity each sliding node has slid with since the step began, or
# since it was released (its first guess): the direction stepper._stick_reversing_nodes tests against
B_VSLIDE = 17
N_BUF = 18
I_PIV, I_ORDER, I_FRICTION, I_SWITCHES = 0, 1, 2, 3
N_IBUF = 4
SLIDING, STUCK = 0, 1
MAX_SWITCHES = 5  # contact changes per node and step (sticks and releases): bounds the passes

# --- diagnostics -----------------------------------------------------------------------------
(
    O_STATUS,
    O_NITER,
    O_RESIDUAL,
    O_P_FLUID,
    O_P_FRICTION,
    O_P_ACT,
    O_E_FLUID,
    O_E_FRICTION,
    O_E_ACT,
    O_W_ACT,
    O_NSTEPS,
) = range(11)
# energy ledger (docs/model.md §4): damping power of the last step and its accumulated energy, and
# the body's kinetic and elastic energy and the water's kinetic energy T_f after the last step
O_P_DAMP, O_E_DAMP, O_E_KIN, O_E_ELASTIC, O_T_FLUID = range(11, 16)
# where the ledger starts (written at reset/set_state): those energies and the accumulated work
# and dissipation at that moment
O_L0_KIN, O_L0_ELASTIC, O_L0_T_FLUID, O_L0_W_ACT, O_L0_E_FLUID, O_L0_E_DAMP, O_L0_E_FRICTION = range(16, 23)
# the ledger since then, ``out[O_LEDGER : O_LEDGER + 8]`` in the order of LEDGER_KEYS
O_LEDGER, N_LEDGER = 23, 8
LEDGER_KEYS = (
    "actuator_work",
    "fluid_dissipation",
    "damping_dissipation",
    "friction_dissipation",
    "delta_kinetic",
    "delta_elastic",
    "delta_fluid_kinetic",
    "error",
)
# Newton's work in the last step (summed over its stages and sub-steps): Jacobian assemblies (each
# with its residual), residuals alone (line-search trials, chord steps) and factorizations
O_NJAC, O_NRES, O_NFACTOR = 31, 32, 33
N_OUT = 34  # simulated time is O_NSTEPS * h: derived, so it cannot drift


def energy_ledger(out: list[float]) -> dict[str, float]:
    """The energy ledger by name (:data:`LEDGER_KEYS`) from one robot's ``out`` as a list."""
    return dict(zip(LEDGER_KEYS, out[O_LEDGER : O_LEDGER + N_LEDGER], strict=False))  # not strict: 8 of N_OUT


# --- status codes ----------------------------------------------------------------------------
OK, NOT_CONVERGED, NON_FINITE, SELF_INTERSECTION, RUNAWAY_STRETCH, BAD_REST_LENGTH = range(6)
STATUS_REASONS = (
    "ok",
    "newton_not_converged",
    "non_finite_state",
    "self_intersection",
    "runaway_stretch",
    "non_positive_rest_length",
)


class SimArrays(NamedTuple):
    """The arrays of one robot's simulation (or of ``n`` robots, stacked on a leading axis).

    As the kernels take them. numba passes a ``NamedTuple`` of arrays as one argument. The float
    arrays are views of ``f``; a pickled ``SimArrays`` keeps them so.

    Attributes:
        q: node positions, interleaved (x0, y0, x1, ...), (2N,) [m].
        v: node velocities, same layout, (2N,) [m/s].
        kbar: rest curvatures of the interior nodes, (N-2,) [-].
        lbar: rest lengths of the edges, (N-1,) [m].
        prm: parameters at ``P_*``, (N_PRM,).
        buf: float scratch rows ``B_*``, (N_BUF, 2N).
        J: banded Jacobian / mass matrix, (2N, WIDTH) (see :mod:`~soft_snake_gym.physics.banded`).
        ibuf: integer scratch rows ``I_*`` (pivots, sort order, contact states), (N_IBUF, 2N).
        out: step diagnostics and the energy ledger at ``O_*``, (N_OUT,).
        f: the block the float arrays are views of, (``sim_offsets(N)[-1]``,).
    """

    q: np.ndarray
    v: np.ndarray
    kbar: np.ndarray
    lbar: np.ndarray
    prm: np.ndarray
    buf: np.ndarray
    J: np.ndarray
    ibuf: np.ndarray
    out: np.ndarray
    f: np.ndarray

    def row(self, i: int) -> SimArrays:
        """Robot ``i`` of stacked arrays: views, so writes go to the batch."""
        return SimArrays(*(a[i] for a in self))

    def __reduce__(self):
        """Pickle the blocks and rebuild the views on loading (numpy pickles a view as a copy of its own)."""
        return sim_arrays_over, (self.f, self.ibuf)


@njit(cache=True)
def sim_offsets(N: int) -> tuple[int, int, int, int, int, int, int, int]:
    """Where ``v``, ``kbar``, ``lbar``, ``prm``, ``buf``, ``J``, ``out`` start in a robot's block ``f``, and its size.

    ``q`` starts at 0. Compiled, so that the kernels and :func:`sim_arrays_over` share it.
    """
    n2 = 2 * N
    o_kbar = 2 * n2
    o_lbar = o_kbar + N - 2
    o_prm = o_lbar + N - 1
    o_buf = o_prm + N_PRM
    o_J = o_buf + N_BUF * n2
    o_out = o_J + n2 * WIDTH
    return n2, o_kbar, o_lbar, o_prm, o_buf, o_J, o_out, o_out + N_OUT


def borrowed(arr):
    """``arr`` without its reference count: the same array, its meminfo and parent NULL.

    Views of it are not counted either, so a kernel that builds views of a block it was given
    pays no atomic increments and decrements for them. Only for views that do not outlive the
    call that borrowed them (the caller's array keeps the memory alive). A tuple (a NamedTuple
    too) of arrays and tuples comes back with every array in it borrowed: reading a member of
    a counted tuple is an increment and a decrement. In Python (the kernels run with
    ``NUMBA_DISABLE_JIT=1``) it is ``arr`` itself.
    """
    return arr


def _borrow(context, builder, ty, value):
    """``value`` of type ``ty`` with the meminfo and parent of every array in it NULL."""
    if isinstance(ty, types.Array):
        out = context.make_array(ty)(context, builder, value=value)
        out.meminfo = cgutils.get_null_value(out.meminfo.type)
        out.parent = cgutils.get_null_value(out.parent.type)
        return out._getvalue()
    for k, item in enumerate(ty):
        member = _borrow(context, builder, item, builder.extract_value(value, k))
        value = builder.insert_value(value, member, k)
    return value


def _borrowable(ty):
    """True for an array, or a tuple of arrays and such tuples."""
    return isinstance(ty, types.Array) or (isinstance(ty, types.BaseTuple) and all(map(_borrowable, ty)))


@intrinsic
def _borrowed(typingctx, arr):
    """Compiled :func:`borrowed`: a copy of the array's (or each array's) struct with a NULL meminfo and parent."""
    if not _borrowable(arr):
        return None

    def codegen(context, builder, sig, args):
        return _borrow(context, builder, sig.args[0], args[0])

    return arr(arr), codegen


@overload(borrowed, jit_options={"_nrt": True})
def _borrowed_overload(arr):
    return lambda arr: _borrowed(arr)


@njit(cache=True, inline="always")
def copy_into(dst, src):
    """``dst[:] = src`` for two 1-D arrays of one size, element by element.

    In compiled code a slice assignment between arrays may allocate a temporary (where the two
    overlap), which a kernel compiled without reference counting (``_nrt=False``) cannot.
    """
    for k in range(dst.size):
        dst[k] = src[k]


def rows_of(arr, start, rows, cols):
    """``arr[start : start + rows * cols]`` as a (rows, cols) array, :func:`borrowed` when compiled.

    ``arr`` is 1-D and C-contiguous. In compiled code the view's struct is written at once:
    ``reshape`` calls numba's C helper that checks the new shape against the strides, a quarter
    of a microsecond a robot step in the batched eel's views (docs/performance_history.md, "Borrowed views").
    """
    return arr[start : start + rows * cols].reshape(rows, cols)


@intrinsic
def _rows_of(typingctx, arr, start, rows, cols):
    """Compiled :func:`rows_of`: a (rows, cols) C struct over ``arr``'s data from ``start``, meminfo NULL."""
    if not (isinstance(arr, types.Array) and arr.ndim == 1 and arr.layout == "C"):
        return None

    def codegen(context, builder, sig, args):
        src = context.make_array(sig.args[0])(context, builder, value=args[0])
        start, rows, cols = (
            context.cast(builder, v, t, types.intp) for v, t in zip(args[1:], sig.args[1:], strict=True)
        )
        out = context.make_array(sig.return_type)(context, builder)
        populate_array(
            out,
            data=cgutils.gep_inbounds(builder, src.data, start),
            shape=[rows, cols],
            strides=[builder.mul(cols, src.itemsize), src.itemsize],
            itemsize=src.itemsize,
            meminfo=None,
        )
        return out._getvalue()

    return types.Array(arr.dtype, 2, "C")(arr, start, rows, cols), codegen


@overload(rows_of, jit_options={"_nrt": True})
def _rows_of_overload(arr, start, rows, cols):
    return lambda arr, start, rows, cols: _rows_of(arr, start, rows, cols)


@njit(cache=True, inline="always")
def sim_views(f, ibuf):
    """One robot's :class:`SimArrays` over its block ``f`` and its ``ibuf`` (compiled code).

    The views are :func:`borrowed`: no reference counts inside the kernels.
    """
    f, ibuf = borrowed(f), borrowed(ibuf)
    n2 = ibuf.shape[1]
    o_v, o_kbar, o_lbar, o_prm, o_buf, o_J, o_out, end = sim_offsets(n2 // 2)
    return SimArrays(
        f[:o_v],
        f[o_v:o_kbar],
        f[o_kbar:o_lbar],
        f[o_lbar:o_prm],
        f[o_prm:o_buf],
        rows_of(f, o_buf, N_BUF, n2),
        rows_of(f, o_J, n2, WIDTH),
        ibuf,
        f[o_out:end],
        f,
    )


@njit(cache=True, inline="always")
def borrowed_arrays(s):
    """:class:`SimArrays` of the arrays of ``s`` (a SimArrays or the plain tuple), each :func:`borrowed`."""
    return borrowed(SimArrays(*s))


def sim_arrays_over(f: np.ndarray, ibuf: np.ndarray) -> SimArrays:
    """:class:`SimArrays` over blocks ``f`` (..., size) and ``ibuf`` (..., N_IBUF, 2N), any leading axes."""
    lead, n2 = f.shape[:-1], ibuf.shape[-1]
    o_v, o_kbar, o_lbar, o_prm, o_buf, o_J, o_out, end = sim_offsets(n2 // 2)
    return SimArrays(
        f[..., :o_v],
        f[..., o_v:o_kbar],
        f[..., o_kbar:o_lbar],
        f[..., o_lbar:o_prm],
        f[..., o_prm:o_buf],
        f[..., o_buf:o_J].reshape(lead + (N_BUF, n2)),
        f[..., o_J:o_out].reshape(lead + (n2, WIDTH)),
        ibuf,
        f[..., o_out:end],
        f,
    )


def allocate_arrays(N: int, batch: tuple[int, ...] = ()) -> SimArrays:
    """Zeroed :class:`SimArrays` of ``batch`` robots of N nodes (float64 views of one block per robot; ``ibuf`` int64)."""
    return sim_arrays_over(
        np.zeros(batch + (sim_offsets(N)[-1],)), np.zeros(batch + (N_IBUF, 2 * N), dtype=np.int64)
    )
