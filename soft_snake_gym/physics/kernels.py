"""Numba kernels of the planar discrete elastic rod (docs/model.md §2-§5a).

Conventions: positions ``q`` and velocities ``v`` are flat, interleaved arrays of length 2N
(``q[2i], q[2i+1]`` are x, y of node i) so that they index the banded Jacobian directly; the
simulator exposes them as (N, 2) views. Rest curvatures ``kbar`` (N-2) belong to the interior
nodes 1..N-2 (``kbar[j-1]`` at node j), rest lengths ``lbar`` (N-1) to the edges. All kernels
take contiguous float64 arrays, write outputs in place, allocate nothing and raise nothing;
failures come back as a status code.

Parameters travel in one float64 vector ``prm`` (indices ``P_*``), per-robot scratch in
``buf`` (rows ``B_*``, each 2N long), integer scratch in ``ibuf`` (rows ``I_*``) and step
diagnostics in ``out`` (indices ``O_*``). A batch of robots is the same arrays with a leading
axis, each robot stepped by the same :func:`simulate` call.
"""

from __future__ import annotations

import math

from numba import njit

from soft_snake_gym.physics import banded
from soft_snake_gym.physics.banded import KL, band_lu, band_solve
from soft_snake_gym.physics.cache import drop_stale_cache

drop_stale_cache(__file__, [banded.__file__])  # the cached kernels embed banded.py's code

# --- parameter vector ----------------------------------------------------------------------
P_EA, P_EI, P_DBEND, P_RHO, P_CF, P_CD, P_CA, P_A, P_B = 0, 1, 2, 3, 4, 5, 6, 7, 8
P_MUS, P_MUD, P_VTOL, P_G = 9, 10, 11, 12
P_H, P_SUBSTEPS, P_TOL, P_MAXIT, P_MEDIUM, P_METHOD, P_MAXSTRAIN, P_CHECKSI = (
    13, 14, 15, 16, 17, 18, 19, 20,
)
P_DSTRETCH = 21
P_ADDED_MASS = 22  # ADDED_MASS_* code

P_ANISO, P_MU_FWD, P_MU_BWD, P_MU_LAT = 23, 24, 25, 26  # anisotropic kinetic friction
N_PRM = 27

ADDED_MASS_CONSISTENT, ADDED_MASS_KELASIDI = 0, 1

MEDIUM_NONE, MEDIUM_WATER, MEDIUM_GROUND = 0, 1, 2
METHOD_BACKWARD_EULER, METHOD_SYMPLECTIC_EULER = 0, 1

# --- scratch rows ----------------------------------------------------------------------------
B_R, B_DV, B_F, B_Q0, B_V0, B_VACC, B_M, B_FEXT, B_KEYS, B_A, B_P0 = range(11)
N_BUF = 11
I_PIV, I_ORDER, I_FRICTION, I_SWITCHES = 0, 1, 2, 3
N_IBUF = 4
SLIDING, STUCK = 0, 1
MAX_SWITCHES = 2  # contact changes per node and step: bounds the active-set passes

# --- diagnostics -----------------------------------------------------------------------------
(O_STATUS, O_NITER, O_RESIDUAL, O_P_FLUID, O_P_FRICTION, O_P_ACT, O_E_FLUID, O_E_FRICTION,
 O_E_ACT, O_W_ACT, O_NSTEPS) = range(11)
# energy ledger (docs/model.md §4): damping power of the last step and its accumulated energy, and
# the body's kinetic and elastic energy and the water's kinetic energy T_f after the last step
O_P_DAMP, O_E_DAMP, O_E_KIN, O_E_ELASTIC, O_T_FLUID = range(11, 16)
# where the ledger starts (written at reset/set_state): those energies and the accumulated work
# and dissipation at that moment
O_L0_KIN, O_L0_ELASTIC, O_L0_T_FLUID, O_L0_W_ACT, O_L0_E_FLUID, O_L0_E_DAMP, O_L0_E_FRICTION = range(16, 23)
# the ledger since then, ``out[O_LEDGER : O_LEDGER + 8]`` in the order of LEDGER_KEYS
O_LEDGER, N_LEDGER = 23, 8
LEDGER_KEYS = ("actuator_work", "fluid_dissipation", "damping_dissipation", "friction_dissipation",
               "delta_kinetic", "delta_elastic", "delta_fluid_kinetic", "error")
N_OUT = 31  # simulated time is O_NSTEPS * h: derived, so it cannot drift

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


@njit(cache=True, inline="always", error_model="numpy")
def _add_block(J, i, j, m00, m01, m10, m11):
    """Add a 2x2 block to the band at node pair (i, j)."""
    r = 2 * i
    c = 2 * j - r + KL
    J[r, c] += m00
    J[r, c + 1] += m01
    J[r + 1, c - 1] += m10
    J[r + 1, c] += m11


@njit(cache=True, inline="always", error_model="numpy")
def _add_edge_pattern(J, k, s00, s01, s11):
    """Add the pattern [[-S, S], [S, -S]] of a symmetric 2x2 S to nodes (k, k+1)."""
    _add_block(J, k, k, -s00, -s01, -s01, -s11)
    _add_block(J, k, k + 1, s00, s01, s01, s11)
    _add_block(J, k + 1, k, s00, s01, s01, s11)
    _add_block(J, k + 1, k + 1, -s00, -s01, -s01, -s11)


@njit(cache=True, error_model="numpy")
def turning(q, j):
    """Turning quantities at interior node j (docs/model.md §2).

    Returns:
        (kappa, g0x, g0y, g1x, g1y, g2x, g2y, ta, tb, la, lb) packed as: kappa, the gradient
        d phi / d x of nodes j-1, j, j+1, and the unit tangents and lengths of both edges.
    """
    ax = q[2 * j] - q[2 * j - 2]
    ay = q[2 * j + 1] - q[2 * j - 1]
    bx = q[2 * j + 2] - q[2 * j]
    by = q[2 * j + 3] - q[2 * j + 1]
    la = math.sqrt(ax * ax + ay * ay)
    lb = math.sqrt(bx * bx + by * by)
    tax, tay = ax / la, ay / la
    tbx, tby = bx / lb, by / lb
    cross = tax * tby - tay * tbx
    dot = tax * tbx + tay * tby
    kappa = 2.0 * cross / (1.0 + dot)
    # n = (-t_y, t_x); d phi/d x_{j-1} = n_a/l_a, d phi/d x_{j+1} = n_b/l_b
    g0x, g0y = -tay / la, tax / la
    g2x, g2y = -tby / lb, tbx / lb
    return kappa, g0x, g0y, -g0x - g2x, -g0y - g2y, g2x, g2y, tax, tay, tbx, tby, la, lb


