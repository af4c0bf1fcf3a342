"""Forces on the discrete rod and their Jacobians (docs/model.md §3-§5).

Elastic and damping forces, drag and added mass of the water, kinetic friction on the ground, and
the powers and energies they give. Kernels on flat interleaved ``q``, ``v`` (2N,) and the parameter
vector ``prm`` (``P_*``); forces are added into their outputs, Jacobians into a band
(:mod:`~soft_snake_gym.physics.banded`).
"""

from __future__ import annotations

import math

from numba import njit

from soft_snake_gym.physics import banded, geometry, layout
from soft_snake_gym.physics.banded import (
    KL,
    PIVOT_THRESHOLD,
    add_block,
    add_edge_pattern,
    band_factor,
    band_solve,
)
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.geometry import (
    edge_frame,
    edge_frame_at,
    edge_geometry,
    node_tangent,
    turning_at,
    turning_rate,
)
from soft_snake_gym.physics.layout import (
    P_A,
    P_ANISO,
    P_B,
    P_CA,
    P_CD,
    P_CF,
    P_DBEND,
    P_DSTRETCH,
    P_EA,
    P_EI,
    P_MU_BWD,
    P_MU_FWD,
    P_MU_LAT,
    P_MUD,
    P_RHO,
)

# the cached kernels embed the code of the kernels and constants they use from these files
drop_stale_cache(__file__, [banded.__file__, geometry.__file__, layout.__file__])


@njit(cache=True, inline="always", error_model="numpy")
def added_mass_coefficient(prm):
    """``rho pi C_A a^2``, the added mass per length of the body across itself (docs/model.md §4).

    An edge of length ``l`` entrains ``mu_n = rho pi C_A a^2 l`` [kg/m].
    """
    return prm[P_RHO] * math.pi * prm[P_CA] * prm[P_A] * prm[P_A]


@njit(cache=True, error_model="numpy", _nrt=False)
def elastic_energy(geo, kbar, lbar, prm):
    """Stretching plus bending energy ``E_s + E_b`` (docs/model.md §3) [J].

    ``geo`` is the edge geometry of the positions (:func:`~soft_snake_gym.physics.geometry.
    edge_geometry`); bit for bit the energy computed from them.
    """
    N = lbar.size + 1
    EA, EI = prm[P_EA], prm[P_EI]
    e = 0.0
    for k in range(N - 1):
        s = geo[0, 2 * k] / lbar[k] - 1.0
        e += 0.5 * EA * s * s * lbar[k]
    for j in range(1, N - 1):
        dk = turning_at(geo, j)[0] - kbar[j - 1]
        e += 0.5 * EI / (0.5 * (lbar[j - 1] + lbar[j])) * dk * dk
    return e


@njit(cache=True, inline="always", error_model="numpy")
def drag_jacobian(ct, cn, l, tx, ty, nx, ny, vt, vn, gt, gn, cx, cv):
    """One edge's drag Jacobian ``cx dF/dq + cv dF/dv`` as :func:`assemble` adds it, in parts.

    Returns (c00, c01, c11): a quarter of ``cv`` d F_edge / d v_edge for each of the four node
    blocks; (d00, d01, d10, d11): half of ``cx`` d F_edge / d e per node, signed by node.
    """
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
    d00 = -hx * _drag_entry(ct, cn, gt, gn, dgt, dgn, vt, vn, tx, nx, tx, nx)
    d01 = -hx * _drag_entry(ct, cn, gt, gn, dgt, dgn, vt, vn, tx, nx, ty, ny)
    d10 = -hx * _drag_entry(ct, cn, gt, gn, dgt, dgn, vt, vn, ty, ny, tx, nx)
    d11 = -hx * _drag_entry(ct, cn, gt, gn, dgt, dgn, vt, vn, ty, ny, ty, ny)
    return c00, c01, c11, d00, d01, d10, d11


