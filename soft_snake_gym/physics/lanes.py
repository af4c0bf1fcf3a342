"""Sixteen robots per instruction: implicit stages in water for a block at once; worms' steps, a lane each.

The batched env (``envs.task.step_units``) steps its swimmers in blocks of :data:`LANES`. In a
block every robot runs the same arithmetic on its own numbers, so each SDIRK2 stage (or BDF2's
one stage a step) is done for the whole block with each robot in one lane of the CPU's vector
registers: the stage's start (:func:`stage_start`, :func:`bdf2_start`), its Newton solve
(:func:`newton`: the residual with its Jacobian, the banded factorization and the solves), its
end (:func:`stage_end`: the powers, and the curvatures for the observation), then the energies
(:func:`energies`). :func:`take` copies the robots into a :class:`Block` once a step and
:func:`put` copies them back. LLVM vectorizes a loop over the lanes only in one form, found with
``scripts/probe_soa.py`` (docs/performance_history.md, "Sixteen eels per instruction"):

- every array of the block is flat, element ``i`` of lane ``r`` at ``i * LANES + r`` (a band
  entry (row, col) at ``(row * BAND + col) * LANES + r``), strides that are compile-time
  constants, so that LLVM can tell the stores of one lane's straight-line code apart;
- a lane loop runs ``LANES`` = 16 iterations, the least that LLVM's loop vectorizer takes on
  (two registers of eight doubles with AVX-512: each kernel with lane loops asks for them,
  :func:`_wide_vectors`, where LLVM's tuning for Intel's cores would take four of four);
- a loop that does the same to every element of its arrays runs over the flat index, not over
  elements and lanes: LLVM unrolls a lane loop with a small body whole before its loop
  vectorizer runs, and the unrolled code stays scalar (numba runs no SLP vectorizer), where a
  flat loop becomes vector code behind a runtime test that the arrays do not overlap; a small
  body that cannot run flat (a sum over a lane's elements) runs over a count LLVM does not
  know, the columns of ``res`` (:func:`_norms`), which it vectorizes and does not unroll;
- indices are unsigned (no negative-index test per access), and a flag that chooses between
  paths (``jac``) is a constant in each compiled body, or the loop runs both paths masked;
- inside a lane loop, a loop runs a constant count (a variable count keeps the lane loop
  scalar: :func:`factor` and :func:`solve` write out the band's last rows), and an index that
  LLVM cannot prove non-negative, such as a row counted down, is tested (``if k < 0``) before
  the lane loop, or the loop stays scalar;
- no branch per lane and no store that some lanes make and others skip (LLVM makes it a masked
  store, slow on AMD's cores, or on a core without AVX-512 may leave the loop scalar): each lane
  computes what every lane does and picks its values. LLVM also masks the store of a value picked
  between a new one and the one loaded from the same place (:func:`_larger`), and turns a mask of
  0 or all ones that it sees made by a test back into the branch (the held rows of
  :func:`ground_residual` take theirs from an array).

**Bit for bit the scalar step.** The kernels do the scalar kernels' operations in the same
order, so each lane's numbers are the ones :func:`stepper._be_residual`, ``band_factor`` and
``band_solve`` give. The Newton control follows one path for every lane, the one nearly every
stage takes in water: one Newton step (Jacobian, factorization, solve, a full step accepted)
and, unless that converged, chord steps with the same factors while the residual contracts
fast (at most :data:`CHORD_STEPS`); or none if the first guess converged. Each lane checks that
:func:`stepper._be_newton` would have decided the same at each point. A lane where it would
not (a line search, a renewed Jacobian, a row exchange, more chord steps than the block takes,
no convergence) is put back into its robot as the stage started, solved
there by ``_be_newton`` itself, and taken back. A block's robots therefore end every stage
exactly as the single env's, which the tests compare bit for bit. Transcendental functions stay
out of the lane loops: numba may vectorize them with SVML, whose digits are not libm's.

**On the ground** the Newton paths differ from robot to robot, so a block's lanes are workers
instead (:func:`crawl`): each runs one worm's step with the scalar stepper's own functions up to
each residual, which :func:`ground_residual` makes for the sixteen lanes at once; a lane whose
worm is done takes the next.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from soft_snake_gym.physics import banded, forces, geometry, layout, stepper
from soft_snake_gym.physics.banded import KL, KU, PIVOT_THRESHOLD
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.geometry import _turning_of
from soft_snake_gym.physics.layout import (
    ADDED_MASS_CONSISTENT,
    B_A,
    B_DV,
    B_F,
    B_FEXT,
    B_GEO,
    B_LRATE,
    B_M,
    B_MINV,
    B_P0,
    B_Q0,
    B_QPREV,
    B_R,
    B_V0,
    B_VACC,
    B_VSLIDE,
    B_VSTEP,
    I_FRICTION,
    I_PIV,
    MEDIUM_GROUND,
    MEDIUM_WATER,
    METHOD_BACKWARD_EULER,
    NOT_CONVERGED,
    O_NFACTOR,
    O_NJAC,
    O_NRES,
    OK,
    P_A,
    P_ADDED_MASS,
    P_ANISO,
    P_B,
    P_CD,
    P_CF,
    P_CHORD,
    P_DBEND,
    P_DSTRETCH,
    P_EA,
    P_EI,
    P_G,
    P_H,
    P_LAG,
    P_MAXIT,
    P_MEDIUM,
    P_METHOD,
    P_MUD,
    P_RHO,
    P_SUBSTEPS,
    P_TOL,
    P_VTOL,
    STUCK,
)

# the cached kernels embed _be_newton and the kernels it calls from these files
drop_stale_cache(__file__, [m.__file__ for m in (banded, forces, geometry, layout, stepper)])

LANES = 16
"""Robots per block: a compile-time constant, and LLVM's least trip count for a vector loop."""

BAND = KL + KU + 1
"""Entries of a band row in a block: ``banded.WIDTH`` less the room for row exchanges' fill-in, which
the block's factorization never makes (a lane that would exchange rows is solved elsewhere)."""
if KL != 5 or KU != KL:
    raise ImportError(
        "lanes.factor and lanes.solve write out the band's last five columns: update them for KL, KU"
    )


# per-lane parameters, rows of the block's (N_LANE_PRM, LANES) array
L_EA, L_EI, L_D, L_DB, L_CT, L_CN, L_CM, L_TOL, L_MAXIT, L_CHORD, L_MUD, L_G, L_EPS2 = range(13)
N_LANE_PRM = 13
# per-lane results of a residual, rows of (N_LANE_RES, LANES): |R|^2, max |R|/m, drag power
# (on the ground: friction power)
L_NORM2, L_RMAX, L_PFLUID = range(3)
L_PFRIC = L_PFLUID
N_LANE_RES = 3
SCALAR_TAIL = 6
"""Busy lanes, once no robot is left to take, at or below which :func:`crawl` finishes their jobs one
by one in scalar code: a round costs the block the same for one busy lane as for sixteen."""
CHORD_STEPS = 3
"""The most chord steps a stage takes in the block: a lane that would take more is solved alone.

Under random actions (256 eels, 2,000 steps, 2026-12-07) an SDIRK2 stage converges after its Newton
step and one chord step (99.4 % of the steps; in the others one stage needs no chord step), and
BDF2's one stage after three (99.6 %; the others two); none takes more. Each step of the loop costs
the block a solve and a residual, whoever needs it."""


class Block(NamedTuple):
    """A block's arrays: robot state in the flat layout (element i of lane r at ``_ix(i, r)``), and work.

    :func:`take` copies the robots' state in, :func:`put` copies it back: ``q``, ``v``, the
    stage's start ``q0``, ``v0``, the water's momentum there ``p0``, the step's start velocity
    ``vstep``, the forces ``F``, residual ``R`` and ``A`` (``buf``'s rows of those names), the
    rest shape ``kbar``, ``lbar``, the inputs ``uk`` and the length rates ``lrate``, and the
    edges' lengths, their reciprocals and unit tangents ``E`` (four rows an edge; ``buf[B_GEO]``). ``fext``,
    ``m`` and, on the ground, ``minv`` (the masses' reciprocals, ``buf[B_MINV]``) are copied in only. The rest is
    work: the band ``J``, Newton's ``vacc``, ``dv`` and the stage's first guess ``guess``;
    :func:`newton`'s per-lane residual figures ``res``,
    ``res1``, the lanes whose factors kept their rows ``kept``, the lanes on the common path
    ``on`` and how each ended ``done``; the stage's actuator and damping power per lane
    ``power`` (2, LANES), the curvatures and their rates at the stage's end ``curv`` (2 (N-2)
    rows), and the energies at the step's end ``energy`` (3, LANES). On the ground
    (:func:`crawl`) ``slides`` is -1 (every bit set) for a sliding node, 0 for one held at rest
    (``ibuf[I_FRICTION]``): a mask for its rows' bits (:func:`ground_residual`). Under
    BDF2, ``qprev`` is the last step's start (``buf[B_QPREV]``: :func:`take_history`).
    """

    q: np.ndarray
    v: np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    fext: np.ndarray
    m: np.ndarray
    p0: np.ndarray
    kbar: np.ndarray
    lbar: np.ndarray
    F: np.ndarray
    R: np.ndarray
    A: np.ndarray
    J: np.ndarray
    vacc: np.ndarray
    dv: np.ndarray
    E: np.ndarray
    res: np.ndarray
    res1: np.ndarray
    kept: np.ndarray
    on: np.ndarray
    done: np.ndarray
    uk: np.ndarray
    lrate: np.ndarray
    vstep: np.ndarray
    guess: np.ndarray
    power: np.ndarray
    curv: np.ndarray
    energy: np.ndarray
    slides: np.ndarray
    minv: np.ndarray
    qprev: np.ndarray


@intrinsic
def _wide_vectors(typingctx):
    """Ask LLVM for 512-bit vectors in the kernel that calls this (LLVM's ``prefer-vector-width``).

    LLVM tunes for Intel's cores with AVX-512 as if they preferred 256-bit vectors, and numba
    compiles every function of a process for one tuning. The lane kernels ask for the registers'
    whole width for themselves; the scalar kernels (the single envs', a robot's own work in a
    block) keep LLVM's choice, since 512-bit vectors made the single envs 0.92× to 0.94× as fast
    on an Intel Xeon (docs/performance.md, "512-bit vectors"). On a CPU without AVX-512 the widest
    vectors it has are used, as before. The numbers are the same bit for bit: no reassociation, so
    a wider vector does more of the same operations at once.
    """

    def codegen(context, builder, signature, args):
        # a string attribute, which llvmlite's list of known function attributes does not hold
        try:
            set.add(builder.function.attributes, '"prefer-vector-width"="512"')
        except TypeError:  # an llvmlite whose attributes are no set: LLVM's own choice, as elsewhere
            pass
        return context.get_dummy_value()

    return types.none(), codegen