@njit(cache=True, inline="always", error_model="numpy")
def edge_frame(q, v, i):
    """Edge i's length ``l``, unit tangent ``t`` and normal ``n = (-t_y, t_x)``, its mean
    velocity ``v^i = (v[i] + v[i+1]) / 2`` and that velocity's components ``v_t``, ``v_n``
    (docs/model.md §2, §4), as (l, tx, ty, nx, ny, vx, vy, vt, vn)."""
    ex = q[2 * i + 2] - q[2 * i]
    ey = q[2 * i + 3] - q[2 * i + 1]
    l = math.sqrt(ex * ex + ey * ey)
    tx, ty = ex / l, ey / l
    nx, ny = -ty, tx
    vx = 0.5 * (v[2 * i] + v[2 * i + 2])
    vy = 0.5 * (v[2 * i + 1] + v[2 * i + 3])
    return l, tx, ty, nx, ny, vx, vy, vx * tx + vy * ty, vx * nx + vy * ny


@njit(cache=True, error_model="numpy")
def curvatures(q, kappa):
    """Discrete curvature ``kappa_j = 2 tan(phi_j/2)`` of the interior nodes, (N-2,) [-]."""
    for j in range(1, q.size // 2 - 1):
        kappa[j - 1] = turning(q, j)[0]


@njit(cache=True, error_model="numpy")
def curvature_rates(q, v, kdot):
    """Exact curvature rate ``(1 + kappa^2/4)(theta_dot^j - theta_dot^(j-1))``, (N-2,) [1/s]."""
    for j in range(1, q.size // 2 - 1):
        k, g0x, g0y, g1x, g1y, g2x, g2y = turning(q, j)[:7]
        phidot = (g0x * v[2 * j - 2] + g0y * v[2 * j - 1] + g1x * v[2 * j] + g1y * v[2 * j + 1]
                  + g2x * v[2 * j + 2] + g2y * v[2 * j + 3])
        kdot[j - 1] = (1.0 + 0.25 * k * k) * phidot


@njit(cache=True, error_model="numpy")
def edge_lengths(q, out):
    """Current edge lengths ``|e^k|``, (N-1,) [m]."""
    for k in range(q.size // 2 - 1):
        out[k] = math.hypot(q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1])


@njit(cache=True, error_model="numpy")
def edge_length_rates(q, v, out):
    """Rates ``t^k . (v[k+1] - v[k])`` of the edge lengths, (N-1,) [m/s]."""
    for k in range(q.size // 2 - 1):
        ex = q[2 * k + 2] - q[2 * k]
        ey = q[2 * k + 3] - q[2 * k + 1]
        l = math.hypot(ex, ey)
        out[k] = (ex * (v[2 * k + 2] - v[2 * k]) + ey * (v[2 * k + 3] - v[2 * k + 1])) / l


@njit(cache=True, error_model="numpy")
def elastic_energy(q, kbar, lbar, prm):
    """Stretching plus bending energy ``E_s + E_b`` (docs/model.md §3) [J]."""
    N = q.size // 2
    EA, EI = prm[P_EA], prm[P_EI]
    e = 0.0
    for k in range(N - 1):
        l = math.hypot(q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1])
        s = l / lbar[k] - 1.0
        e += 0.5 * EA * s * s * lbar[k]
    for j in range(1, N - 1):
        dk = turning(q, j)[0] - kbar[j - 1]
        e += 0.5 * EI / (0.5 * (lbar[j - 1] + lbar[j])) * dk * dk
    return e


@njit(cache=True, error_model="numpy")
def assemble(q, v, kbar, lbar, prm, F, J, cx, cv, jac, water):
    """Add internal (elastic, damping) and, if ``water``, drag forces into F (2N,) [N].

    If ``jac``, also add ``cx dF/dq + cv dF/dv`` into the band ``J`` (exact, damping's
    position dependence included: without it Newton needs a second iteration every step).
    Returns the power lost to drag ``-sum F_D . v_edge`` [W].
    """
    N = q.size // 2
    EA, EI, d, db = prm[P_EA], prm[P_EI], prm[P_DSTRETCH], prm[P_DBEND]
    # stretching (docs/model.md §3): force on x[k+1] is -EA (|e|/lbar - 1) t
    for k in range(N - 1):
        ex = q[2 * k + 2] - q[2 * k]
        ey = q[2 * k + 3] - q[2 * k + 1]
        l = math.sqrt(ex * ex + ey * ey)
        tx, ty = ex / l, ey / l
        lb = lbar[k]
        strain = l / lb - 1.0
        f = -EA * strain
        ldot = 0.0
        if d > 0.0:
            dvx, dvy = v[2 * k + 2] - v[2 * k], v[2 * k + 3] - v[2 * k + 1]
            ldot = tx * dvx + ty * dvy
            f -= d * ldot
        F[2 * k + 2] += f * tx
        F[2 * k + 3] += f * ty
        F[2 * k] -= f * tx
        F[2 * k + 1] -= f * ty
        if jac:
            # -dF_{k+1}/dx_{k+1} = EA t t^T / lbar - f/l (I - t t^T) + d t p^T, with the
            # turning of the stretch rate p = d ldot / d x_{k+1} = (dv - ldot t) / l
            a1 = EA / lb
            a2 = -f / l
            s00 = cx * (a1 * tx * tx + a2 * (1.0 - tx * tx)) + cv * d * tx * tx
            s01 = cx * (a1 - a2) * tx * ty + cv * d * tx * ty
            s11 = cx * (a1 * ty * ty + a2 * (1.0 - ty * ty)) + cv * d * ty * ty
            _add_edge_pattern(J, k, s00, s01, s11)
            if d > 0.0:
                px, py = cx * d * (dvx - ldot * tx) / l, cx * d * (dvy - ldot * ty) / l
                t00, t01, t10, t11 = tx * px, tx * py, ty * px, ty * py
                _add_block(J, k, k, -t00, -t01, -t10, -t11)
                _add_block(J, k, k + 1, t00, t01, t10, t11)
                _add_block(J, k + 1, k, t00, t01, t10, t11)
                _add_block(J, k + 1, k + 1, -t00, -t01, -t10, -t11)
    # bending (docs/model.md §3): F = -(EI/lvor)(kappa - kbar)(1 + kappa^2/4) d phi/d x
    for j in range(1, N - 1):
        kap, g0x, g0y, g1x, g1y, g2x, g2y, tax, tay, tbx, tby, la, lbn = turning(q, j)
        kb = EI / (0.5 * (lbar[j - 1] + lbar[j]))
        dk = kap - kbar[j - 1]
        w = 1.0 + 0.25 * kap * kap
        s = kb * dk * w  # dE/dphi
        phidot = 0.0
        if db > 0.0:
            phidot = (g0x * v[2 * j - 2] + g0y * v[2 * j - 1] + g1x * v[2 * j]
                      + g1y * v[2 * j + 1] + g2x * v[2 * j + 2] + g2y * v[2 * j + 3])
            s += db * w * w * phidot  # -d kappa_dot mapped through d kappa/d x
        F[2 * j - 2] -= s * g0x
        F[2 * j - 1] -= s * g0y
        F[2 * j] -= s * g1x
        F[2 * j + 1] -= s * g1y
        F[2 * j + 2] -= s * g2x
        F[2 * j + 3] -= s * g2y
        if jac:
            # d2E/dphi2 and the Hessians of the edge angles, H = -(t n^T + n t^T)/l^2
            # damping s_d = db w^2 phidot adds d s_d/dx = db w^2 (kappa phidot g + r), with
            # r = (d phidot / d x) = sum_b d2phi/dx dx_b v_b
            s2 = kb * (w * w + dk * 0.5 * kap * w) + db * w * w * kap * phidot
            alpha = -(cx * s2 + cv * db * w * w)
            beta = -cx * (kb * dk * w + db * w * w * phidot)
            ia = 1.0 / (la * la)
            ib = 1.0 / (lbn * lbn)
            ha00, ha01, ha11 = 2.0 * tax * tay * ia, (tay * tay - tax * tax) * ia, -2.0 * tax * tay * ia
            hb00, hb01, hb11 = 2.0 * tbx * tby * ib, (tby * tby - tbx * tbx) * ib, -2.0 * tbx * tby * ib
            if db > 0.0:
                # r_{j-1} = Ha (v_j - v_{j-1}), r_{j+1} = Hb (v_{j+1} - v_j), r_j = -(the two)
                ux, uy = v[2 * j] - v[2 * j - 2], v[2 * j + 1] - v[2 * j - 1]
                wx, wy = v[2 * j + 2] - v[2 * j], v[2 * j + 3] - v[2 * j + 1]
                r0x, r0y = ha00 * ux + ha01 * uy, ha01 * ux + ha11 * uy
                r2x, r2y = hb00 * wx + hb01 * wy, hb01 * wx + hb11 * wy
                r1x, r1y = -r0x - r2x, -r0y - r2y
                c = -cx * db * w * w
                for a, gx, gy in ((j - 1, g0x, g0y), (j, g1x, g1y), (j + 1, g2x, g2y)):
                    _add_block(J, a, j - 1, c * gx * r0x, c * gx * r0y, c * gy * r0x, c * gy * r0y)
                    _add_block(J, a, j, c * gx * r1x, c * gx * r1y, c * gy * r1x, c * gy * r1y)
                    _add_block(J, a, j + 1, c * gx * r2x, c * gx * r2y, c * gy * r2x, c * gy * r2y)
            # d2phi blocks: (0,0) -Ha, (0,1) Ha, (1,1) Hb - Ha, (1,2) -Hb, (2,2) Hb
            _add_block(J, j - 1, j - 1, alpha * g0x * g0x - beta * ha00, alpha * g0x * g0y - beta * ha01,
                       alpha * g0y * g0x - beta * ha01, alpha * g0y * g0y - beta * ha11)
            _add_block(J, j - 1, j, alpha * g0x * g1x + beta * ha00, alpha * g0x * g1y + beta * ha01,
                       alpha * g0y * g1x + beta * ha01, alpha * g0y * g1y + beta * ha11)
            _add_block(J, j, j - 1, alpha * g1x * g0x + beta * ha00, alpha * g1x * g0y + beta * ha01,
                       alpha * g1y * g0x + beta * ha01, alpha * g1y * g0y + beta * ha11)
            _add_block(J, j - 1, j + 1, alpha * g0x * g2x, alpha * g0x * g2y,
                       alpha * g0y * g2x, alpha * g0y * g2y)
            _add_block(J, j + 1, j - 1, alpha * g2x * g0x, alpha * g2x * g0y,
                       alpha * g2y * g0x, alpha * g2y * g0y)
            _add_block(J, j, j, alpha * g1x * g1x + beta * (hb00 - ha00),
                       alpha * g1x * g1y + beta * (hb01 - ha01),
                       alpha * g1y * g1x + beta * (hb01 - ha01),
                       alpha * g1y * g1y + beta * (hb11 - ha11))
            _add_block(J, j, j + 1, alpha * g1x * g2x - beta * hb00, alpha * g1x * g2y - beta * hb01,
                       alpha * g1y * g2x - beta * hb01, alpha * g1y * g2y - beta * hb11)
            _add_block(J, j + 1, j, alpha * g2x * g1x - beta * hb00, alpha * g2x * g1y - beta * hb01,
                       alpha * g2y * g1x - beta * hb01, alpha * g2y * g1y - beta * hb11)
            _add_block(J, j + 1, j + 1, alpha * g2x * g2x + beta * hb00, alpha * g2x * g2y + beta * hb01,
                       alpha * g2y * g2x + beta * hb01, alpha * g2y * g2y + beta * hb11)
    if not water:
        return 0.0
    # drag (docs/model.md §4): F = -c_t l (v_t + v_t|v_t|) t - c_n l (v_n + v_n|v_n|) n, half per node
    ct = 0.25 * prm[P_RHO] * math.pi * prm[P_CF] * (prm[P_A] + prm[P_B])
    cn = prm[P_RHO] * prm[P_CD] * prm[P_A]
    power = 0.0
    for i in range(N - 1):
        l, tx, ty, nx, ny, vx, vy, vt, vn = edge_frame(q, v, i)
        gt = vt + vt * abs(vt)
        gn = vn + vn * abs(vn)
        fx = -ct * l * gt * tx - cn * l * gn * nx
        fy = -ct * l * gt * ty - cn * l * gn * ny
        power -= fx * vx + fy * vy
        F[2 * i] += 0.5 * fx
        F[2 * i + 1] += 0.5 * fy
        F[2 * i + 2] += 0.5 * fx
        F[2 * i + 3] += 0.5 * fy
        if jac:
            dgt = 1.0 + 2.0 * abs(vt)
            dgn = 1.0 + 2.0 * abs(vn)
            # d F_edge / d v_edge, a quarter of it on each of the four node blocks
            qv = 0.25 * cv
            c00 = -qv * l * (ct * dgt * tx * tx + cn * dgn * nx * nx)
            c01 = -qv * l * (ct * dgt * tx * ty + cn * dgn * nx * ny)
            c11 = -qv * l * (ct * dgt * ty * ty + cn * dgn * ny * ny)
            # d F_edge / d e (e = x[i+1] - x[i]), half of it per node, sign by node
            #   = -ct [gt t t^T + dgt vn t n^T + gt n n^T] - cn [gn n t^T - dgn vt n n^T - gn t n^T]
            hx = 0.5 * cx
            d00 = -hx * (ct * (gt * tx * tx + dgt * vn * tx * nx + gt * nx * nx)
                         + cn * (gn * nx * tx - dgn * vt * nx * nx - gn * tx * nx))
            d01 = -hx * (ct * (gt * tx * ty + dgt * vn * tx * ny + gt * nx * ny)
                         + cn * (gn * nx * ty - dgn * vt * nx * ny - gn * tx * ny))
            d10 = -hx * (ct * (gt * ty * tx + dgt * vn * ty * nx + gt * ny * nx)
                         + cn * (gn * ny * tx - dgn * vt * ny * nx - gn * ty * nx))
            d11 = -hx * (ct * (gt * ty * ty + dgt * vn * ty * ny + gt * ny * ny)
                         + cn * (gn * ny * ty - dgn * vt * ny * ny - gn * ty * ny))
            for a in (i, i + 1):
                _add_block(J, a, i, c00 - d00, c01 - d01, c01 - d10, c11 - d11)
                _add_block(J, a, i + 1, c00 + d00, c01 + d01, c01 + d10, c11 + d11)
    return power


@njit(cache=True, error_model="numpy")
def added_mass(q, prm, dv, out, J, coef, apply, jac):
    """Added mass of docs/model.md §4: ``M_A`` puts ``mu_n/4 n n^T`` on the four blocks of each
    edge, ``mu_n = rho pi C_A a^2 l``. If ``apply``, add ``M_A dv`` to ``out``; if ``jac``,
    add ``coef M_A`` to the band ``J``."""
    N = q.size // 2
    cm = prm[P_RHO] * math.pi * prm[P_CA] * prm[P_A] * prm[P_A]
    for i in range(N - 1):
        ex = q[2 * i + 2] - q[2 * i]
        ey = q[2 * i + 3] - q[2 * i + 1]
        l = math.sqrt(ex * ex + ey * ey)
        nx, ny = -ey / l, ex / l
        mu = 0.25 * cm * l
        if apply:
            an = mu * (nx * (dv[2 * i] + dv[2 * i + 2]) + ny * (dv[2 * i + 1] + dv[2 * i + 3]))
            out[2 * i] += an * nx
            out[2 * i + 1] += an * ny
            out[2 * i + 2] += an * nx
            out[2 * i + 3] += an * ny
        if jac:
            m00, m01, m11 = coef * mu * nx * nx, coef * mu * nx * ny, coef * mu * ny * ny
            for a in (i, i + 1):
                for b in (i, i + 1):
                    _add_block(J, a, b, m00, m01, m01, m11)


@njit(cache=True, error_model="numpy")
def solve_mass(q, prm, m, F, a, J, piv, water):
    """Accelerations ``a`` from ``(M + M_A(q)) a = F`` by a banded solve (``M_A = 0`` unless
    ``water``); ``m`` is the node mass per coordinate (2N,)."""
    n = q.size
    if not water:
        for i in range(n):
            a[i] = F[i] / m[i]
        return
    J[:, :] = 0.0
    for i in range(n):
        J[i, KL] = m[i]
        a[i] = F[i]
    added_mass(q, prm, a, a, J, 1.0, False, True)
    band_lu(J, piv, n)
    band_solve(J, piv, n, a)


@njit(cache=True, error_model="numpy")
def fluid_momentum(q, v, prm, R, sp, sg, J, dt, jac):
    """The water's kinetic energy ``T_f = sum_i 1/2 mu_n (v^i . n^i)^2`` (docs/model.md §4) and its
    derivatives: adds ``sp P_f + sg G`` to R (2N,), with the water's momentum
    ``P_f = dT_f/dv`` (half of each edge's ``mu_n v_n n`` to each node) [N s] and
    ``G = dT_f/dx`` [N]. If ``jac``, adds the Jacobian of ``P_f - dt G`` with respect to the
    end-of-step velocity (``x = x0 + dt v``) to the band J:
    ``dP_f/dv + dt (dP_f/dx - dG/dv) - dt^2 dG/dx`` (``M_A``, a skew gyroscopic part and a
    symmetric curvature part). Returns ``T_f`` [J].

    Per edge, with ``c = rho pi C_A a^2`` (``mu_n = c l``), ``e = x[i+1] - x[i]``:
    ``dT/de = c (vn^2/2 t - vn vt n)``, ``d(mu_n vn n)/de = c (-vt n n^T + vn (n t^T - t n^T))``,
    ``d2T/de2 = c/l (vt^2 - vn^2/2) n n^T``.
    """
    N = q.size // 2
    cm = prm[P_RHO] * math.pi * prm[P_CA] * prm[P_A] * prm[P_A]
    tf = 0.0
    for i in range(N - 1):
        l, tx, ty, nx, ny, vx, vy, vt, vn = edge_frame(q, v, i)
        tf += 0.5 * cm * l * vn * vn
        pn = 0.5 * sp * cm * l * vn  # half the edge's momentum to each node
        gt = sg * cm * 0.5 * vn * vn
        gn = -sg * cm * vn * vt
        gx, gy = gt * tx + gn * nx, gt * ty + gn * ny
        R[2 * i] += pn * nx - gx
        R[2 * i + 1] += pn * ny - gy
        R[2 * i + 2] += pn * nx + gx
        R[2 * i + 3] += pn * ny + gy
        if jac:
            a = 0.25 * cm * l
            # D = d(edge momentum)/de; block (a, b) gets A + dt/2 (s_b D - s_a D^T) - dt^2 s_a s_b H
            d00 = cm * (-vt * nx * nx + vn * (nx * tx - tx * nx))
            d01 = cm * (-vt * nx * ny + vn * (nx * ty - tx * ny))
            d10 = cm * (-vt * ny * nx + vn * (ny * tx - ty * nx))
            d11 = cm * (-vt * ny * ny + vn * (ny * ty - ty * ny))
            hc = dt * dt * cm / l * (vt * vt - 0.5 * vn * vn)
            hd = 0.5 * dt
            for ia in range(2):
                sa = 2.0 * ia - 1.0
                for ib in range(2):
                    sb = 2.0 * ib - 1.0
                    h = hc * sa * sb
                    _add_block(
                        J, i + ia, i + ib,
                        a * nx * nx + hd * (sb * d00 - sa * d00) - h * nx * nx,
                        a * nx * ny + hd * (sb * d01 - sa * d10) - h * nx * ny,
                        a * ny * nx + hd * (sb * d10 - sa * d01) - h * ny * nx,
                        a * ny * ny + hd * (sb * d11 - sa * d11) - h * ny * ny,
                    )
    return tf


@njit(cache=True, error_model="numpy")
def munk_force(q, v, prm, F):
    """Adds the velocity part of the consistent added-mass force, ``dT_f/dx - (dP_f/dx) v``
    (the turning normal's terms, the Munk moment), to F (2N,) [N]. With it,
    ``(M + M_A) a = F_other + munk`` is the Lagrangian equation of ``T_f`` (docs/model.md §4)."""
    N = q.size // 2
    cm = prm[P_RHO] * math.pi * prm[P_CA] * prm[P_A] * prm[P_A]
    for i in range(N - 1):
        l, tx, ty, nx, ny, vx, vy, vt, vn = edge_frame(q, v, i)
        dx = v[2 * i + 2] - v[2 * i]
        dy = v[2 * i + 3] - v[2 * i + 1]
        et = dx * tx + dy * ty
        en = dx * nx + dy * ny
        gt = 0.5 * cm * vn * vn
        gn = -cm * vn * vt
        # half of D (v[i+1] - v[i]) on each node, D = c (-vt n n^T + vn (n t^T - t n^T))
        ct = -0.5 * cm * (-vn * en)
        cn = -0.5 * cm * (-vt * en + vn * et)
        F[2 * i] += -gt * tx - gn * nx + ct * tx + cn * nx
        F[2 * i + 1] += -gt * ty - gn * ny + ct * ty + cn * ny
        F[2 * i + 2] += gt * tx + gn * nx + ct * tx + cn * nx
        F[2 * i + 3] += gt * ty + gn * ny + ct * ty + cn * ny


@njit(cache=True, error_model="numpy")
def fluid_kinetic_energy(q, v, prm):
    """``T_f = sum_i 1/2 mu_n (v^i . n^i)^2``, the water's kinetic energy (docs/model.md §4) [J]."""
    N = q.size // 2
    cm = prm[P_RHO] * math.pi * prm[P_CA] * prm[P_A] * prm[P_A]
    tf = 0.0
    for i in range(N - 1):
        ex = q[2 * i + 2] - q[2 * i]
        ey = q[2 * i + 3] - q[2 * i + 1]
        vx = 0.5 * (v[2 * i] + v[2 * i + 2])
        vy = 0.5 * (v[2 * i + 1] + v[2 * i + 3])
        w = vy * ex - vx * ey  # l v_n
        tf += 0.5 * cm * w * w / math.sqrt(ex * ex + ey * ey)
    return tf


@njit(cache=True, error_model="numpy")
def damping_power(q, v, prm):
    """Power lost to material damping, ``damping_bend sum kappa_dot^2 + damping_stretch sum
    ldot^2`` (docs/model.md §3) [W]."""
    N = q.size // 2
    db, ds = prm[P_DBEND], prm[P_DSTRETCH]
    p = 0.0
    if ds > 0.0:
        for k in range(N - 1):
            ex = q[2 * k + 2] - q[2 * k]
            ey = q[2 * k + 3] - q[2 * k + 1]
            ld = (ex * (v[2 * k + 2] - v[2 * k]) + ey * (v[2 * k + 3] - v[2 * k + 1])) / math.sqrt(
                ex * ex + ey * ey
            )
            p += ds * ld * ld
    if db > 0.0:
        for j in range(1, N - 1):
            k, g0x, g0y, g1x, g1y, g2x, g2y = turning(q, j)[:7]
            kd = (1.0 + 0.25 * k * k) * (g0x * v[2 * j - 2] + g0y * v[2 * j - 1] + g1x * v[2 * j]
                                         + g1y * v[2 * j + 1] + g2x * v[2 * j + 2] + g2y * v[2 * j + 3])
            p += db * kd * kd
    return p


@njit(cache=True, error_model="numpy")
def actuator_power(q, kbar, lbar, u_k, u_l, prm):
    """Power the inputs put into the body, ``dE/dkbar . u_k + dE/dlbar . u_l`` (docs/model.md §3) [W]."""
    N = q.size // 2
    EA, EI = prm[P_EA], prm[P_EI]
    p = 0.0
    for j in range(1, N - 1):
        lv = 0.5 * (lbar[j - 1] + lbar[j])
        dk = turning(q, j)[0] - kbar[j - 1]
        p -= EI / lv * dk * u_k[j - 1]
        p -= 0.25 * EI * dk * dk / (lv * lv) * (u_l[j - 1] + u_l[j])
    for k in range(N - 1):
        r = math.hypot(q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1]) / lbar[k]
        p -= 0.5 * EA * (r * r - 1.0) * u_l[k]
    return p


@njit(cache=True, error_model="numpy")
def _segments_cross(q, a, b):
    """True if edges a and b cross properly (a shared end or a mere touch does not count)."""
    p1x, p1y, p2x, p2y = q[2 * a], q[2 * a + 1], q[2 * a + 2], q[2 * a + 3]
    p3x, p3y, p4x, p4y = q[2 * b], q[2 * b + 1], q[2 * b + 2], q[2 * b + 3]
    d1 = (p2x - p1x) * (p3y - p1y) - (p2y - p1y) * (p3x - p1x)
    d2 = (p2x - p1x) * (p4y - p1y) - (p2y - p1y) * (p4x - p1x)
    d3 = (p4x - p3x) * (p1y - p3y) - (p4y - p3y) * (p1x - p3x)
    d4 = (p4x - p3x) * (p2y - p3y) - (p4y - p3y) * (p2x - p3x)
    return d1 * d2 < 0.0 and d3 * d4 < 0.0


@njit(cache=True, error_model="numpy")
def self_intersects(q, keys, order):
    """Sweep and prune over the edges' x-extents; ``order`` (N-1,) persists between calls, so
    the insertion sort is nearly linear for a body that moves a little each step."""
    ne = q.size // 2 - 1
    for e in range(ne):
        keys[e] = min(q[2 * e], q[2 * e + 2])
    for i in range(1, ne):
        o = order[i]
        kv = keys[o]
        j = i - 1
        while j >= 0 and keys[order[j]] > kv:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = o
    for ii in range(ne):
        a = order[ii]
        xmax = max(q[2 * a], q[2 * a + 2])
        for jj in range(ii + 1, ne):
            b = order[jj]
            if keys[b] > xmax:
                break
            if abs(a - b) >= 2 and _segments_cross(q, a, b):
                return True
    return False


@njit(cache=True, error_model="numpy")
def check_state(q, v, lbar, prm, buf, ibuf):
    """Status code of a state: non-finite, runaway stretch, or self-intersection."""
    n = q.size
    for i in range(n):
        if not (math.isfinite(q[i]) and math.isfinite(v[i])):
            return NON_FINITE
    max_strain = prm[P_MAXSTRAIN]
    for k in range(n // 2 - 1):
        l = math.hypot(q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1])
        if abs(l / lbar[k] - 1.0) > max_strain:
            return RUNAWAY_STRETCH
    if prm[P_CHECKSI] != 0.0 and self_intersects(q, buf[B_KEYS], ibuf[I_ORDER]):
        return SELF_INTERSECTION
    return OK


@njit(cache=True, error_model="numpy")
def node_tangent(q, i):
    """Unit tangent of the body at node i: along the sum of its edges' unit tangents."""
    N = q.size // 2
    tx, ty = 0.0, 0.0
    for k in (i - 1, i):
        if 0 <= k < N - 1:
            ex, ey = q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1]
            l = math.sqrt(ex * ex + ey * ey)
            tx += ex / l
            ty += ey / l
    l = math.sqrt(tx * tx + ty * ty)
    return tx / l, ty / l