@njit(cache=True, inline="always", error_model="numpy")
def _drag_entry(ct, cn, gt, gn, dgt, dgn, vt, vn, ta, na, tb, nb):
    """Entry (a, b) of :func:`drag_jacobian`'s bracket, from the a-th and b-th components of ``t`` and ``n``."""
    return ct * (gt * ta * tb + dgt * vn * ta * nb + gt * na * nb) + cn * (
        gn * na * tb - dgn * vt * na * nb - gn * ta * nb
    )


@njit(cache=True, inline="always", error_model="numpy")
def bending_blocks(be, g, u, ha, hb):
    """A joint's nine 2x2 blocks of :func:`assemble`'s band: ``g_a u_b^T`` plus ``be`` times the edge-angle Hessians.

    Block ``k`` couples node ``j - 1 + k // 3`` (rows) with node ``j - 1 + k % 3`` (columns), as
    (m00, m01, m10, m11). The Hessians' pattern over nodes (j-1, j, j+1): (0,0) -Ha, (0,1) and
    (1,0) Ha, (1,1) Hb - Ha, (1,2) and (2,1) -Hb, (2,2) Hb. The lanes add the same blocks in
    the same order (``lanes._residual``).
    """
    g0x, g0y, g1x, g1y, g2x, g2y = g
    u0x, u0y, u1x, u1y, u2x, u2y = u
    ha00, ha01, ha11 = ha
    hb00, hb01, hb11 = hb
    return (
        (g0x * u0x - be * ha00, g0x * u0y - be * ha01, g0y * u0x - be * ha01, g0y * u0y - be * ha11),
        (g0x * u1x + be * ha00, g0x * u1y + be * ha01, g0y * u1x + be * ha01, g0y * u1y + be * ha11),
        (g0x * u2x, g0x * u2y, g0y * u2x, g0y * u2y),
        (g1x * u0x + be * ha00, g1x * u0y + be * ha01, g1y * u0x + be * ha01, g1y * u0y + be * ha11),
        (
            g1x * u1x + be * (hb00 - ha00),
            g1x * u1y + be * (hb01 - ha01),
            g1y * u1x + be * (hb01 - ha01),
            g1y * u1y + be * (hb11 - ha11),
        ),
        (g1x * u2x - be * hb00, g1x * u2y - be * hb01, g1y * u2x - be * hb01, g1y * u2y - be * hb11),
        (g2x * u0x, g2x * u0y, g2y * u0x, g2y * u0y),
        (g2x * u1x - be * hb00, g2x * u1y - be * hb01, g2y * u1x - be * hb01, g2y * u1y - be * hb11),
        (g2x * u2x + be * hb00, g2x * u2y + be * hb01, g2y * u2x + be * hb01, g2y * u2y + be * hb11),
    )


@njit(cache=True, error_model="numpy", _nrt=False)
def assemble(q, v, kbar, lbar, prm, F, J, cx, cv, jac, water, geo):
    """Add internal (elastic, damping) and, if ``water``, drag forces into F (2N,) [N].

    If ``jac``, also add ``cx dF/dq + cv dF/dv`` into the band ``J`` (exact, damping's
    position dependence included: without it Newton needs a second iteration every step).
    Writes the edges' lengths and tangents of ``q`` into ``geo`` (:func:`~soft_snake_gym.physics.
    geometry.edge_geometry`, (2, 2N)) and computes every force from them, so each edge's square
    root and divisions are done once, not four times. Returns the power lost to drag
    ``-sum F_D . v_edge`` [W].
    """
    edge_geometry(q, geo)
    return assemble_at(q, v, kbar, lbar, prm, F, J, cx, cv, jac, water, geo)