@njit(cache=True, inline="always")
def _ix(i, r):
    """Flat index of element ``i`` of lane ``r``."""
    return np.uint64(i * LANES + r)


@njit(cache=True, inline="always")
def _jx(row, col, r):
    """Flat index of band entry (``row``, ``col``) of lane ``r``."""
    return np.uint64((row * BAND + col) * LANES + r)


@njit(cache=True, inline="always", error_model="numpy")
def _add_block(J, r, i, j, m00, m01, m10, m11):
    """``banded.add_block`` for lane ``r`` of a flat band."""
    row, col = 2 * i, 2 * j - 2 * i + KL
    J[_jx(row, col, r)] += m00
    J[_jx(row, col + 1, r)] += m01
    J[_jx(row + 1, col - 1, r)] += m10
    J[_jx(row + 1, col, r)] += m11


@njit(cache=True, inline="always", error_model="numpy")
def _set_block(J, r, i, j, m00, m01, m10, m11):
    """:func:`_add_block` to a block that no term has reached yet: ``+0 + m``, an add's bits on a zeroed band, without its loads."""
    row, col = 2 * i, 2 * j - 2 * i + KL
    J[_jx(row, col, r)] = 0.0 + m00
    J[_jx(row, col + 1, r)] = 0.0 + m01
    J[_jx(row + 1, col - 1, r)] = 0.0 + m10
    J[_jx(row + 1, col, r)] = 0.0 + m11