@njit(cache=True, error_model="numpy")
def kinetic_friction(q, v, i, fn, eps2, prm):
    """Kinetic friction on sliding node i with normal load ``fn`` [N] (docs/model.md §5) and its
    derivative by the node's velocity (the tangent's dependence on q is left out).

    Isotropic: ``-mu_d fn v / s``, ``s = sqrt(|v|^2 + eps2)`` (a smoothing far below the
    sticking speed). Anisotropic: ``-fn (mu_t v_t t + mu_lateral v_n n) / s``, with ``mu_t`` the
    forward or backward coefficient by the sign of ``v_t``.

    Returns:
        (fx, fy, d fx/d vx, d fx/d vy, d fy/d vx, d fy/d vy).
    """
    vx, vy = v[2 * i], v[2 * i + 1]
    s = math.sqrt(vx * vx + vy * vy + eps2)
    if prm[P_ANISO] == 0.0:
        c = prm[P_MUD] * fn
        s3 = s * s * s
        return (-c * vx / s, -c * vy / s, -c * (1.0 / s - vx * vx / s3), c * vx * vy / s3,
                c * vx * vy / s3, -c * (1.0 / s - vy * vy / s3))
    tx, ty = node_tangent(q, i)
    nx, ny = -ty, tx
    vt = vx * tx + vy * ty
    vn = vx * nx + vy * ny
    mt = prm[P_MU_FWD] if vt > 0.0 else prm[P_MU_BWD]
    mn = prm[P_MU_LAT]
    gx = fn * (mt * vt * tx + mn * vn * nx)  # the friction force is -g / s
    gy = fn * (mt * vt * ty + mn * vn * ny)
    s3 = s * s * s
    # d(-g/s)/dv = -(fn (mt t t^T + mn n n^T)) / s + g v^T / s^3
    a00 = fn * (mt * tx * tx + mn * nx * nx)
    a01 = fn * (mt * tx * ty + mn * nx * ny)
    a11 = fn * (mt * ty * ty + mn * ny * ny)
    return (-gx / s, -gy / s, -a00 / s + gx * vx / s3, -a01 / s + gx * vy / s3,
            -a01 / s + gy * vx / s3, -a11 / s + gy * vy / s3)