@njit(cache=True, inline="always", error_model="numpy")
def assemble_at(q, v, kbar, lbar, prm, F, J, cx, cv, jac, water, geo):
    """:func:`assemble` where ``geo`` already holds the edge geometry of ``q``."""
    N = q.size // 2
    EA, EI, d, db = prm[P_EA], prm[P_EI], prm[P_DSTRETCH], prm[P_DBEND]
    # stretching (docs/model.md §3): force on x[k+1] is -EA (|e|/lbar - 1) t
    for k in range(N - 1):
        l, tx, ty = geo[0, 2 * k], geo[1, 2 * k], geo[1, 2 * k + 1]
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
            il = geo[0, 2 * k + 1]  # 1/l
            a1 = EA / lb
            a2 = -f * il
            s00 = cx * (a1 * tx * tx + a2 * (1.0 - tx * tx)) + cv * d * tx * tx
            s01 = cx * (a1 - a2) * tx * ty + cv * d * tx * ty
            s11 = cx * (a1 * ty * ty + a2 * (1.0 - ty * ty)) + cv * d * ty * ty
            add_edge_pattern(J, k, s00, s01, s11)
            if d > 0.0:
                px, py = cx * d * (dvx - ldot * tx) * il, cx * d * (dvy - ldot * ty) * il
                t00, t01, t10, t11 = tx * px, tx * py, ty * px, ty * py
                add_block(J, k, k, -t00, -t01, -t10, -t11)
                add_block(J, k, k + 1, t00, t01, t10, t11)
                add_block(J, k + 1, k, t00, t01, t10, t11)
                add_block(J, k + 1, k + 1, -t00, -t01, -t10, -t11)
    # bending (docs/model.md §3): F = -(EI/lvor)(kappa - kbar)(1 + kappa^2/4) d phi/d x
    for j in range(1, N - 1):
        kap, g0x, g0y, g1x, g1y, g2x, g2y, tax, tay, tbx, tby, ila, ilb = turning_at(geo, j)
        kb = EI / (0.5 * (lbar[j - 1] + lbar[j]))
        dk = kap - kbar[j - 1]
        w = 1.0 + 0.25 * kap * kap
        s = kb * dk * w  # dE/dphi
        phidot = 0.0
        if db > 0.0:
            phidot = turning_rate(g0x, g0y, g1x, g1y, g2x, g2y, v, j)
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
            ia = ila * ila
            ib = ilb * ilb
            ha00, ha01, ha11 = 2.0 * tax * tay * ia, (tay * tay - tax * tax) * ia, -2.0 * tax * tay * ia
            hb00, hb01, hb11 = 2.0 * tbx * tby * ib, (tby * tby - tbx * tbx) * ib, -2.0 * tbx * tby * ib
            # block (a, b) is g_a u_b^T + beta (the Hessians' pattern), u_b = alpha g_b + c r_b
            u0x, u0y, u1x, u1y = alpha * g0x, alpha * g0y, alpha * g1x, alpha * g1y
            u2x, u2y = alpha * g2x, alpha * g2y
            if db > 0.0:
                # r_{j-1} = Ha (v_j - v_{j-1}), r_{j+1} = Hb (v_{j+1} - v_j), r_j = -(the two)
                ux, uy = v[2 * j] - v[2 * j - 2], v[2 * j + 1] - v[2 * j - 1]
                wx, wy = v[2 * j + 2] - v[2 * j], v[2 * j + 3] - v[2 * j + 1]
                r0x, r0y = ha00 * ux + ha01 * uy, ha01 * ux + ha11 * uy
                r2x, r2y = hb00 * wx + hb01 * wy, hb01 * wx + hb11 * wy
                r1x, r1y = -r0x - r2x, -r0y - r2y
                c = -cx * db * w * w
                u0x, u0y = u0x + c * r0x, u0y + c * r0y
                u1x, u1y = u1x + c * r1x, u1y + c * r1y
                u2x, u2y = u2x + c * r2x, u2y + c * r2y
            g, u = (g0x, g0y, g1x, g1y, g2x, g2y), (u0x, u0y, u1x, u1y, u2x, u2y)
            blocks = bending_blocks(beta, g, u, (ha00, ha01, ha11), (hb00, hb01, hb11))
            for k in range(9):
                m00, m01, m10, m11 = blocks[k]
                add_block(J, j - 1 + k // 3, j - 1 + k % 3, m00, m01, m10, m11)
    if not water:
        return 0.0
    # drag (docs/model.md §4): F = -c_t l (v_t + v_t|v_t|) t - c_n l (v_n + v_n|v_n|) n, half per node
    ct = 0.25 * prm[P_RHO] * math.pi * prm[P_CF] * (prm[P_A] + prm[P_B])
    cn = prm[P_RHO] * prm[P_CD] * prm[P_A]
    power = 0.0
    for i in range(N - 1):
        l, tx, ty, nx, ny, vx, vy, vt, vn = edge_frame_at(geo, v, i)
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
            c00, c01, c11, d00, d01, d10, d11 = drag_jacobian(
                ct, cn, l, tx, ty, nx, ny, vt, vn, gt, gn, cx, cv
            )
            for a in (i, i + 1):
                add_block(J, a, i, c00 - d00, c01 - d01, c01 - d10, c11 - d11)
                add_block(J, a, i + 1, c00 + d00, c01 + d01, c01 + d10, c11 + d11)
    return power


@njit(cache=True, error_model="numpy", _nrt=False)
def added_mass(q, prm, dv, out, J, coef, apply, jac):
    """Added mass of docs/model.md §4.

    ``M_A`` puts ``mu_n/4 n n^T`` on the four blocks of each edge, ``mu_n = rho pi C_A a^2 l``. If
    ``apply``, add ``M_A dv`` to ``out``; if ``jac``, add ``coef M_A`` to the band ``J``.
    """
    N = q.size // 2
    cm = added_mass_coefficient(prm)
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
                    add_block(J, a, b, m00, m01, m01, m11)


@njit(cache=True, error_model="numpy", _nrt=False)
def solve_mass(q, prm, m, F, a, J, piv, water):
    """Accelerations ``a`` from ``(M + M_A(q)) a = F`` by a banded solve.

    ``M_A = 0`` unless ``water``; ``m`` is the node mass per coordinate (2N,).
    """
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
    band_factor(J, piv, n, PIVOT_THRESHOLD)  # M + M_A: symmetric positive definite
    band_solve(J, piv, n, a)


@njit(cache=True, error_model="numpy", _nrt=False)
def fluid_momentum(geo, v, prm, R, sp, sg, J, dt, jac):
    """The water's kinetic energy ``T_f = sum_i 1/2 mu_n (v^i .

    n^i)^2`` (docs/model.md §4) and its derivatives: adds ``sp P_f + sg G`` to R (2N,), with the
    water's momentum ``P_f = dT_f/dv`` (half of each edge's ``mu_n v_n n`` to each node) [N s] and
    ``G = dT_f/dx`` [N]. If ``jac``, adds the Jacobian of ``P_f - dt G`` with respect to the
    end-of-step velocity (``x = x0 + dt v``) to the band J: ``dP_f/dv + dt (dP_f/dx - dG/dv) - dt^2
    dG/dx`` (``M_A``, a skew gyroscopic part and a symmetric curvature part). Returns ``T_f`` [J].
    The positions enter through their edge geometry ``geo``
    (:func:`~soft_snake_gym.physics.geometry.edge_geometry`, or :func:`assemble` of the same ``q``).

    Per edge, with ``c = rho pi C_A a^2`` (``mu_n = c l``), ``e = x[i+1] - x[i]``:
    ``dT/de = c (vn^2/2 t - vn vt n)``, ``d(mu_n vn n)/de = c (-vt n n^T + vn (n t^T - t n^T))``,
    ``d2T/de2 = c/l (vt^2 - vn^2/2) n n^T``.
    """
    N = v.size // 2
    cm = added_mass_coefficient(prm)
    tf = 0.0
    for i in range(N - 1):
        l, tx, ty, nx, ny, vx, vy, vt, vn = edge_frame_at(geo, v, i)
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
            parts = momentum_jacobian(cm, l, tx, ty, nx, ny, vt, vn, dt)
            for ia in range(2):
                for ib in range(2):
                    m00, m01, m10, m11 = momentum_block(2.0 * ia - 1.0, 2.0 * ib - 1.0, nx, ny, parts)
                    add_block(J, i + ia, i + ib, m00, m01, m10, m11)
    return tf


@njit(cache=True, inline="always", error_model="numpy")
def momentum_jacobian(cm, l, tx, ty, nx, ny, vt, vn, dt):
    """One edge's parts of :func:`fluid_momentum`'s Jacobian: (A, dt/2, dt^2 H's factor, D).

    ``D = d(edge momentum)/de``; node block (a, b) gets ``A + dt/2 (s_b D - s_a D^T) - dt^2 s_a
    s_b H`` (:func:`momentum_block`).
    """
    a = 0.25 * cm * l
    d00 = cm * (-vt * nx * nx + vn * (nx * tx - tx * nx))
    d01 = cm * (-vt * nx * ny + vn * (nx * ty - tx * ny))
    d10 = cm * (-vt * ny * nx + vn * (ny * tx - ty * nx))
    d11 = cm * (-vt * ny * ny + vn * (ny * ty - ty * ny))
    hc = dt * dt * cm / l * (vt * vt - 0.5 * vn * vn)
    return a, 0.5 * dt, hc, d00, d01, d10, d11


@njit(cache=True, inline="always", error_model="numpy")
def momentum_block(sa, sb, nx, ny, parts):
    """The 2x2 block of nodes (a, b) of one edge (signs ``sa``, ``sb``: -1 or 1) from :func:`momentum_jacobian`."""
    a, hd, hc, d00, d01, d10, d11 = parts
    h = hc * sa * sb
    return (
        a * nx * nx + hd * (sb * d00 - sa * d00) - h * nx * nx,
        a * nx * ny + hd * (sb * d01 - sa * d10) - h * nx * ny,
        a * ny * nx + hd * (sb * d10 - sa * d01) - h * ny * nx,
        a * ny * ny + hd * (sb * d11 - sa * d11) - h * ny * ny,
    )


@njit(cache=True, error_model="numpy", _nrt=False)
def munk_force(q, v, prm, F):
    """Adds the velocity part of the consistent added-mass force to F (2N,) [N].

    That part is ``dT_f/dx - (dP_f/dx) v`` (the turning normal's terms, the Munk moment). With it,
    ``(M + M_A) a = F_other + munk`` is the Lagrangian equation of ``T_f`` (docs/model.md §4).
    """
    N = q.size // 2
    cm = added_mass_coefficient(prm)
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


@njit(cache=True, error_model="numpy", _nrt=False)
def fluid_kinetic_energy(q, v, prm):
    """``T_f = sum_i 1/2 mu_n (v^i . n^i)^2``, the water's kinetic energy (docs/model.md §4) [J]."""
    N = q.size // 2
    cm = added_mass_coefficient(prm)
    tf = 0.0
    for i in range(N - 1):
        ex = q[2 * i + 2] - q[2 * i]
        ey = q[2 * i + 3] - q[2 * i + 1]
        vx = 0.5 * (v[2 * i] + v[2 * i + 2])
        vy = 0.5 * (v[2 * i + 1] + v[2 * i + 3])
        w = vy * ex - vx * ey  # l v_n
        tf += 0.5 * cm * w * w / math.sqrt(ex * ex + ey * ey)
    return tf


@njit(cache=True, error_model="numpy", _nrt=False)
def damping_power(q, v, prm, geo):
    """Power lost to material damping [W].

    ``damping_bend sum kappa_dot^2 + damping_stretch sum ldot^2`` (docs/model.md §3). ``geo`` is
    the edge geometry of ``q`` (:func:`~soft_snake_gym.physics.geometry.edge_geometry`).
    """
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
            k, g0x, g0y, g1x, g1y, g2x, g2y = turning_at(geo, j)[:7]
            kd = (1.0 + 0.25 * k * k) * turning_rate(g0x, g0y, g1x, g1y, g2x, g2y, v, j)
            p += db * kd * kd
    return p


@njit(cache=True, error_model="numpy", _nrt=False)
def actuator_power(q, kbar, lbar, u_k, u_l, prm, geo):
    """Power the inputs put into the body, ``dE/dkbar . u_k + dE/dlbar . u_l`` (docs/model.md §3) [W].

    ``geo`` is the edge geometry of ``q`` (:func:`~soft_snake_gym.physics.geometry.edge_geometry`).
    """
    N = q.size // 2
    EA, EI = prm[P_EA], prm[P_EI]
    p = 0.0
    for j in range(1, N - 1):
        lv = 0.5 * (lbar[j - 1] + lbar[j])
        dk = turning_at(geo, j)[0] - kbar[j - 1]
        p -= EI / lv * dk * u_k[j - 1]
        p -= 0.25 * EI * dk * dk / (lv * lv) * (u_l[j - 1] + u_l[j])
    for k in range(N - 1):
        r = geo[0, 2 * k] / lbar[k]
        p -= 0.5 * EA * (r * r - 1.0) * u_l[k]
    return p


@njit(cache=True, inline="always", error_model="numpy")
def kinetic_friction(q, v, i, fn, eps2, prm):
    """Kinetic friction on sliding node i with normal load ``fn`` [N] and its velocity derivative.

    See docs/model.md §5. The derivative is by the node's velocity (the tangent's dependence on q is
    left out).

    Isotropic: ``-mu_d fn v / s``, ``s = sqrt(|v|^2 + eps2)`` (a smoothing far below the
    sticking speed). Anisotropic: ``-fn (mu_t v_t t + mu_lateral v_n n) / s``, with ``mu_t`` the
    forward or backward coefficient by the sign of ``v_t``.

    Returns:
        (fx, fy, d fx/d vx, d fx/d vy, d fy/d vx, d fy/d vy).
    """
    vx, vy = v[2 * i], v[2 * i + 1]
    if prm[P_ANISO] == 0.0:
        return isotropic_friction(vx, vy, prm[P_MUD] * fn, eps2)
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + eps2)  # 1/s: one division, where six were
    tx, ty = node_tangent(q, i)
    nx, ny = -ty, tx
    vt = vx * tx + vy * ty
    vn = vx * nx + vy * ny
    mt = prm[P_MU_FWD] if vt > 0.0 else prm[P_MU_BWD]
    mn = prm[P_MU_LAT]
    gx = fn * (mt * vt * tx + mn * vn * nx) * inv  # the friction force is -g / s
    gy = fn * (mt * vt * ty + mn * vn * ny) * inv
    inv2 = inv * inv
    # d(-g/s)/dv = -(fn (mt t t^T + mn n n^T)) / s + g v^T / s^3
    a00 = fn * (mt * tx * tx + mn * nx * nx) * inv
    a01 = fn * (mt * tx * ty + mn * nx * ny) * inv
    a11 = fn * (mt * ty * ty + mn * ny * ny) * inv
    return (
        -gx,
        -gy,
        -a00 + gx * vx * inv2,
        -a01 + gx * vy * inv2,
        -a01 + gy * vx * inv2,
        -a11 + gy * vy * inv2,
    )


@njit(cache=True, inline="always", error_model="numpy")
def isotropic_friction(vx, vy, mufn, eps2):
    """:func:`kinetic_friction` with one coefficient: ``-mufn v / s`` for ``mufn = mu_d fn``, and its derivative."""
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + eps2)  # 1/s: one division, where six were
    c = mufn * inv  # mu_d fn / s
    c3 = c * inv * inv  # mu_d fn / s^3
    return (
        -c * vx,
        -c * vy,
        -c + c3 * vx * vx,
        c3 * vx * vy,
        c3 * vx * vy,
        -c + c3 * vy * vy,
    )