@njit(cache=True, inline="always", error_model="numpy")
def _clear_unreached(J, n2):
    """Zero the entries of every lane's band that :func:`_elastic` does not set, before it writes the Jacobian.

    :func:`_elastic` sets each entry that a term reaches with its first term (:func:`_set_block`),
    which gives the bits of an add to a zeroed band, so only the entries it leaves need a zero:
    node 0's diagonal block, whose first term is an add; each node's two entries five places off
    the diagonal (row ``2i`` five columns left, row ``2i + 1`` five right), which no block of
    the stencil reaches and the factorization updates; and the first and last rows' entries
    outside the matrix. The band is then, entry for entry, what zeroing it whole and adding
    gives, whatever it held (the last round's factors); ``J[:] = 0`` was 15 % of
    :func:`ground_residual`.
    """
    for r in range(LANES):
        J[_jx(0, KL, r)] = J[_jx(0, KL + 1, r)] = J[_jx(1, KL - 1, r)] = J[_jx(1, KL, r)] = 0.0
    for i in range(n2 // 2):
        for r in range(LANES):
            J[_jx(2 * i, 0, r)] = J[_jx(2 * i + 1, 2 * KL, r)] = 0.0
    for k in range(KL):
        for c in range(KL - k):
            for r in range(LANES):
                J[_jx(k, c, r)] = J[_jx(n2 - 1 - k, 2 * KL - c, r)] = 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _momentum_block(J, r, a, b, sa, sb, nx, ny, parts):
    """``fluid_momentum``'s block (a, b) of one edge for lane r (sa, sb: -1 or 1)."""
    m00, m01, m10, m11 = forces.momentum_block(sa, sb, nx, ny, parts)
    _add_block(J, r, a, b, m00, m01, m10, m11)


@njit(cache=True, inline="always", error_model="numpy")
def _edge_geometry(q, E, n2):
    """``geometry.edge_geometry`` for every lane: edge k's length, its reciprocal and unit tangent at ``E`` rows 4k .. 4k+3."""
    for k in range(n2 // 2 - 1):
        for r in range(LANES):
            ex = q[_ix(2 * k + 2, r)] - q[_ix(2 * k, r)]
            ey = q[_ix(2 * k + 3, r)] - q[_ix(2 * k + 1, r)]
            l = math.sqrt(ex * ex + ey * ey)
            il = 1.0 / l
            E[_ix(4 * k, r)] = l
            E[_ix(4 * k + 1, r)] = il
            E[_ix(4 * k + 2, r)] = ex * il
            E[_ix(4 * k + 3, r)] = ey * il


@njit(cache=True, inline="always", error_model="numpy")
def _edge(E, v, i, r):
    """``geometry.edge_frame_at`` for edge i of lane r: (l, tx, ty, nx, ny, vx, vy, vt, vn)."""
    l, tx, ty = E[_ix(4 * i, r)], E[_ix(4 * i + 2, r)], E[_ix(4 * i + 3, r)]
    nx, ny = -ty, tx
    vx = 0.5 * (v[_ix(2 * i, r)] + v[_ix(2 * i + 2, r)])
    vy = 0.5 * (v[_ix(2 * i + 1, r)] + v[_ix(2 * i + 3, r)])
    return l, tx, ty, nx, ny, vx, vy, vx * tx + vy * ty, vx * nx + vy * ny


@njit(cache=True, inline="always", error_model="numpy")
def _turning(E, j, r):
    """``geometry.turning_at`` at node j of lane r: ``_turning_of`` the node's two edges."""
    a, b = 4 * (j - 1), 4 * j
    return _turning_of(
        E[_ix(a + 1, r)],
        E[_ix(a + 2, r)],
        E[_ix(a + 3, r)],
        E[_ix(b + 1, r)],
        E[_ix(b + 2, r)],
        E[_ix(b + 3, r)],
    )


@njit(cache=True, inline="always", error_model="numpy")
def _momentum_edge(E, v, R, cm, sp, sg, i, r):
    """``forces.fluid_momentum``'s sum for edge i of lane r: adds ``sp P_f + sg G`` to R.

    Returns the edge's frame for the Jacobian: (l, tx, ty, nx, ny, vt, vn).
    """
    l, tx, ty, nx, ny, vx, vy, vt, vn = _edge(E, v, i, r)
    pn = 0.5 * sp * cm * l * vn
    gt = sg * cm * 0.5 * vn * vn
    gn = -sg * cm * vn * vt
    gx, gy = gt * tx + gn * nx, gt * ty + gn * ny
    R[_ix(2 * i, r)] += pn * nx - gx
    R[_ix(2 * i + 1, r)] += pn * ny - gy
    R[_ix(2 * i + 2, r)] += pn * nx + gx
    R[_ix(2 * i + 3, r)] += pn * ny + gy
    return l, tx, ty, nx, ny, vt, vn


@njit(cache=True, inline="always", error_model="numpy")
def _turning_rate(v, j, r, g0x, g0y, g1x, g1y, g2x, g2y):
    """``geometry.turning_rate`` at node j of lane r, the gradient ``g`` from :func:`_turning`."""
    return (
        g0x * v[_ix(2 * j - 2, r)]
        + g0y * v[_ix(2 * j - 1, r)]
        + g1x * v[_ix(2 * j, r)]
        + g1y * v[_ix(2 * j + 1, r)]
        + g2x * v[_ix(2 * j + 2, r)]
        + g2y * v[_ix(2 * j + 3, r)]
    )


@njit(cache=True, inline="always", error_model="numpy")
def _start_residual(x, dt):
    """``_be_residual``'s start for every lane: ``q = q0 + dt v``, ``F = fext``, ``A = v - v0``, the edges of ``q`` in ``E``."""
    q, v, q0, v0, fext, F, A, E = x.q, x.v, x.q0, x.v0, x.fext, x.F, x.A, x.E
    for k in range(q.size):  # element by element, flat (module docstring)
        q[k] = q0[k] + dt * v[k]
        F[k] = fext[k]
        A[k] = v[k] - v0[k]
    _edge_geometry(q, E, q.size // LANES)  # as assemble: each edge's square root and divisions once per state


@njit(cache=True, inline="always", error_model="numpy")
def _elastic(x, p, cx, cv, jac):
    """``forces.assemble``'s stretching and bending, with their damping, for every lane (``E`` of ``q`` made).

    With ``jac`` the Jacobian's first terms: each band entry that a term reaches is set by its
    first (:func:`_set_block`) and added to by the rest, after :func:`_clear_unreached`.
    """
    v, kbar, lbar, F, J, E = x.v, x.kbar, x.lbar, x.F, x.J, x.E
    n2 = v.size // LANES
    for k in range(n2 // 2 - 1):  # stretching
        for r in range(LANES):
            l, tx, ty = E[_ix(4 * k, r)], E[_ix(4 * k + 2, r)], E[_ix(4 * k + 3, r)]
            lb, EA, d = lbar[_ix(k, r)], p[L_EA, r], p[L_D, r]
            f = -EA * (l / lb - 1.0)
            dvx, dvy = v[_ix(2 * k + 2, r)] - v[_ix(2 * k, r)], v[_ix(2 * k + 3, r)] - v[_ix(2 * k + 1, r)]
            ldot = tx * dvx + ty * dvy
            f -= d * ldot  # assemble skips it for d = 0, where it only changes the sign of a zero f
            F[_ix(2 * k + 2, r)] += f * tx
            F[_ix(2 * k + 3, r)] += f * ty
            F[_ix(2 * k, r)] -= f * tx
            F[_ix(2 * k + 1, r)] -= f * ty
            if jac:
                il = E[_ix(4 * k + 1, r)]
                a1, a2 = EA / lb, -f * il
                s00 = cx * (a1 * tx * tx + a2 * (1.0 - tx * tx)) + cv * d * tx * tx
                s01 = cx * (a1 - a2) * tx * ty + cv * d * tx * ty
                s11 = cx * (a1 * ty * ty + a2 * (1.0 - ty * ty)) + cv * d * ty * ty
                _add_block(J, r, k, k, -s00, -s01, -s01, -s11)  # the others' first terms
                _set_block(J, r, k, k + 1, s00, s01, s01, s11)
                _set_block(J, r, k + 1, k, s00, s01, s01, s11)
                _set_block(J, r, k + 1, k + 1, -s00, -s01, -s01, -s11)
                px, py = cx * d * (dvx - ldot * tx) * il, cx * d * (dvy - ldot * ty) * il
                t00, t01, t10, t11 = tx * px, tx * py, ty * px, ty * py
                _add_block(J, r, k, k, -t00, -t01, -t10, -t11)
                _add_block(J, r, k, k + 1, t00, t01, t10, t11)
                _add_block(J, r, k + 1, k, t00, t01, t10, t11)
                _add_block(J, r, k + 1, k + 1, -t00, -t01, -t10, -t11)
    for j in range(1, n2 // 2 - 1):  # bending
        for r in range(LANES):
            kap, g0x, g0y, g1x, g1y, g2x, g2y, tax, tay, tbx, tby, ila, ilb = _turning(E, j, r)
            kb = p[L_EI, r] / (0.5 * (lbar[_ix(j - 1, r)] + lbar[_ix(j, r)]))
            dk = kap - kbar[_ix(j - 1, r)]
            w = 1.0 + 0.25 * kap * kap
            db = p[L_DB, r]
            phidot = _turning_rate(v, j, r, g0x, g0y, g1x, g1y, g2x, g2y)
            s = kb * dk * w + db * w * w * phidot
            F[_ix(2 * j - 2, r)] -= s * g0x
            F[_ix(2 * j - 1, r)] -= s * g0y
            F[_ix(2 * j, r)] -= s * g1x
            F[_ix(2 * j + 1, r)] -= s * g1y
            F[_ix(2 * j + 2, r)] -= s * g2x
            F[_ix(2 * j + 3, r)] -= s * g2y
            if jac:
                s2 = kb * (w * w + dk * 0.5 * kap * w) + db * w * w * kap * phidot
                alpha = -(cx * s2 + cv * db * w * w)
                beta = -cx * (kb * dk * w + db * w * w * phidot)
                ia, ib = ila * ila, ilb * ilb
                ha00, ha01, ha11 = 2.0 * tax * tay * ia, (tay * tay - tax * tax) * ia, -2.0 * tax * tay * ia
                hb00, hb01, hb11 = 2.0 * tbx * tby * ib, (tby * tby - tbx * tbx) * ib, -2.0 * tbx * tby * ib
                ux, uy = v[_ix(2 * j, r)] - v[_ix(2 * j - 2, r)], v[_ix(2 * j + 1, r)] - v[_ix(2 * j - 1, r)]
                wx, wy = v[_ix(2 * j + 2, r)] - v[_ix(2 * j, r)], v[_ix(2 * j + 3, r)] - v[_ix(2 * j + 1, r)]
                r0x, r0y = ha00 * ux + ha01 * uy, ha01 * ux + ha11 * uy
                r2x, r2y = hb00 * wx + hb01 * wy, hb01 * wx + hb11 * wy
                r1x, r1y = -r0x - r2x, -r0y - r2y
                c = -cx * db * w * w
                g = (g0x, g0y, g1x, g1y, g2x, g2y)
                u = (alpha * g0x + c * r0x, alpha * g0y + c * r0y, alpha * g1x + c * r1x,
                     alpha * g1y + c * r1y, alpha * g2x + c * r2x, alpha * g2y + c * r2y)  # fmt: skip
                blocks = forces.bending_blocks(beta, g, u, (ha00, ha01, ha11), (hb00, hb01, hb11))
                for k in range(9):
                    m00, m01, m10, m11 = blocks[k]
                    if k == 2 or k == 6:  # nodes two apart: the first term
                        _set_block(J, r, j - 1 + k // 3, j - 1 + k % 3, m00, m01, m10, m11)
                    else:
                        _add_block(J, r, j - 1 + k // 3, j - 1 + k % 3, m00, m01, m10, m11)


@njit(cache=True, error_model="numpy", _nrt=False)
def residual(x, p, dt, jac, res):
    """``stepper._be_residual`` in water with the consistent added mass, for every lane of a block.

    ``x`` is the block's :func:`allocate` arrays, ``p`` its lane parameters (``L_*`` rows). Writes
    ``q = q0 + dt v``, the forces ``F``, the residual ``R``, ``v - v0`` into ``A`` and, if
    ``jac``, the Jacobian into ``J``; per lane into ``res`` (``L_NORM2``, ``L_RMAX``,
    ``L_PFLUID``). ``jac`` is a constant in each compiled body (see the module docstring).

    The damping terms are computed for every lane, where ``assemble`` skips them for a zero
    coefficient: a branch in a lane loop keeps it scalar. A zero coefficient adds signed zeros
    there, which change no force and no entry of the band (its entries start at +0 and only
    add, so none is -0). A lane whose velocity is not finite could differ; its residual is not
    finite either, and ``newton`` solves it by ``_be_newton``.
    """
    _wide_vectors()
    if jac:
        _residual(x, p, dt, True, res)
    else:
        _residual(x, p, dt, False, res)


@njit(cache=True, inline="always", error_model="numpy")
def _residual(x, p, dt, jac, res):
    """The body of :func:`residual`: ``_be_residual``'s operations in its order, lane by lane."""
    q, v, m, p0, F, R, A, J, E = x.q, x.v, x.m, x.p0, x.F, x.R, x.A, x.J, x.E
    n2 = q.size // LANES
    cx, cv = -dt * dt, -dt
    _start_residual(x, dt)
    if jac:
        _clear_unreached(J, n2)
    _elastic(x, p, cx, cv, jac)
    for r in range(LANES):
        res[L_PFLUID, r] = 0.0
    for i in range(n2 // 2 - 1):  # drag
        for r in range(LANES):
            l, tx, ty, nx, ny, vx, vy, vt, vn = _edge(E, v, i, r)
            ct, cn = p[L_CT, r], p[L_CN, r]
            gt = vt + vt * abs(vt)
            gn = vn + vn * abs(vn)
            fx = -ct * l * gt * tx - cn * l * gn * nx
            fy = -ct * l * gt * ty - cn * l * gn * ny
            res[L_PFLUID, r] -= fx * vx + fy * vy
            F[_ix(2 * i, r)] += 0.5 * fx
            F[_ix(2 * i + 1, r)] += 0.5 * fy
            F[_ix(2 * i + 2, r)] += 0.5 * fx
            F[_ix(2 * i + 3, r)] += 0.5 * fy
            if jac:
                c00, c01, c11, d00, d01, d10, d11 = forces.drag_jacobian(
                    ct, cn, l, tx, ty, nx, ny, vt, vn, gt, gn, cx, cv
                )
                _add_block(J, r, i, i, c00 - d00, c01 - d01, c01 - d10, c11 - d11)
                _add_block(J, r, i, i + 1, c00 + d00, c01 + d01, c01 + d10, c11 + d11)
                _add_block(J, r, i + 1, i, c00 - d00, c01 - d01, c01 - d10, c11 - d11)
                _add_block(J, r, i + 1, i + 1, c00 + d00, c01 + d01, c01 + d10, c11 + d11)
    for k in range(R.size):
        R[k] = m[k] * A[k] - dt * F[k]
    if jac:
        _add_masses(J, m, res.shape[1])
    for i in range(n2 // 2 - 1):  # the water's momentum: fluid_momentum(sp = 1, sg = -dt)
        for r in range(LANES):
            cm = p[L_CM, r]
            l, tx, ty, nx, ny, vt, vn = _momentum_edge(E, v, R, cm, 1.0, -dt, i, r)
            if jac:
                parts = forces.momentum_jacobian(cm, l, tx, ty, nx, ny, vt, vn, dt)
                _momentum_block(J, r, i, i, -1.0, -1.0, nx, ny, parts)
                _momentum_block(J, r, i, i + 1, -1.0, 1.0, nx, ny, parts)
                _momentum_block(J, r, i + 1, i, 1.0, -1.0, nx, ny, parts)
                _momentum_block(J, r, i + 1, i + 1, 1.0, 1.0, nx, ny, parts)
    for r in range(LANES):
        res[L_NORM2, r] = 0.0
        res[L_RMAX, r] = 0.0
    for i in range(n2):
        for r in range(LANES):
            e = R[_ix(i, r)] - p0[_ix(i, r)]
            R[_ix(i, r)] = e
            res[L_NORM2, r] += e * e
            # 1 / m as _be_residual's B_MINV
            res[L_RMAX, r] = _larger(res[L_RMAX, r], abs(e) * (1.0 / m[_ix(i, r)]))


@njit(cache=True, inline="always", error_model="numpy")
def _add_masses(J, m, lanes):
    """``J``'s diagonal += the masses ``m``, for every lane; ``lanes`` = ``LANES``, a count LLVM does not know (:func:`_norms`)."""
    for i in range(m.size // LANES):
        for r in range(lanes):
            J[_jx(i, KL, r)] += m[_ix(i, r)]


@njit(cache=True, inline="always", error_model="numpy")
def _larger(cur, val):
    """``max(cur, val)`` for a running maximum ``cur`` >= +0 (never -0 nor NaN), in a form whose store is every lane's.

    ``max`` keeps ``cur`` where ``val`` is not larger, and LLVM then drops that lane's store of
    the value it loaded: a masked store, which AMD's cores without AVX-512 (Zen 3) run slowly.
    ``cur + 0.0`` is ``cur`` bit for bit, but not the loaded value to LLVM, so every lane stores.
    """
    return val if val > cur else cur + 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _norms(R, minv, res):
    """``_be_residual``'s norms of the residual ``R`` for every lane: ``res[L_NORM2]`` = |R|^2, ``res[L_RMAX]`` = max |R|/m.

    The lane loop runs over ``res``'s columns, a count LLVM does not know: over ``LANES`` it
    unrolled the small body whole and the sums stayed scalar, one element at a time with a
    division each (docs/performance_history.md, "The residual's norms in vector code").
    """
    lanes = res.shape[1]  # = LANES
    for r in range(LANES):
        res[L_NORM2, r] = 0.0
        res[L_RMAX, r] = 0.0
    for i in range(R.size // LANES):
        for r in range(lanes):
            e = R[_ix(i, r)]
            res[L_NORM2, r] += e * e
            res[L_RMAX, r] = _larger(res[L_RMAX, r], abs(e) * minv[_ix(i, r)])


@njit(cache=True, inline="always", error_model="numpy")
def _column(J, kept, k, below):
    """``band_factor``'s column ``k`` in every lane, ``below`` rows under its pivot (a constant: see :func:`factor`)."""
    if k < 0:  # a band of fewer than KL rows; it also tells LLVM that k is not negative
        return
    for r in range(LANES):  # band_factor's test: the diagonal >= threshold x the largest below
        diag = abs(J[_jx(k, KL, r)])
        best = diag
        for e in range(1, below + 1):
            best = max(best, abs(J[_jx(k + e, KL - e, r)]))
        kept[r] = kept[r] & (diag >= PIVOT_THRESHOLD * best) & (best > 0.0)
    for r in range(LANES):
        inv = 1.0 / J[_jx(k, KL, r)]  # the factors hold the pivot's reciprocal, as band_factor's
        J[_jx(k, KL, r)] = inv
        for e in range(1, below + 1):
            f = J[_jx(k + e, KL - e, r)] * inv
            J[_jx(k + e, KL - e, r)] = f
            for c in range(1, below + 1):
                J[_jx(k + e, KL - e + c, r)] -= f * J[_jx(k, KL + c, r)]


@njit(cache=True, error_model="numpy", _nrt=False)
def factor(J, kept, n):
    """``band_factor`` of every lane's band in place, where it keeps every diagonal pivot.

    ``kept[r]`` becomes False where ``band_factor`` would exchange rows (or find the band
    singular); that lane's factors are then not ``band_factor``'s. Each column is
    :func:`_column` with a constant count of rows below its pivot, ``KL`` where the band is
    whole and ``KL - 1`` down to 0 in the last ``KL`` columns, written out, so that each lane's
    column is straight-line code and the lane loops are vector code (with the count a variable,
    the last five columns took as long as the other fifteen). The pivot test runs without
    short-circuits and the row updates without ``band_factor``'s skip of zero multipliers, whose
    branch kept the loops scalar. The skip changes no bit of a finite band: the bands
    (:func:`residual`, :func:`ground_residual`) start at +0 and only add or set +0, an update
    ``x - f u`` gives -0 only from ``x`` = -0, so no entry an update reads is -0, and ``x - (±0)
    u`` is ``x`` for every other ``x`` and finite ``u``. Where a lane's band holds an infinity or a
    NaN its factors may differ from ``band_factor``'s; its residual is not finite then either,
    where ``_be_newton`` uses no factors (a swimmer's lane is solved on its robot, a worm's job
    gives up as ``_be_newton`` does).
    """
    _wide_vectors()
    for r in range(LANES):
        kept[r] = True
    for k in range(n - KL):
        _column(J, kept, k, KL)
    _column(J, kept, n - 5, 4)  # the last KL = 5 columns
    _column(J, kept, n - 4, 3)
    _column(J, kept, n - 3, 2)
    _column(J, kept, n - 2, 1)
    _column(J, kept, n - 1, 0)


@njit(cache=True, inline="always", error_model="numpy")
def _forward(J, b, k, below):
    """``band_solve``'s forward step from row ``k`` in every lane: ``below`` rows under it (a constant: :func:`solve`)."""
    if k < 0:  # a band of fewer than KL rows; it also tells LLVM that k is not negative
        return
    for r in range(LANES):
        bk = b[_ix(k, r)]
        for e in range(1, below + 1):
            b[_ix(k + e, r)] -= J[_jx(k + e, KL - e, r)] * bk


@njit(cache=True, inline="always", error_model="numpy")
def _backward(J, b, k, right):
    """``band_solve``'s back substitution of row ``k`` in every lane: ``right`` entries right of the diagonal (a constant)."""
    if k < 0:  # as in _forward: without it LLVM leaves the lanes scalar
        return
    for r in range(LANES):
        s = b[_ix(k, r)]
        for e in range(1, right + 1):
            s -= J[_jx(k, KL + e, r)] * b[_ix(k + e, r)]
        b[_ix(k, r)] = s * J[_jx(k, KL, r)]


@njit(cache=True, error_model="numpy", _nrt=False, no_cpython_wrapper=True)
def _backward_row(J, b, k):
    """``_backward(J, b, k, KU)``, a whole row, compiled as a function of its own.

    Inlined into :func:`solve`'s loop over rows, its lane loop stays scalar whatever its form
    (loads before stores, the lanes four at a time, the sum taken term by term); compiled alone,
    with ``k`` an argument, LLVM vectorizes it before numba links it into :func:`solve`, and a
    solve of 16 eels' bands takes 0.50 to 0.53 µs instead of 0.73 (docs/performance_history.md, "The
    back substitution's rows as functions of their own").
    """
    _wide_vectors()
    _backward(J, b, k, KU)


@njit(cache=True, error_model="numpy", _nrt=False)
def solve(J, b, n):
    """``band_solve`` for every lane with the factors of :func:`factor` (no row exchanges), in place in ``b``.

    Written out as :func:`factor` is, each row with a constant count of entries, so that the lane
    loops are vector code; the back substitution's rows with ``KU`` entries through
    :func:`_backward_row`.
    """
    _wide_vectors()
    for k in range(n - KL):
        _forward(J, b, k, KL)
    _forward(J, b, n - 5, 4)  # the last KL = 5 rows (the last has none below)
    _forward(J, b, n - 4, 3)
    _forward(J, b, n - 3, 2)
    _forward(J, b, n - 2, 1)
    _backward(J, b, n - 1, 0)
    _backward(J, b, n - 2, 1)
    _backward(J, b, n - 3, 2)
    _backward(J, b, n - 4, 3)
    _backward(J, b, n - 5, 4)
    for kk in range(n - KU):  # k from n - KU - 1 down
        _backward_row(J, b, n - KU - 1 - kk)


@njit(cache=True, error_model="numpy")
def allocate(n2):
    """A :class:`Block` for robots of ``n2 = 2N`` unknowns, allocated once per thread and reused."""
    n, N = n2 * LANES, n2 // 2
    z = np.zeros
    return Block(z(n), z(n), z(n), z(n), z(n), z(n), z(n), z((N - 2) * LANES), z((N - 1) * LANES), z(n), z(n),
                 z(n), z(n2 * BAND * LANES), z(n), z(n), z(4 * (N - 1) * LANES), z((N_LANE_RES, LANES)),
                 z((N_LANE_RES, LANES)), z(LANES, dtype=np.bool_), z(LANES, dtype=np.bool_),
                 z(LANES, dtype=np.int64), z((N - 2) * LANES), z((N - 1) * LANES), z(n), z(n), z((2, LANES)), z(2 * (N - 2) * LANES),
                 z((3, LANES)), z(N * LANES, dtype=np.int64), z(n), z(n))  # fmt: skip


@njit(cache=True, error_model="numpy", _nrt=False)
def eligible(prm):
    """True if a robot's stages can be solved here: water, the consistent added mass."""
    return int(prm[P_MEDIUM]) == MEDIUM_WATER and int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT


@njit(cache=True, error_model="numpy", _nrt=False)
def take(s, uk, first, x, p):
    """Copy robots ``first`` .. ``first + LANES - 1`` of stacked ``SimArrays`` ``s`` (inputs ``uk``) into block ``x``.

    Their state at the start of a step (:class:`Block`) and, into ``p``, their parameters
    (``L_*`` rows); not the stages' start ``q0``, ``p0`` and ``vstep``, which :func:`stage_start`
    writes before anything reads them. Lanes past the last robot of ``s`` get the last robot
    again: their arithmetic stays that of a robot.
    """
    _wide_vectors()
    n2 = s.q.shape[1]
    for r in range(LANES):
        i = min(first + r, s.q.shape[0] - 1)
        buf, prm = s.buf[i], s.prm[i]
        for k in range(n2):
            x.q[_ix(k, r)] = s.q[i, k]
            x.v[_ix(k, r)] = s.v[i, k]
            x.v0[_ix(k, r)] = buf[B_V0, k]
            x.fext[_ix(k, r)] = buf[B_FEXT, k]
            x.m[_ix(k, r)] = buf[B_M, k]
        for k in range(s.kbar.shape[1]):
            x.kbar[_ix(k, r)] = s.kbar[i, k]
            x.uk[_ix(k, r)] = uk[i, k]
        for k in range(s.lbar.shape[1]):
            x.lbar[_ix(k, r)] = s.lbar[i, k]
            x.lrate[_ix(k, r)] = buf[B_LRATE, k]
        p[L_EA, r], p[L_EI, r], p[L_D, r], p[L_DB, r] = prm[P_EA], prm[P_EI], prm[P_DSTRETCH], prm[P_DBEND]
        p[L_CT, r] = 0.25 * prm[P_RHO] * math.pi * prm[P_CF] * (prm[P_A] + prm[P_B])  # as assemble
        p[L_CN, r] = prm[P_RHO] * prm[P_CD] * prm[P_A]
        p[L_CM, r] = forces.added_mass_coefficient(prm)
        p[L_TOL, r], p[L_MAXIT, r], p[L_CHORD, r] = prm[P_TOL], prm[P_MAXIT], prm[P_CHORD]


STAGE_ROWS = (B_Q0, B_VSTEP, B_P0, B_F, B_R, B_A)
"""``buf``'s rows that hold a stage's start and its residual's work: every integrator writes them
before it reads them, so a step's end does not copy them back (:func:`put_state`)."""


@njit(cache=True, inline="always", error_model="numpy")
def put_state(s, i, x, r, v):
    """Copy lane ``r``'s state back into robot ``i`` of ``s``, with the velocity from ``v`` (``x.v`` or ``x.guess``).

    What a later step or the task reads: ``q``, ``v``, ``kbar``, the step's start velocity
    ``buf[B_V0]`` (the next step's first guess extrapolates from it) and the edges ``buf[B_GEO]``
    (the observation's); at a step's end, ``buf``'s :data:`STAGE_ROWS` stay as they were.
    """
    n2 = s.q.shape[1]
    buf = s.buf[i]
    for k in range(n2):
        s.q[i, k] = x.q[_ix(k, r)]
        s.v[i, k] = v[_ix(k, r)]
        buf[B_V0, k] = x.v0[_ix(k, r)]
    for k in range(s.kbar.shape[1]):
        s.kbar[i, k] = x.kbar[_ix(k, r)]
    _edges_of_lane(x.E, buf, r)


@njit(cache=True, inline="always", error_model="numpy")
def _edges_of_lane(E, buf, r):
    """Lane ``r``'s edges ``E`` into its robot's ``buf[B_GEO]`` (``geometry.edge_geometry``'s layout; the same bits)."""
    for k in range(buf.shape[1] // 2 - 1):  # the N - 1 edges of 2N coordinates
        buf[B_GEO, 2 * k] = E[_ix(4 * k, r)]
        buf[B_GEO, 2 * k + 1] = E[_ix(4 * k + 1, r)]
        buf[B_GEO + 1, 2 * k] = E[_ix(4 * k + 2, r)]
        buf[B_GEO + 1, 2 * k + 1] = E[_ix(4 * k + 3, r)]


@njit(cache=True, inline="always", error_model="numpy")
def _edges_into_lane(buf, E, r):
    """:func:`_edges_of_lane`'s inverse: a robot's ``buf[B_GEO]`` into lane ``r`` of ``E``."""
    for k in range(buf.shape[1] // 2 - 1):  # the N - 1 edges of 2N coordinates
        E[_ix(4 * k, r)] = buf[B_GEO, 2 * k]
        E[_ix(4 * k + 1, r)] = buf[B_GEO, 2 * k + 1]
        E[_ix(4 * k + 2, r)] = buf[B_GEO + 1, 2 * k]
        E[_ix(4 * k + 3, r)] = buf[B_GEO + 1, 2 * k + 1]


@njit(cache=True, inline="always", error_model="numpy")
def put(s, i, x, r, v):
    """:func:`put_state` and the stages' work (``buf``'s :data:`STAGE_ROWS`): all that :func:`take` and a stage change.

    For a lane that ``_be_newton`` solves on its robot's arrays, and a robot whose step fails. A
    swimmer's rest lengths and length rates do not move (:func:`stage_start`).
    """
    put_state(s, i, x, r, v)
    buf = s.buf[i]
    for k in range(s.q.shape[1]):
        buf[B_Q0, k] = x.q0[_ix(k, r)]
        buf[B_VSTEP, k] = x.vstep[_ix(k, r)]
        buf[B_P0, k] = x.p0[_ix(k, r)]
        buf[B_F, k] = x.F[_ix(k, r)]
        buf[B_R, k] = x.R[_ix(k, r)]
        buf[B_A, k] = x.A[_ix(k, r)]


@njit(cache=True, error_model="numpy", _nrt=False)
def take_history(s, first, x):
    """BDF2's history of robots ``first`` .. ``first + LANES - 1``, ``buf[B_QPREV]``, into ``x.qprev``."""
    _wide_vectors()
    for r in range(LANES):
        i = min(first + r, s.q.shape[0] - 1)
        for k in range(s.q.shape[1]):
            x.qprev[_ix(k, r)] = s.buf[i, B_QPREV, k]


@njit(cache=True, inline="always", error_model="numpy")
def put_history(s, i, x, r):
    """Lane ``r``'s BDF2 history back into robot ``i`` (:func:`bdf2_start` made it this step's start)."""
    for k in range(s.q.shape[1]):
        s.buf[i, B_QPREV, k] = x.qprev[_ix(k, r)]


@njit(cache=True, error_model="numpy", _nrt=False)
def stage_start(x, p, stage, dt):
    """``stepper.sdirk2_stage_start`` in water for every lane: the rest shape moved, the stage's solve set up.

    The lanes are swimmers (``envs.task.block_eligible``): their inputs are curvature rates, their
    length rates zero, so ``_move_rest_shape`` moves ``kbar`` alone (``lbar`` gains ``+0``) and
    cannot fail. Stage 0 is ``_be_start``'s in water (the velocity extrapolated by ``GAMMA``, the
    water's momentum at the start); stage 1 is ``_sdirk2_second_start``'s, from the edges of ``q``
    that :func:`newton`'s last residual left in ``E``.
    """
    _wide_vectors()
    q, v, q0, v0, p0, A, E, vstep = x.q, x.v, x.q0, x.v0, x.p0, x.A, x.E, x.vstep
    n2 = q.size // LANES
    stage_dt = (stepper.GAMMA if stage == 0 else 1.0 - stepper.GAMMA) * dt
    for k in range(x.kbar.size):
        x.kbar[k] += stage_dt * x.uk[k]
    if stage == 0:
        _be_start(x, p, stepper.GAMMA)
        return
    c = (1.0 - stepper.GAMMA) / stepper.GAMMA
    A[:] = 0.0
    _momentum(E, v, p, A, n2)  # E: the edges of q, the first stage's last residual's
    for k in range(q.size):
        p0[k] += c * (A[k] - p0[k])
        vstep[k] = v0[k]
        change = v[k] - v0[k]
        q0[k] += c * (q[k] - q0[k])
        v0[k] += c * change
        v[k] = v0[k] + change


@njit(cache=True, error_model="numpy", _nrt=False)
def bdf2_start(x, p, dt):
    """``stepper``'s start of a BDF2 step of ``dt`` in water for every lane, as ``simulate`` makes it.

    ``move_rest_shape``: the actuator power at the start, of the rest shape not moved yet, into
    ``x.power[0]``, and the rest shape moved (``kbar`` alone, as in :func:`stage_start`).
    ``_bdf2_substep`` up to its solve: the start recorded, the velocity extrapolated and the
    water's momentum there (:func:`_be_start`), and the backward-Euler stage of ``2 dt / 3`` set
    up from ``(4 y_n - y_(n-1)) / 3`` for the position, the velocity and the momentum, with
    ``y_(n-1)`` the last step's start (``qprev``, the velocity ``v0``, which ``vstep`` keeps);
    both then hold this step's start. Every lane must have its history (``stepper.simulate``
    starts a fresh state with an SDIRK2 step).
    """
    _wide_vectors()
    q, q0, v0, p0, A, E, vstep, qprev = x.q, x.q0, x.v0, x.p0, x.A, x.E, x.vstep, x.qprev
    n2 = q.size // LANES
    for k in range(q.size):
        vstep[k] = v0[k]  # the last step's start velocity, before _be_start moves v0 on
        A[k] = 0.0
    _be_start(x, p, 1.0)
    _actuator_power(x, p)  # of q, whose edges _be_start left in E (q0 is q), and the unmoved kbar
    for k in range(x.kbar.size):
        x.kbar[k] += dt * x.uk[k]
    _edge_geometry(qprev, E, n2)
    _momentum(E, vstep, p, A, n2)
    for k in range(q.size):
        p0[k] += (p0[k] - A[k]) / 3.0
        qn, vn = q0[k], v0[k]
        q0[k] += (qn - qprev[k]) / 3.0
        v0[k] += (vn - vstep[k]) / 3.0
        qprev[k] = qn
        vstep[k] = vn


@njit(cache=True, inline="always", error_model="numpy")
def _be_start(x, p, extrapolate):
    """``stepper._be_start`` in water for every lane: the start recorded, the first guess, the momentum.

    ``q0``, ``v0`` the state, the velocity extrapolated from the last start by ``extrapolate``
    (SDIRK2's first stage ``GAMMA``, BDF2 1), and the water's momentum at the start into ``p0``;
    ``E`` is left the edges of ``q0``.
    """
    q, v, q0, v0, p0, E = x.q, x.v, x.q0, x.v0, x.p0, x.E
    n2 = q.size // LANES
    for k in range(q.size):
        q0[k] = q[k]
        v_prev = v0[k]
        v0[k] = v[k]
        v[k] += extrapolate * (v[k] - v_prev)
        p0[k] = 0.0
    _edge_geometry(q0, E, n2)
    _momentum(E, v0, p, p0, n2)


@njit(cache=True, inline="always", error_model="numpy")
def _momentum(E, v, p, P, n2):
    """Add the water's momentum ``P_f`` of every lane to ``P`` (``fluid_momentum`` with ``sp = 1``, ``sg = 0``)."""
    for i in range(n2 // 2 - 1):
        for r in range(LANES):
            _momentum_edge(E, v, P, p[L_CM, r], 1.0, 0.0, i, r)


@njit(cache=True, error_model="numpy", _nrt=False)
def stage_end(x, p, stage):
    """The lanes' part of ``stepper.sdirk2_stage_end``: the powers at the stage's end, into ``x.power``.

    Also the end of a BDF2 step (``stage`` 1), whose energies take the same powers
    (``stepper.implicit_energies``). The step's start velocity back in ``v0`` after stage 1,
    ``forces.actuator_power`` into ``power[0]`` and ``forces.damping_power`` into ``power[1]``,
    in their order of operations, from the edges of ``q`` that :func:`newton`'s last residual
    left in ``E``; on the way, the curvatures and their rates into ``x.curv``. The damping terms
    are summed for every lane, a zero added in place of a term where ``damping_power`` skips it.
    Where no lane has stretch damping (the default) the stretching's terms are not made at all:
    their zeros would leave the sum +0, as ``damping_power``'s skip does.
    """
    _wide_vectors()
    q, v, E, power = x.q, x.v, x.E, x.power
    n2 = q.size // LANES
    N = n2 // 2
    if stage == 1:
        layout.copy_into(x.v0, x.vstep)
    _actuator_power(x, p)
    stretch_damped = False
    for r in range(LANES):
        power[1, r] = 0.0
        stretch_damped |= p[L_D, r] > 0.0
    for k in range(N - 1 if stretch_damped else 0):
        for r in range(LANES):
            ex = q[_ix(2 * k + 2, r)] - q[_ix(2 * k, r)]
            ey = q[_ix(2 * k + 3, r)] - q[_ix(2 * k + 1, r)]
            dvx = v[_ix(2 * k + 2, r)] - v[_ix(2 * k, r)]
            dvy = v[_ix(2 * k + 3, r)] - v[_ix(2 * k + 1, r)]
            ld = (ex * dvx + ey * dvy) / math.sqrt(ex * ex + ey * ey)
            ds = p[L_D, r]
            power[1, r] += ds * ld * ld if ds > 0.0 else 0.0
    for j in range(1, N - 1):
        for r in range(LANES):
            kap, g0x, g0y, g1x, g1y, g2x, g2y = _turning(E, j, r)[:7]
            kd = (1.0 + 0.25 * kap * kap) * _turning_rate(v, j, r, g0x, g0y, g1x, g1y, g2x, g2y)
            x.curv[_ix(j - 1, r)] = kap  # geometry.curvatures_and_rates_at, for the observation
            x.curv[_ix(N - 3 + j, r)] = kd
            db = p[L_DB, r]
            power[1, r] += db * kd * kd if db > 0.0 else 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _actuator_power(x, p):
    """``forces.actuator_power`` of every lane into ``x.power[0]``, in its order, from the edges in ``E``."""
    E, kbar, lbar, uk, lrate, power = x.E, x.kbar, x.lbar, x.uk, x.lrate, x.power
    N = x.q.size // LANES // 2
    for r in range(LANES):
        power[0, r] = 0.0
    for j in range(1, N - 1):
        for r in range(LANES):
            EI = p[L_EI, r]
            lv = 0.5 * (lbar[_ix(j - 1, r)] + lbar[_ix(j, r)])
            dk = _turning(E, j, r)[0] - kbar[_ix(j - 1, r)]
            power[0, r] -= EI / lv * dk * uk[_ix(j - 1, r)]
            power[0, r] -= 0.25 * EI * dk * dk / (lv * lv) * (lrate[_ix(j - 1, r)] + lrate[_ix(j, r)])
    for k in range(N - 1):
        for r in range(LANES):
            ratio = E[_ix(4 * k, r)] / lbar[_ix(k, r)]
            power[0, r] -= 0.5 * p[L_EA, r] * (ratio * ratio - 1.0) * lrate[_ix(k, r)]


@njit(cache=True, inline="always", error_model="numpy")
def curvatures_into(x, r, raw):
    """Lane ``r``'s curvatures and their rates from the last :func:`stage_end` into ``raw[:2 (N-2)]``."""
    for j in range(2 * (x.kbar.size // LANES)):
        raw[j] = x.curv[_ix(j, r)]


@njit(cache=True, error_model="numpy", _nrt=False)
def energies(x, p):
    """``stepper.ledger_energies``'s energies for every lane, after :func:`stage_end`, into ``x.energy``.

    The body's kinetic energy, ``forces.elastic_energy`` and ``forces.fluid_kinetic_energy``, in
    their order of operations; the edges' lengths and turning from ``E`` (the same bits as from
    ``q``, see ``geometry.turning_at``).
    """
    _wide_vectors()
    q, v, m, E, kbar, lbar, energy = x.q, x.v, x.m, x.E, x.kbar, x.lbar, x.energy
    n2 = q.size // LANES
    N = n2 // 2
    for r in range(LANES):
        energy[0, r] = 0.0
        energy[1, r] = 0.0
        energy[2, r] = 0.0
    for i in range(n2):
        for r in range(LANES):
            energy[0, r] += 0.5 * m[_ix(i, r)] * v[_ix(i, r)] * v[_ix(i, r)]
    for k in range(N - 1):
        for r in range(LANES):
            s = E[_ix(4 * k, r)] / lbar[_ix(k, r)] - 1.0
            energy[1, r] += 0.5 * p[L_EA, r] * s * s * lbar[_ix(k, r)]
    for j in range(1, N - 1):
        for r in range(LANES):
            dk = _turning(E, j, r)[0] - kbar[_ix(j - 1, r)]
            energy[1, r] += 0.5 * p[L_EI, r] / (0.5 * (lbar[_ix(j - 1, r)] + lbar[_ix(j, r)])) * dk * dk
    for i in range(N - 1):
        for r in range(LANES):
            ex = q[_ix(2 * i + 2, r)] - q[_ix(2 * i, r)]
            ey = q[_ix(2 * i + 3, r)] - q[_ix(2 * i + 1, r)]
            vx = 0.5 * (v[_ix(2 * i, r)] + v[_ix(2 * i + 2, r)])
            vy = 0.5 * (v[_ix(2 * i + 1, r)] + v[_ix(2 * i + 3, r)])
            w = vy * ex - vx * ey  # l v_n
            energy[2, r] += 0.5 * p[L_CM, r] * w * w / E[_ix(4 * i, r)]


@njit(cache=True, inline="always")
def _going(on, done, r):
    """True if lane ``r`` is on :func:`newton`'s common path and has not converged yet."""
    return on[r] and done[r] == 0


@njit(cache=True, inline="always")
def _any_going(on, done):
    """True if any lane is :func:`_going` (a loop: a mask expression would allocate arrays)."""
    for r in range(LANES):
        if _going(on, done, r):
            return True
    return False


@njit(cache=True, error_model="numpy", _nrt=False)
def _full_step(x, n2):
    """``_be_newton``'s update at full length for the lanes :func:`_going`: ``v = vacc + 1 dv``.

    ``vacc`` = v, ``dv`` = -R solved with the factors in J; the other lanes keep their ``v``:
    every lane is updated in one flat loop (module docstring), then theirs is copied back from
    ``vacc``.
    """
    _wide_vectors()
    v, R, J, vacc, dv, on, done = x.v, x.R, x.J, x.vacc, x.dv, x.on, x.done
    for k in range(n2 * LANES):
        vacc[k] = v[k]
        dv[k] = -R[k]
    solve(J, dv, n2)
    for k in range(n2 * LANES):
        v[k] = vacc[k] + 1.0 * dv[k]
    for r in range(LANES):
        if not _going(on, done, r):
            for k in range(n2):
                v[_ix(k, r)] = vacc[_ix(k, r)]


@njit(cache=True, error_model="numpy", _nrt=False)
def newton(s, first, go, x, p, dt, result):
    """:func:`stepper._be_newton` in water for the lanes with ``go[r]``, bit for bit.

    Lane r of block ``x`` is robot ``first + r`` of the stacked ``SimArrays`` ``s``, its stage
    set up by :func:`stage_start`. The block solves the common path (module docstring). A lane
    off it is put back into its robot as the stage started (:func:`put`), solved there by
    ``_be_newton``, and its results taken back (:func:`_load`). Every lane ends with the edges
    of its ``q`` in ``E``, its last residual's. Writes each lane's ``_be_newton`` result
    (status, iterations, residual, fluid power, friction power) into ``result`` (5, LANES) and
    its Newton counts into its robot's ``out``. Returns how many lanes the block solved.
    """
    _wide_vectors()
    res, res1, kept, on, done = x.res, x.res1, x.kept, x.on, x.done
    n2 = s.q.shape[1]
    on[:] = False  # lanes on the common path
    done[:] = 0  # 0: going on; else 1 + the iterations it converged in
    layout.copy_into(x.guess, x.v)
    residual(x, p, dt, True, res)
    for r in range(LANES):
        if not go[r]:
            continue
        if res[L_RMAX, r] <= p[L_TOL, r]:
            on[r], done[r] = True, 1
        else:  # an iteration cap of 0 or a non-finite start: _be_newton gives up, it says why
            on[r] = int(p[L_MAXIT, r]) > 0 and math.isfinite(res[L_NORM2, r])
    if _any_going(on, done):
        # the Newton step: factors, solve, the full step accepted if |R|^2 falls
        factor(x.J, kept, n2)
        _full_step(x, n2)
        residual(x, p, dt, False, res1)
        for r in range(LANES):
            if not _going(on, done, r):
                continue
            if not (kept[r] and res1[L_NORM2, r] < res[L_NORM2, r] * (1.0 - 1e-4 * 1.0)):
                on[r] = False  # a row exchange, or a line search
            elif res1[L_RMAX, r] <= p[L_TOL, r]:
                done[r] = 2
            elif not (
                1 < int(p[L_MAXIT, r])
                and math.isfinite(res1[L_NORM2, r])
                and res1[L_RMAX, r] <= p[L_CHORD, r] * res[L_RMAX, r]
            ):
                on[r] = False  # a renewed Jacobian, or the cap
        it = 1
        while _any_going(on, done):
            # a chord step: the same factors, accepted if |R|^2 falls; another while the largest
            # residual shrinks by the chord rate or more (res1: each lane's last accepted iterate)
            it += 1
            _full_step(x, n2)
            residual(x, p, dt, False, res)
            for r in range(LANES):
                if not _going(on, done, r):
                    continue
                if not res[L_NORM2, r] < res1[L_NORM2, r] * (1.0 - 1e-4):
                    on[r] = False  # a renewed Jacobian
                elif res[L_RMAX, r] <= p[L_TOL, r]:
                    done[r] = it + 1
                elif not (
                    it < min(int(p[L_MAXIT, r]), CHORD_STEPS + 1)
                    and math.isfinite(res[L_NORM2, r])
                    and res[L_RMAX, r] <= p[L_CHORD, r] * res1[L_RMAX, r]
                ):
                    on[r] = False  # a renewed Jacobian, the cap, or more chord steps than the block takes
                for k in range(N_LANE_RES):
                    res1[k, r] = res[k, r]
    solved = 0
    for r in range(LANES):
        if not go[r]:
            continue
        i = first + r
        si = layout.sim_views(s.f[i], s.ibuf[i])
        if not on[r]:
            put(s, i, x, r, x.guess)
            status, it, rmax, pf, pfr = stepper._be_newton(si, dt, MEDIUM_WATER)
            _load(si, x, r)  # what _be_newton changed: its last residual's, and the velocity
            _edges_into_lane(si.buf, x.E, r)
            for k in range(n2):
                x.v[_ix(k, r)] = si.v[k]
        else:
            it = done[r] - 1
            rmax, pf = (res[L_RMAX, r], res[L_PFLUID, r]) if it == 0 else (res1[L_RMAX, r], res1[L_PFLUID, r])
            status, pfr = OK, 0.0
            out = si.out
            out[O_NJAC] += 1.0
            out[O_NRES] += it
            out[O_NFACTOR] += 1.0 if it > 0 else 0.0
        result[0, r], result[1, r], result[2, r], result[3, r], result[4, r] = status, it, rmax, pf, pfr
        solved += on[r]
    return solved


# --- the ground: backward-Euler steps of worms, each lane a worker ------------------------------


@njit(cache=True, error_model="numpy", _nrt=False)
def ground_residual(x, p, dt, res):
    """``stepper._be_residual`` on the ground with its Jacobian, for every lane of a block.

    As :func:`residual` (the elastic forces in ``assemble``'s order), then isotropic kinetic
    friction on the sliding nodes and ``v_i = 0`` on the stuck ones (``x.slides`` 0). Writes ``q``,
    ``F``, ``R``, ``A`` = ``v - v0`` and the band ``J``; per lane into ``res`` (``L_NORM2``,
    ``L_RMAX``, ``L_PFRIC``). The Jacobian is always made: the residual's bits do not depend on
    it, and :func:`crawl` then has the Jacobian of every iterate it accepts.
    """
    _wide_vectors()
    v, m, F, R, A, J, slides = x.v, x.m, x.F, x.R, x.A, x.J, x.slides
    bits = J.view(np.int64)
    n2 = v.size // LANES
    cx, cv = -dt * dt, -dt
    _start_residual(x, dt)
    _clear_unreached(J, n2)
    _elastic(x, p, cx, cv, True)
    for k in range(R.size):
        R[k] = m[k] * A[k] - dt * F[k]
    _add_masses(J, m, res.shape[1])
    for r in range(LANES):
        res[L_PFRIC, r] = 0.0
    for i in range(n2 // 2):
        r0, r1 = 2 * i, 2 * i + 1
        for r in range(LANES):
            held = slides[_ix(i, r)] == 0
            vx, vy = v[_ix(r0, r)], v[_ix(r1, r)]
            fn = m[_ix(r0, r)] * p[L_G, r]
            fx, fy, d00, d01, d10, d11 = forces.isotropic_friction(vx, vy, p[L_MUD, r] * fn, p[L_EPS2, r])
            rx, ry = R[_ix(r0, r)] - dt * fx, R[_ix(r1, r)] - dt * fy  # every lane loads and stores
            R[_ix(r0, r)] = vx if held else rx
            R[_ix(r1, r)] = vy if held else ry
            res[L_PFRIC, r] -= 0.0 if held else fx * vx + fy * vy
            # stores of every lane (a store kept where a lane is held would be a masked store,
            # slow on AMD's cores); a held diagonal gains +0, which leaves it as it is (it is no -0)
            J[_jx(r0, KL, r)] += 0.0 if held else -dt * d00
            J[_jx(r0, KL + 1, r)] += -dt * d01
            J[_jx(r1, KL - 1, r)] += -dt * d10
            J[_jx(r1, KL, r)] += 0.0 if held else -dt * d11
        for r in range(LANES):  # a held node's rows: their assembled diagonal alone
            # the entries' bits and'ed with the mask: 0 where held (+0), all ones where the node
            # slides (as they are). Every lane stores, in vector code: a branch per lane left the
            # loop scalar, and a mask LLVM can see is 0 or -1 (made here from a test) it turns
            # back into that branch, so the mask is data (_await)
            keep = slides[_ix(i, r)]
            for c in range(BAND):
                if c != KL:
                    bits[_jx(r0, c, r)] &= keep
                    bits[_jx(r1, c, r)] &= keep
    _norms(R, x.minv, res)


# a worker lane's state, rows of (N_WORK_INT, LANES) int64 and (N_WORK, LANES) float64 arrays:
# the robot in the lane (-1: none) and its place in the list, the job's phase, steps done and
# to do, sub-steps done, _be_newton's counters, line-search trials, the status; Newton's
# |R|^2, max |R|/m and friction power at the iterate, the line search's step, the actuator
# power at the sub-step's start, simulate's sums over the sub-steps
W_ROBOT, W_SLOT, W_PHASE, W_STEP, W_NSTEPS, W_SUB, W_IT, W_PASS, W_SEARCHED, W_TRIALS, W_RENEW = range(11)
W_STATUS, W_NITER = 11, 12
N_WORK_INT = 13
W_NORM2, W_RMAX, W_PFRIC, W_LS, W_PACT0, W_RESID, W_EDAMP, W_EFRIC, W_EACT = range(9)
N_WORK = 9
# the phases of a job: a step begins, a sub-step begins, Newton's loop (its top), a residual
# awaited at a Newton iterate or at a line-search trial, a Newton step awaited (the
# factorization and solve), a sub-step ends, a step ends
_STEP, _SUB, _TOP, _POINT, _TRIAL, _SOLVE, _SUB_END, _STEP_END = range(8)
# what a lane's job awaits when it stops (_work's result): nothing (it ended), a residual, a solve
_ENDED, _RESIDUAL, _NEWTON_STEP = range(3)


@njit(cache=True, error_model="numpy", _nrt=False)
def crawl_eligible(prm):
    """True if :func:`crawl` takes the robot: on the ground, backward Euler, isotropic friction."""
    return (
        int(prm[P_MEDIUM]) == MEDIUM_GROUND
        and int(prm[P_METHOD]) == METHOD_BACKWARD_EULER
        and prm[P_ANISO] == 0.0
    )


@njit(cache=True, error_model="numpy", _nrt=False)
def crawl(s, uk, ul, robots, nsteps, status, x, p, wi, wf):
    """``stepper.simulate(robot, uk[i], ul[i], nsteps[k])`` for each robot ``i = robots[k]``, bit for bit.

    Robots of stacked ``SimArrays`` ``s``, every one :func:`crawl_eligible` with the same ``h``
    and sub-steps; the status of ``robots[k]`` into ``status[k]``. Each lane of block ``x`` is
    a worker: it runs one robot's job (``simulate``'s steps and sub-steps, each a ``_be_start``
    and ``_be_newton``'s loop on the ground) in the robot's own arrays, with ``stepper``'s own
    functions, up to the point where ``_be_newton`` evaluates a residual; then it waits. Each
    round evaluates the sixteen lanes' residuals with their Jacobians at once
    (:func:`ground_residual`), and each lane goes on to its next residual, or ends its job and
    takes the next robot, so that lanes stay busy however many iterations each robot's step
    takes. ``wi``, ``wf``: the workers' state (``W_*`` rows).

    Every residual comes with its Jacobian, so where ``_be_newton`` assembles the Jacobian again
    at the iterate a line search accepted, the trial's serves (the same bits): it is counted in
    ``out[O_NJAC]`` as ``_be_newton`` counts it, and not computed. Each round also factors and
    solves every lane's system at once (:func:`factor`, :func:`solve`), before the lanes go on,
    so a lane that takes a Newton step at its residual takes it in the same visit; a lane whose
    factors would exchange rows takes ``band_factor``'s own step (:func:`_newton_step`). Once
    no robot is left to take and at most :data:`SCALAR_TAIL` lanes are busy, their jobs end one
    by one in scalar code (:func:`_finish_alone`), where a round would cost the whole block. Bit
    for bit, but for the sign and payload of a NaN, which in vector code depend on the order in
    which an instruction takes its operands: a robot whose state is not finite fails as alone,
    its diagnostics NaN as alone.
    """
    robots, nsteps, status, wi, wf = layout.borrowed((robots, nsteps, status, wi, wf))
    first = robots[0]
    dt = s.prm[first, P_H] / int(s.prm[first, P_SUBSTEPS])  # as stepper.simulate
    n2 = s.q.shape[1]
    taken = 0
    for r in range(LANES):
        wi[W_ROBOT, r] = -1
        taken = _next_job(s, uk, ul, robots, nsteps, status, taken, wi, r)
    while True:
        # each lane goes on from its residual (the first time, starts its job). At a Newton step
        # it takes the solution already made at that residual and goes on to its next residual.
        # A lane whose job ends takes the next robot and starts its job in the same visit
        for r in range(LANES):
            i = wi[W_ROBOT, r]
            if i < 0:
                continue
            si = layout.sim_views(s.f[i], s.ibuf[i])
            while True:
                awaits = _work(si, uk[i], ul[i], x, p, wi, wf, dt, r)
                if awaits == _RESIDUAL:
                    break
                if awaits == _NEWTON_STEP:
                    if not _newton_step(si, x, dt, r, False):
                        wi[W_STATUS, r], wi[W_PHASE, r] = NOT_CONVERGED, _SUB_END
                    continue
                taken = _next_job(s, uk, ul, robots, nsteps, status, taken, wi, r)
                i = wi[W_ROBOT, r]
                if i < 0:
                    break
                si = layout.sim_views(s.f[i], s.ibuf[i])
        busy = 0
        for r in range(LANES):
            busy += wi[W_ROBOT, r] >= 0
        if busy == 0:
            return
        if taken == robots.size and busy <= SCALAR_TAIL:
            for r in range(LANES):
                if wi[W_ROBOT, r] >= 0:
                    _finish_alone(s, uk, ul, robots, nsteps, status, x, p, wi, wf, dt, r)
            return
        # every lane's residual, and the Newton step from it, whether or not the lane takes it:
        # about 70 % of the lanes do at a residual, and a round with none at a Newton step was
        # not seen (256 worms under random actions, 108 rounds a step, every one factored)
        ground_residual(x, p, dt, x.res)
        factor(x.J, x.kept, n2)
        for k in range(n2 * LANES):
            x.dv[k] = -x.R[k]
        solve(x.J, x.dv, n2)


@njit(cache=True, error_model="numpy", _nrt=False)
def _finish_alone(s, uk, ul, robots, nsteps, status, x, p, wi, wf, dt, r):
    """Lane ``r``'s job, awaiting a residual, run to its end in scalar code; no robot is left to take.

    Each residual is the robot's own (``stepper._be_residual`` with its Jacobian, the lane's
    bits) and each Newton step ``band_factor``'s on that Jacobian, for :func:`_work`'s phases as
    the lanes serve them; the residual's ``q``, ``F``, ``R`` and ``A`` go into the lane, where
    :func:`_store` reads them.
    """
    i = wi[W_ROBOT, r]
    si = layout.sim_views(s.f[i], s.ibuf[i])
    while True:
        norm2, rmax, _, p_fric = stepper._be_residual(si, dt, MEDIUM_GROUND, True)
        si.out[O_NJAC] -= 1.0  # _await counted it
        x.res[L_NORM2, r], x.res[L_RMAX, r], x.res[L_PFRIC, r] = norm2, rmax, p_fric
        _load(si, x, r)
        awaits = _work(si, uk[i], ul[i], x, p, wi, wf, dt, r)
        if awaits == _NEWTON_STEP:
            if not _newton_step(si, x, dt, r, True):
                wi[W_STATUS, r], wi[W_PHASE, r] = NOT_CONVERGED, _SUB_END
            awaits = _work(si, uk[i], ul[i], x, p, wi, wf, dt, r)
        if awaits == _ENDED:
            _next_job(s, uk, ul, robots, nsteps, status, robots.size, wi, r)
            return


@njit(cache=True, inline="always", error_model="numpy")
def _newton_step(si, x, dt, r, alone):
    """``_be_newton``'s factorization and solve for lane ``r``: ``vacc = v`` and ``dv`` in the robot's ``buf``.

    From the lane's factors where they kept every row, else by ``band_factor`` on the robot's
    band, assembled again at the same iterate (the same bits; not counted), or, if ``alone``
    (:func:`_finish_alone`), as the robot's own residual left it. False where ``band_factor``
    fails.
    """
    v, buf, ibuf = si.v, si.buf, si.ibuf
    n = v.size
    vacc, dv = buf[B_VACC], buf[B_DV]
    if x.kept[r] and not alone:
        for k in range(n):
            vacc[k] = v[k]
            dv[k] = x.dv[_ix(k, r)]
        return True
    if not alone:
        stepper._be_residual(si, dt, MEDIUM_GROUND, True)
        si.out[O_NJAC] -= 1.0
    piv = ibuf[I_PIV]
    if not banded.band_factor(si.J, piv, n, PIVOT_THRESHOLD):
        return False
    R = buf[B_R]
    for k in range(n):
        vacc[k] = v[k]
        dv[k] = -R[k]
    banded.band_solve(si.J, piv, n, dv)
    return True


@njit(cache=True, error_model="numpy", _nrt=False)
def _next_job(s, uk, ul, robots, nsteps, status, taken, wi, r):
    """Record the status of lane ``r``'s ended job, if any, and give it the next robot after the first ``taken``.

    Returns how many are taken now. The new job starts at its first step (``_STEP``); the lane
    is left empty (``W_ROBOT`` -1) when no robot is left.
    """
    if wi[W_ROBOT, r] >= 0:
        status[wi[W_SLOT, r]] = wi[W_STATUS, r]
    if taken == robots.size:
        wi[W_ROBOT, r] = -1
        return taken
    i = robots[taken]
    si = layout.sim_views(s.f[i], s.ibuf[i])
    wi[W_ROBOT, r], wi[W_SLOT, r], wi[W_PHASE, r] = i, taken, _STEP
    wi[W_STEP, r], wi[W_NSTEPS, r], wi[W_STATUS, r] = 0, nsteps[taken], OK
    if si.prm[P_LAG] == 0.0:  # as stepper.simulate: no lag, the rates jump to the inputs
        layout.copy_into(si.buf[B_LRATE, : si.lbar.size], ul[i])
    return taken + 1


@njit(cache=True, inline="always", error_model="numpy")
def _await(si, x, wi, r, phase, jac):
    """Lane ``r`` waits for the residual at its robot's iterate (``jac``: counted as one with its Jacobian).

    The lane takes the robot's velocity, and at ``_POINT`` its stuck nodes too: a pass of
    Newton's loop starts there, where the contacts have just changed (a sub-step's start, a
    contact pass, a reversal held, a slow node stuck), and nowhere else do they change.
    """
    si.out[O_NJAC if jac else O_NRES] += 1.0
    wi[W_PHASE, r] = phase
    for k in range(si.v.size):
        x.v[_ix(k, r)] = si.v[k]
    if phase == _POINT:
        state = si.ibuf[I_FRICTION]
        for k in range(state.size // 2):
            x.slides[_ix(k, r)] = 0 if state[k] == STUCK else -1
    return _RESIDUAL


@njit(cache=True, inline="always", error_model="numpy")
def _store(si, x, r, whole):
    """What ``_be_residual`` wrote at lane ``r``'s last iterate, into its robot: ``F``; if ``whole``, ``q``, ``R`` and ``A`` too.

    The lane's residual serves the lane's Newton; the robot needs its forces where
    ``_update_contacts`` reads them, and the rest where its sub-step ends.
    """
    buf = si.buf
    for k in range(si.q.size):
        buf[B_F, k] = x.F[_ix(k, r)]
    if whole:
        for k in range(si.q.size):
            si.q[k] = x.q[_ix(k, r)]
            buf[B_R, k] = x.R[_ix(k, r)]
            buf[B_A, k] = x.A[_ix(k, r)]


@njit(cache=True, inline="always", error_model="numpy")
def _load(si, x, r):
    """What ``_be_residual`` wrote into a robot's arrays, ``q``, ``F``, ``R`` and ``A``, into lane ``r``: :func:`_store`'s inverse."""
    buf = si.buf
    for k in range(si.q.size):
        x.q[_ix(k, r)] = si.q[k]
        x.F[_ix(k, r)] = buf[B_F, k]
        x.R[_ix(k, r)] = buf[B_R, k]
        x.A[_ix(k, r)] = buf[B_A, k]


@njit(cache=True, inline="always", error_model="numpy")
def _start_solve(si, x, p, r):
    """Copy a robot's implicit step, set up by ``_be_start``, into lane ``r``: its start, masses, rest shape and parameters."""
    buf, prm = si.buf, si.prm
    for k in range(si.q.size):
        x.q0[_ix(k, r)] = buf[B_Q0, k]
        x.v0[_ix(k, r)] = buf[B_V0, k]
        x.fext[_ix(k, r)] = buf[B_FEXT, k]
        x.m[_ix(k, r)] = buf[B_M, k]
        x.minv[_ix(k, r)] = buf[B_MINV, k]
    for k in range(si.kbar.size):
        x.kbar[_ix(k, r)] = si.kbar[k]
    for k in range(si.lbar.size):
        x.lbar[_ix(k, r)] = si.lbar[k]
    p[L_EA, r], p[L_EI, r], p[L_D, r], p[L_DB, r] = prm[P_EA], prm[P_EI], prm[P_DSTRETCH], prm[P_DBEND]
    p[L_MUD, r], p[L_G, r] = prm[P_MUD], prm[P_G]
    p[L_EPS2, r] = (0.1 * prm[P_VTOL]) ** 2  # as _be_residual


@njit(cache=True, inline="always", error_model="numpy")
def _work(si, u_k, u_l, x, p, wi, wf, dt, r):
    """Run lane ``r``'s job on until it awaits something; returns what (``_RESIDUAL``, ``_NEWTON_STEP``, ``_ENDED``).

    The phases are ``stepper.simulate``'s loops and ``_be_newton``'s on the ground (never a chord
    step there), in their order (:func:`_advance`). A lane that awaited a residual (``_POINT``,
    ``_TRIAL``) finds it in ``x.res`` and the robot's ``q``, ``F``, ``R``, ``A``, its Jacobian in
    its lane of ``x.J``; one that awaited a Newton step (``_SOLVE``) finds ``vacc`` and ``dv`` in
    the robot's ``buf``. An ended job's status is in ``W_STATUS``.
    """
    awaits, phase, jac = _advance(si, u_k, u_l, x, p, wi, wf, dt, r)
    if awaits == _RESIDUAL:  # one place that hands the iterate to the lane
        _await(si, x, wi, r, phase, jac)
    return awaits


@njit(cache=True, inline="always", error_model="numpy")
def _advance(si, u_k, u_l, x, p, wi, wf, dt, r):
    """:func:`_work`'s phases: (what the lane awaits, the phase it awaits in, whether with the Jacobian)."""
    q, v, prm, buf, ibuf, out = si.q, si.v, si.prm, si.buf, si.ibuf, si.out
    n = q.size
    tol, maxit = prm[P_TOL], int(prm[P_MAXIT])
    vacc, dv = buf[B_VACC], buf[B_DV]
    phase = wi[W_PHASE, r]
    if phase == _POINT:
        wf[W_NORM2, r], wf[W_RMAX, r], wf[W_PFRIC, r] = x.res[L_NORM2, r], x.res[L_RMAX, r], x.res[L_PFRIC, r]
        wi[W_PHASE, r] = _TOP
    elif phase == _TRIAL:
        norm2, rmax = x.res[L_NORM2, r], x.res[L_RMAX, r]
        step = wf[W_LS, r]
        if not norm2 < wf[W_NORM2, r] * (1.0 - 1e-4 * step):  # _be_newton's backtracking
            step *= 0.5
            wf[W_LS, r] = step
            wi[W_TRIALS, r] += 1
            if wi[W_TRIALS, r] < 12:
                for k in range(n):
                    v[k] = vacc[k] + step * dv[k]
                return _RESIDUAL, _TRIAL, False
        if step < 1.0:
            wi[W_SEARCHED, r] = wi[W_PASS, r]
        wf[W_NORM2, r], wf[W_RMAX, r], wf[W_PFRIC, r] = norm2, rmax, x.res[L_PFRIC, r]
        if rmax > tol and stepper._stick_slow_nodes(v, ibuf, prm, n):
            wi[W_PASS, r] = 0
            return _RESIDUAL, _POINT, True
        if (
            rmax > tol
            and wi[W_PASS, r] < maxit
            and math.isfinite(norm2)
            and not (wi[W_RENEW, r] and step == 1.0)
        ):
            out[O_NJAC] += 1.0  # _be_newton's Jacobian at the accepted iterate: the trial's
        wi[W_PHASE, r] = _TOP
    elif phase == _SOLVE:
        if stepper._reversal_in_update(v, dv, buf[B_VSLIDE], ibuf, n):
            wi[W_PASS, r] = 0
            return _RESIDUAL, _POINT, True
        renew = wf[W_RMAX, r] * wf[W_RMAX, r] > tol and wi[W_SEARCHED, r] != wi[W_PASS, r] - 1
        wf[W_LS, r], wi[W_TRIALS, r], wi[W_RENEW, r] = 1.0, 0, renew
        for k in range(n):
            v[k] = vacc[k] + 1.0 * dv[k]
        return _RESIDUAL, _TRIAL, renew
    while True:
        phase = wi[W_PHASE, r]
        if phase == _STEP:
            if wi[W_STEP, r] == wi[W_NSTEPS, r]:  # its last sub-step's powers left q's geometry
                stepper.ledger_energies(si, True)
                return _ENDED, _STEP, False
            wi[W_NITER, r], wi[W_SUB, r] = 0, 0
            for k in range(W_RESID, N_WORK):
                wf[k, r] = 0.0
            out[O_NJAC] = out[O_NRES] = out[O_NFACTOR] = 0.0
            wi[W_PHASE, r] = _SUB
        elif phase == _SUB:
            status, p_act0 = stepper.move_rest_shape(si, u_k, u_l, dt)
            wf[W_PACT0, r] = p_act0
            if status != OK:
                wi[W_STATUS, r], wi[W_PHASE, r] = status, _STEP_END
                continue
            stepper._be_start(si, MEDIUM_GROUND, 1.0)
            _start_solve(si, x, p, r)
            wi[W_IT, r], wi[W_PASS, r], wi[W_SEARCHED, r] = 0, 0, -1
            return _RESIDUAL, _POINT, True
        elif phase == _TOP:
            if wf[W_RMAX, r] <= tol:
                _store(si, x, r, False)
                if not stepper._update_contacts(v, buf, ibuf, prm, dt, n):
                    wi[W_STATUS, r], wi[W_PHASE, r] = OK, _SUB_END
                    continue
                wi[W_PASS, r] = 0
                return _RESIDUAL, _POINT, True
            if wi[W_PASS, r] == maxit or not math.isfinite(wf[W_NORM2, r]):
                wi[W_STATUS, r], wi[W_PHASE, r] = NOT_CONVERGED, _SUB_END
                continue
            wi[W_IT, r] += 1
            wi[W_PASS, r] += 1
            out[O_NFACTOR] += 1.0
            wi[W_PHASE, r] = _SOLVE
            return _NEWTON_STEP, _SOLVE, False
        elif phase == _SUB_END:
            _store(si, x, r, True)
            _, ed, efr, ea = stepper.implicit_energies(si, u_k, dt, wf[W_PACT0, r], 0.0, wf[W_PFRIC, r])
            wi[W_NITER, r] = max(wi[W_NITER, r], wi[W_IT, r])
            wf[W_RESID, r] = max(wf[W_RESID, r], wf[W_RMAX, r])
            wf[W_EDAMP, r] += ed
            wf[W_EFRIC, r] += efr
            wf[W_EACT, r] += ea
            wi[W_SUB, r] += 1
            done = wi[W_STATUS, r] != OK or wi[W_SUB, r] == int(prm[P_SUBSTEPS])
            wi[W_PHASE, r] = _STEP_END if done else _SUB
        else:  # _STEP_END
            status = stepper.end_step(
                si,
                wi[W_STATUS, r],
                wi[W_NITER, r],
                wf[W_RESID, r],
                0.0,
                wf[W_EDAMP, r],
                wf[W_EFRIC, r],
                wf[W_EACT, r],
            )
            wi[W_STATUS, r] = status
            wi[W_STEP, r] += 1
            if status != OK:
                stepper.ledger_energies(si, True)
                return _ENDED, _STEP, False
            wi[W_PHASE, r] = _STEP