@njit(cache=True, error_model="numpy")
def _be_residual(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium, jac):
    """Residual of backward Euler at the trial velocity ``v`` (also writes ``q = q0 + dt v``),
    and if ``jac`` its Jacobian into J. In water with the consistent added mass (docs/model.md §4)
    in momentum form, ``R = M (v - v0) + P_f(q, v) - P_f(q0, v0) - dt (F(q, v) + dT_f/dx(q, v))``
    (``P_f(q0, v0)`` in ``buf[B_P0]``); with ``added_mass = "kelasidi"``,
    ``R = (M + M_A(q)) (v - v0) - dt F(q, v)``. Returns
    (squared 2-norm, max-norm of R/m [m/s], fluid power, friction power)."""
    n = q.size
    q0, v0, F, R, m = buf[B_Q0], buf[B_V0], buf[B_F], buf[B_R], buf[B_M]
    fext = buf[B_FEXT]
    dv = buf[B_A]
    for i in range(n):
        q[i] = q0[i] + dt * v[i]
        F[i] = fext[i]
        dv[i] = v[i] - v0[i]
    if jac:
        J[:, :] = 0.0
    water = medium == MEDIUM_WATER
    p_fluid = assemble(q, v, kbar, lbar, prm, F, J, -dt * dt, -dt, jac, water)
    for i in range(n):
        R[i] = m[i] * dv[i] - dt * F[i]
    if jac:
        for i in range(n):
            J[i, KL] += m[i]
    if water:
        if int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
            fluid_momentum(q, v, prm, R, 1.0, -dt, J, dt, jac)
            p0 = buf[B_P0]
            for i in range(n):
                R[i] -= p0[i]
        else:
            added_mass(q, prm, dv, R, J, 1.0, True, jac)
    p_fric = 0.0
    if medium == MEDIUM_GROUND:
        state = ibuf[I_FRICTION]
        eps2 = (0.1 * prm[P_VTOL]) ** 2  # nodes slower than V_tol stick, so this only smooths
        for i in range(n // 2):
            r0, r1 = 2 * i, 2 * i + 1
            if state[i] == STUCK:
                R[r0] = v[r0]
                R[r1] = v[r1]
                if jac:
                    J[r0, :] = 0.0
                    J[r1, :] = 0.0
                    J[r0, KL] = 1.0
                    J[r1, KL] = 1.0
            else:
                fx, fy, d00, d01, d10, d11 = kinetic_friction(q, v, i, m[r0] * prm[P_G], eps2, prm)
                R[r0] -= dt * fx
                R[r1] -= dt * fy
                p_fric -= fx * v[r0] + fy * v[r1]
                if jac:
                    _add_block(J, i, i, -dt * d00, -dt * d01, -dt * d10, -dt * d11)
    norm2 = 0.0
    rmax = 0.0
    for i in range(n):
        norm2 += R[i] * R[i]
        rmax = max(rmax, abs(R[i]) / m[i])  # as a velocity: mass-independent tolerance
    return norm2, rmax, p_fluid, p_fric


@njit(cache=True, error_model="numpy")
def _update_contacts(v, buf, ibuf, prm, dt, n):
    """Make stick-slip consistent with the end of a converged step (docs/model.md §5); True if a
    node changed and the step must be solved again.

    Sliding nodes that end slower than ``V_tol`` stick. Otherwise every stuck node whose
    holding force ``f = -m v0/dt - F`` (``F``: every other force, at the end of the step)
    exceeds ``mu_s F_N`` is released to slide, with a first guess along its push (releasing
    them one at a time, worst first, gave the same gaits to 1e-4 in more passes). A node
    released too eagerly ends slow and sticks again in the next pass. Each node changes at
    most ``MAX_SWITCHES`` times per step, so the passes end.
    """
    F, m, v0 = buf[B_F], buf[B_M], buf[B_V0]
    state, switches = ibuf[I_FRICTION], ibuf[I_SWITCHES]
    stuck_any = False
    for i in range(n // 2):
        if (state[i] == SLIDING and switches[i] < MAX_SWITCHES
                and math.hypot(v[2 * i], v[2 * i + 1]) < prm[P_VTOL]):
            state[i] = STUCK
            switches[i] += 1
            v[2 * i] = 0.0
            v[2 * i + 1] = 0.0
            stuck_any = True
    if stuck_any:
        return True
    released = False
    for i in range(n // 2):
        if state[i] != STUCK or switches[i] >= MAX_SWITCHES:
            continue
        fx = -m[2 * i] * v0[2 * i] / dt - F[2 * i]
        fy = -m[2 * i] * v0[2 * i + 1] / dt - F[2 * i + 1]
        f = math.hypot(fx, fy)
        if f <= prm[P_MUS] * m[2 * i] * prm[P_G]:
            continue
        state[i] = SLIDING
        switches[i] += 1
        released = True
        # first guess: just above the sticking speed, along the push (Newton finds the rest)
        v[2 * i] = -2.0 * prm[P_VTOL] * fx / f
        v[2 * i + 1] = -2.0 * prm[P_VTOL] * fy / f
    return released


@njit(cache=True, error_model="numpy")
def _be_substep(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium):
    """One backward-Euler step by damped Newton on the banded analytic Jacobian (docs/model.md §5a).
    Returns (status, iterations, residual, fluid power, friction power)."""
    n = q.size
    q0, v0, vacc, dv = buf[B_Q0], buf[B_V0], buf[B_VACC], buf[B_DV]
    R = buf[B_R]
    piv = ibuf[I_PIV]
    tol = prm[P_TOL]
    maxit = int(prm[P_MAXIT])
    if medium == MEDIUM_GROUND:
        # first guess of the contacts from the start of the step: slow nodes stick, the rest
        # slide; _update_contacts then makes them consistent with the end of the step
        state, switches = ibuf[I_FRICTION], ibuf[I_SWITCHES]
        for i in range(n):
            q0[i] = q[i]
            v0[i] = v[i]
        for i in range(n // 2):
            switches[i] = 0
            if math.hypot(v[2 * i], v[2 * i + 1]) < prm[P_VTOL]:
                state[i] = STUCK
                v[2 * i] = 0.0
                v[2 * i + 1] = 0.0
            else:
                state[i] = SLIDING
    else:
        # predictor: extrapolate the velocity from the last step (v0 still holds its start;
        # set_state makes it the current velocity, so a fresh state starts with v)
        for i in range(n):
            q0[i] = q[i]
            v_prev = v0[i]
            v0[i] = v[i]
            v[i] = 2.0 * v[i] - v_prev
        if medium == MEDIUM_WATER and int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
            p0 = buf[B_P0]
            p0[:] = 0.0
            fluid_momentum(q0, v0, prm, p0, 1.0, 0.0, J, 0.0, False)
    norm2, rmax, p_fluid, p_fric = _be_residual(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium, True)
    it = 0
    pass_it = 0
    while True:
        if rmax <= tol:
            # stick-slip decided by the end of the step (docs/model.md §5): if a contact changes,
            # the step is solved again from the current iterate
            if medium != MEDIUM_GROUND or not _update_contacts(v, buf, ibuf, prm, dt, n):
                break
            norm2, rmax, p_fluid, p_fric = _be_residual(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium, True)
            pass_it = 0  # the iteration cap holds per contact pass
            continue
        if pass_it == maxit or not math.isfinite(norm2):
            return NOT_CONVERGED, it, rmax, p_fluid, p_fric
        it += 1
        pass_it += 1
        for i in range(n):
            vacc[i] = v[i]
            dv[i] = -R[i]
        if not band_lu(J, piv, n):
            return NOT_CONVERGED, it, rmax, p_fluid, p_fric
        band_solve(J, piv, n, dv)
        # backtracking line search on |R|^2. In water most steps converge after one Newton
        # iteration, so trials skip the Jacobian; on the ground a pass takes several, so the
        # full step's trial assembles it too and, accepted, serves the next iteration
        fused = medium == MEDIUM_GROUND
        step = 1.0
        for _ in range(12):
            for i in range(n):
                v[i] = vacc[i] + step * dv[i]
            trial = _be_residual(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium, fused and step == 1.0)
            if trial[0] < norm2 * (1.0 - 1e-4 * step):
                break
            step *= 0.5
        norm2, rmax, p_fluid, p_fric = trial
        if rmax > tol and pass_it < maxit and math.isfinite(norm2) and not (fused and step == 1.0):
            # another iteration follows: the Jacobian at the accepted velocity (the residual
            # is recomputed bit for bit)
            _be_residual(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium, True)
    return OK, it, rmax, p_fluid, p_fric


@njit(cache=True, error_model="numpy")
def _symplectic_substep(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium):
    """One explicit semi-implicit (symplectic) Euler step: kick with F(q, v), then drift.
    In water ``(M + M_A(q)) a = F``, plus with the consistent added mass the velocity terms of
    :func:`munk_force`. On the ground, friction is decided by the end of the kick (docs/model.md
    §5): a node whose frictionless end velocity ``w`` could be stopped within ``mu_s F_N``
    sticks, any other slides with ``mu_d F_N`` against ``w`` (the lumped mass matrix is
    diagonal on the ground, so each node is decided on its own).
    Returns (fluid power, friction power)."""
    n = q.size
    F, a, m, fext = buf[B_F], buf[B_A], buf[B_M], buf[B_FEXT]
    for i in range(n):
        F[i] = fext[i]
    p_fluid = assemble(q, v, kbar, lbar, prm, F, J, 0.0, 0.0, False, medium == MEDIUM_WATER)
    if medium == MEDIUM_WATER and int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
        munk_force(q, v, prm, F)
    solve_mass(q, prm, m, F, a, J, ibuf[I_PIV], medium == MEDIUM_WATER)
    p_fric = 0.0
    for i in range(n):
        v[i] += dt * a[i]
    if medium == MEDIUM_GROUND:
        state = ibuf[I_FRICTION]
        stop = dt * prm[P_G]  # the speed a friction coefficient of 1 removes in dt
        for i in range(n // 2):
            r0, r1 = 2 * i, 2 * i + 1
            w = math.hypot(v[r0], v[r1])
            if w <= prm[P_MUS] * stop:
                state[i] = STUCK
                v[r0] = 0.0
                v[r1] = 0.0
            else:
                # kinetic friction along the frictionless end velocity, explicit (a sub-step
                # is far shorter than the time friction needs to stop the node)
                state[i] = SLIDING
                fx, fy = kinetic_friction(q, v, i, m[r0] * prm[P_G], 0.0, prm)[:2]
                v[r0] += dt * fx / m[r0]
                v[r1] += dt * fy / m[r0]
                p_fric -= fx * v[r0] + fy * v[r1]
    for i in range(n):
        q[i] += dt * v[i]
    return p_fluid, p_fric


@njit(cache=True, error_model="numpy")
def ledger_energies(q, v, kbar, lbar, prm, buf, out):
    """Write the body's kinetic and elastic energy and the water's ``T_f`` (0 out of water)
    into ``out[O_E_KIN]``, ``out[O_E_ELASTIC]``, ``out[O_T_FLUID]`` [J], and the energy ledger
    since the start recorded at ``O_L0_*`` into ``out[O_LEDGER:]`` (``LEDGER_KEYS``)."""
    m = buf[B_M]
    ke = 0.0
    for i in range(q.size):
        ke += 0.5 * m[i] * v[i] * v[i]
    out[O_E_KIN] = ke
    out[O_E_ELASTIC] = elastic_energy(q, kbar, lbar, prm)
    out[O_T_FLUID] = fluid_kinetic_energy(q, v, prm) if int(prm[P_MEDIUM]) == MEDIUM_WATER else 0.0
    # the ledger since O_L0_*: actuator work = dissipation + energy changes + error
    work = out[O_W_ACT] - out[O_L0_W_ACT]
    error = work
    for k, (now, start) in enumerate(((O_E_FLUID, O_L0_E_FLUID), (O_E_DAMP, O_L0_E_DAMP),
                                      (O_E_FRICTION, O_L0_E_FRICTION), (O_E_KIN, O_L0_KIN),
                                      (O_E_ELASTIC, O_L0_ELASTIC), (O_T_FLUID, O_L0_T_FLUID))):
        term = out[now] - out[start]
        out[O_LEDGER + 1 + k] = term
        error -= term
    out[O_LEDGER] = work
    out[O_LEDGER + 7] = error


@njit(cache=True, error_model="numpy")
def simulate(q, v, kbar, lbar, u_k, u_l, prm, buf, J, ibuf, out, n_steps):
    """Advance one robot by ``n_steps`` steps of ``h`` with inputs held constant; stops at the
    first failure. Per step: rest shape moves by ``dt u`` each sub-step, the state follows by
    the chosen integrator, then the state is checked. Writes diagnostics into ``out`` (the
    energies of :func:`ledger_energies` once, at the end) and returns the status code
    (``OK`` = 0)."""
    h = prm[P_H]
    nsub = int(prm[P_SUBSTEPS])
    dt = h / nsub
    medium = int(prm[P_MEDIUM])
    symplectic = int(prm[P_METHOD]) == METHOD_SYMPLECTIC_EULER
    damped = prm[P_DBEND] > 0.0 or prm[P_DSTRETCH] > 0.0
    status = OK
    for _ in range(n_steps):
        e_fluid = 0.0
        e_fric = 0.0
        e_act = 0.0
        e_damp = 0.0
        niter = 0
        resid = 0.0
        for _s in range(nsub):
            # the inputs' work over the sub-step by the trapezoidal rule on P_act: exact for a
            # body that lags the rest shape and for one that follows it at once, where a
            # one-point rule charges inputs that reverse every step with work never done
            p_act0 = actuator_power(q, kbar, lbar, u_k, u_l, prm)
            for j in range(kbar.size):
                kbar[j] += dt * u_k[j]
            for k in range(lbar.size):
                lbar[k] += dt * u_l[k]
                if not lbar[k] > 0.0:
                    status = BAD_REST_LENGTH
            if status != OK:
                break
            # each power where the step evaluates its forces: start (explicit) or end (implicit)
            p_damp = 0.0
            if symplectic:
                p_act1 = actuator_power(q, kbar, lbar, u_k, u_l, prm)
                if damped:
                    p_damp = damping_power(q, v, prm)
                p_fluid, p_fric = _symplectic_substep(q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium)
            else:
                status, it, res, p_fluid, p_fric = _be_substep(
                    q, v, kbar, lbar, prm, buf, J, ibuf, dt, medium
                )
                niter = max(niter, it)
                resid = max(resid, res)
                p_act1 = actuator_power(q, kbar, lbar, u_k, u_l, prm)
                if damped:
                    p_damp = damping_power(q, v, prm)
            e_fluid += dt * p_fluid
            e_damp += dt * p_damp
            e_fric += dt * p_fric
            e_act += 0.5 * dt * (p_act0 + p_act1)
            if status != OK:
                break
        if status == OK or status == NOT_CONVERGED:
            check = check_state(q, v, lbar, prm, buf, ibuf)
            if check != OK:
                status = check
        out[O_STATUS] = status
        out[O_NITER] = niter
        out[O_RESIDUAL] = resid
        out[O_P_FLUID] = e_fluid / h
        out[O_P_FRICTION] = e_fric / h
        out[O_P_ACT] = e_act / h
        out[O_E_FLUID] += e_fluid
        out[O_E_FRICTION] += e_fric
        out[O_E_ACT] += abs(e_act)
        out[O_W_ACT] += e_act
        out[O_P_DAMP] = e_damp / h
        out[O_E_DAMP] += e_damp
        out[O_NSTEPS] += 1
        if status != OK:
            break
    ledger_energies(q, v, kbar, lbar, prm, buf, out)
    return status
