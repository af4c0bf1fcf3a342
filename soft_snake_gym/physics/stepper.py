"""Time stepping of the discrete rod (docs/model.md §5-§5a).

Backward Euler by damped Newton on the banded Jacobian, explicit symplectic Euler, the stick-slip
decision both share, the state check after each step, the energy ledger, and :func:`simulate`, which
advances one robot's :class:`~soft_snake_gym.physics.layout.SimArrays` by whole steps. Nothing here
allocates or raises; failures come back as a status code (``layout.OK``, ...).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from soft_snake_gym.physics import banded, forces, geometry, layout
from soft_snake_gym.physics.banded import KL, PIVOT_THRESHOLD, add_block, band_factor, band_solve
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.forces import (
    actuator_power,
    added_mass,
    assemble,
    assemble_at,
    damping_power,
    elastic_energy,
    fluid_kinetic_energy,
    fluid_momentum,
    kinetic_friction,
    munk_force,
    solve_mass,
)
from soft_snake_gym.physics.geometry import edge_geometry, self_intersects
from soft_snake_gym.physics.layout import (
    ADDED_MASS_CONSISTENT,
    B_A,
    B_DV,
    B_F,
    B_FEXT,
    B_GEO,
    B_KEYS,
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
    BAD_REST_LENGTH,
    I_FRICTION,
    I_ORDER,
    I_PIV,
    I_SWITCHES,
    MAX_SWITCHES,
    MEDIUM_GROUND,
    MEDIUM_WATER,
    METHOD_BDF2,
    METHOD_SDIRK2,
    METHOD_SYMPLECTIC_EULER,
    N_LEDGER,
    NON_FINITE,
    NOT_CONVERGED,
    O_E_ACT,
    O_E_DAMP,
    O_E_ELASTIC,
    O_E_FLUID,
    O_E_FRICTION,
    O_E_KIN,
    O_L0_E_DAMP,
    O_L0_E_FLUID,
    O_L0_E_FRICTION,
    O_L0_ELASTIC,
    O_L0_KIN,
    O_L0_T_FLUID,
    O_L0_W_ACT,
    O_LEDGER,
    O_NFACTOR,
    O_NITER,
    O_NJAC,
    O_NRES,
    O_NSTEPS,
    O_P_ACT,
    O_P_DAMP,
    O_P_FLUID,
    O_P_FRICTION,
    O_RESIDUAL,
    O_STATUS,
    O_T_FLUID,
    O_W_ACT,
    OK,
    P_ADDED_MASS,
    P_CHECKSI,
    P_CHORD,
    P_DBEND,
    P_DSTRETCH,
    P_G,
    P_H,
    P_LAG,
    P_MAXIT,
    P_MAXSTRAIN,
    P_MEDIUM,
    P_METHOD,
    P_MUS,
    P_SUBSTEPS,
    P_TOL,
    P_VTOL,
    RUNAWAY_STRETCH,
    SELF_INTERSECTION,
    SLIDING,
    STUCK,
    borrowed_arrays,
    copy_into,
)

#: SDIRK2's diagonal coefficient (Alexander 1977): two backward-Euler stages of ``GAMMA dt``,
#: second order and L-stable, stiffly accurate (the step ends at the second stage)
GAMMA = 1.0 - 1.0 / math.sqrt(2.0)

# the cached kernels embed the code of the kernels they call from these files
drop_stale_cache(__file__, [banded.__file__, forces.__file__, geometry.__file__, layout.__file__])


@njit(cache=True, error_model="numpy", _nrt=False)
def check_state(q, v, lbar, prm, buf, ibuf):
    """Status code of a state: non-finite, runaway stretch, or self-intersection.

    The edges' lengths are ``buf[B_GEO]``'s, which every writer of ``q`` leaves there (their
    square roots: libm's hypot only where the square overflows).
    """
    n = q.size
    for i in range(n):
        if not (math.isfinite(q[i]) and math.isfinite(v[i])):
            return NON_FINITE
    max_strain = prm[P_MAXSTRAIN]
    lengths = buf[B_GEO]
    for k in range(n // 2 - 1):
        l = lengths[2 * k]
        if l == math.inf:
            l = math.hypot(q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1])
        if abs(l / lbar[k] - 1.0) > max_strain:
            return RUNAWAY_STRETCH
    if prm[P_CHECKSI] != 0.0 and self_intersects(q, buf[B_KEYS], ibuf[I_ORDER]):
        return SELF_INTERSECTION
    return OK


@njit(cache=True, inline="always", error_model="numpy")
def classify_contact(v, state, i, limit, at_limit):
    """The stick-slip decision of node i on the ground (docs/model.md §5), shared by both integrators.

    The node sticks (``state[i] = STUCK``, its velocity set to zero) if its speed is below ``limit``
    [m/s] (or equal to it, if ``at_limit``), else it slides (``state[i] = SLIDING``, velocity kept).
    Returns True if it sticks.

    Backward Euler passes ``limit = V_tol``; the explicit method passes the speed static
    friction removes in a sub-step, ``mu_s g dt``, with ``at_limit``.
    """
    w2 = v[2 * i] * v[2 * i] + v[2 * i + 1] * v[2 * i + 1]  # squared: no square root (nor libm's hypot)
    limit2 = limit * limit
    if w2 < limit2 or (at_limit and w2 == limit2):
        state[i] = STUCK
        v[2 * i] = 0.0
        v[2 * i + 1] = 0.0
        return True
    state[i] = SLIDING
    return False


@njit(cache=True, error_model="numpy", _nrt=False)
def _be_residual(s, dt, medium, jac):
    """Residual of backward Euler at the trial velocity ``v``, and if ``jac`` its Jacobian into J.

    Also writes ``q = q0 + dt v``. In water with the consistent added mass (docs/model.md §4) in
    momentum form, ``R = M (v - v0) + P_f(q, v) - P_f(q0, v0) - dt (F(q, v) + dT_f/dx(q, v))``
    (``P_f(q0, v0)`` in ``buf[B_P0]``); with ``added_mass = "kelasidi"``,
    ``R = (M + M_A(q)) (v - v0) - dt F(q, v)``. Returns (squared 2-norm, max-norm of R/m [m/s],
    fluid power, friction power). Counts itself in ``out[O_NJAC]`` or ``out[O_NRES]``.
    """
    q, v, kbar, lbar, prm, buf, J, ibuf = s.q, s.v, s.kbar, s.lbar, s.prm, s.buf, s.J, s.ibuf
    n = q.size
    s.out[O_NJAC if jac else O_NRES] += 1.0
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
    geo = buf[B_GEO : B_GEO + 2]
    p_fluid = assemble(q, v, kbar, lbar, prm, F, J, -dt * dt, -dt, jac, water, geo)
    for i in range(n):
        R[i] = m[i] * dv[i] - dt * F[i]
    if jac:
        for i in range(n):
            J[i, KL] += m[i]
    if water:
        if int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
            fluid_momentum(geo, v, prm, R, 1.0, -dt, J, dt, jac)  # geo: assemble's, of q
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
                # held at rest: R = v (= 0: a node sticks at 0 and its Newton updates are -0). Its
                # rows keep their assembled diagonal, where a 1 against the elastic entries
                # below it would make the factorization exchange rows; the update is 0 either way
                R[r0] = v[r0]
                R[r1] = v[r1]
                if jac:
                    d0, d1 = J[r0, KL], J[r1, KL]
                    J[r0, :] = 0.0
                    J[r1, :] = 0.0
                    J[r0, KL] = d0
                    J[r1, KL] = d1
            else:
                fx, fy, d00, d01, d10, d11 = kinetic_friction(q, v, i, m[r0] * prm[P_G], eps2, prm)
                R[r0] -= dt * fx
                R[r1] -= dt * fy
                p_fric -= fx * v[r0] + fy * v[r1]
                if jac:
                    add_block(J, i, i, -dt * d00, -dt * d01, -dt * d10, -dt * d11)
    norm2 = 0.0
    rmax = 0.0
    minv = buf[B_MINV]
    for i in range(n):
        norm2 += R[i] * R[i]
        rmax = max(rmax, abs(R[i]) * minv[i])  # |R|/m, a velocity: mass-independent tolerance
    return norm2, rmax, p_fluid, p_fric


@njit(cache=True, error_model="numpy", _nrt=False)
def _stick_slow_nodes(v, ibuf, prm, n):
    """Stick every sliding node slower than ``V_tol`` that may still change; True if any did."""
    state, switches = ibuf[I_FRICTION], ibuf[I_SWITCHES]
    stuck_any = False
    for i in range(n // 2):
        if (
            state[i] == SLIDING
            and switches[i] < MAX_SWITCHES
            and classify_contact(v, state, i, prm[P_VTOL], False)
        ):
            switches[i] += 1
            stuck_any = True
    return stuck_any


@njit(cache=True, error_model="numpy", _nrt=False)
def _stick_reversing_nodes(v, dv, ahead, vslide, ibuf, n):
    """Stick every sliding node that ``v + ahead dv`` turns against the way it has slid; True if any did.

    Kinetic friction brakes a sliding node; it cannot push it back. A node whose velocity
    would end the step against ``vslide`` (its velocity at the start of the step, or the
    first guess it was released with: ``buf[B_VSLIDE]``) passed through rest within the
    step, where the law holds it unless the force exceeds ``mu_s F_N``: it is held at rest,
    and :func:`_update_contacts` releases it at the end of the pass if its holding force
    exceeds ``mu_s F_N``, along its new push. Released nodes are tested too: a node
    released with too weak a push otherwise swings about rest, friction flipping at every
    Newton iterate, until a line search brings it below ``V_tol``. ``ahead`` is 1 to test a
    Newton update ``dv`` before it is taken, 0 to test the converged velocity.
    """
    state, switches = ibuf[I_FRICTION], ibuf[I_SWITCHES]
    stuck_any = False
    for i in range(n // 2):
        r0, r1 = 2 * i, 2 * i + 1
        # one branch a node, on all three tests at once (&, not and: three were mispredicted)
        turns = (v[r0] + ahead * dv[r0]) * vslide[r0] + (v[r1] + ahead * dv[r1]) * vslide[r1] < 0.0
        if turns & (state[i] == SLIDING) & (switches[i] < MAX_SWITCHES):
            state[i] = STUCK
            switches[i] += 1
            v[r0] = 0.0
            v[r1] = 0.0
            stuck_any = True
    return stuck_any


@njit(cache=True, error_model="numpy", _nrt=False)
def _reversal_in_update(v, dv, vslide, ibuf, n):
    """Newton's update ``dv``, tested before it is taken; True if a node it turns was held.

    Every sliding node that ``v + dv`` turns against the way it slides is held
    (:func:`_stick_reversing_nodes`), and if any is, the nodes still sliding take the update:
    it was solved with the newly held nodes sliding, but the others' part of it is still a
    better start for the pass than the iterate it came from (under random actions a worm step
    took 4.07 factorizations with it, 4.40 without). ``_be_newton`` and the crawl's lanes then
    start the pass again.
    """
    if not _stick_reversing_nodes(v, dv, 1.0, vslide, ibuf, n):
        return False
    state = ibuf[I_FRICTION]
    for i in range(n // 2):
        if state[i] == SLIDING:
            v[2 * i] += dv[2 * i]
            v[2 * i + 1] += dv[2 * i + 1]
    return True


@njit(cache=True, error_model="numpy", _nrt=False)
def _update_contacts(v, buf, ibuf, prm, dt, n):
    """Make stick-slip consistent with the end of a converged step (docs/model.md §5).

    True if a node changed and the step must be solved again.

    Sliding nodes that end slower than ``V_tol``, or against the way they slide
    (:func:`_stick_reversing_nodes`), stick. Otherwise every stuck node whose
    holding force ``f = -m v0/dt - F`` (``F``: every other force, at the end of the step)
    exceeds ``mu_s F_N`` is released to slide, with a first guess along its push (releasing
    them one at a time, worst first, gave the same gaits to 1e-4 in more passes). A node
    released too eagerly ends slow and sticks again in the next pass. Each node changes at
    most ``MAX_SWITCHES`` times per step, so the passes end.
    """
    if _stick_slow_nodes(v, ibuf, prm, n) | _stick_reversing_nodes(v, v, 0.0, buf[B_VSLIDE], ibuf, n):
        return True
    F, m, v0 = buf[B_F], buf[B_M], buf[B_V0]
    state, switches = ibuf[I_FRICTION], ibuf[I_SWITCHES]
    released = False
    for i in range(n // 2):
        if state[i] != STUCK or switches[i] >= MAX_SWITCHES:
            continue
        fx = -m[2 * i] * v0[2 * i] / dt - F[2 * i]
        fy = -m[2 * i] * v0[2 * i + 1] / dt - F[2 * i + 1]
        hold = prm[P_MUS] * m[2 * i] * prm[P_G]
        if fx * fx + fy * fy <= hold * hold:
            continue
        _release(v, buf[B_VSLIDE], state, i, -fx, -fy, prm[P_VTOL])
        switches[i] += 1
        released = True
    return released


@njit(cache=True, inline="always", error_model="numpy")
def _release(v, vslide, state, i, px, py, vtol):
    """Let node i slide, with a first guess just above the sticking speed along the push (px, py), kept in ``vslide``."""
    state[i] = SLIDING
    p = math.hypot(px, py)
    v[2 * i] = vslide[2 * i] = 2.0 * vtol * px / p
    v[2 * i + 1] = vslide[2 * i + 1] = 2.0 * vtol * py / p


@njit(cache=True, error_model="numpy", _nrt=False)
def _be_substep(s, dt, medium, extrapolate):
    """One backward-Euler step by damped Newton on the banded analytic Jacobian (docs/model.md §5a).

    The first guess of the velocity in water extrapolates the last step's change by the
    fraction ``extrapolate`` (1: a step as long as the last). Returns (status, iterations,
    residual, fluid power, friction power).
    """
    _be_start(s, medium, extrapolate)
    return _be_newton(s, dt, medium)


@njit(cache=True, error_model="numpy", _nrt=False)
def _be_start(s, medium, extrapolate):
    """Record the start of an implicit step in ``buf`` and make the first guess (contacts, velocity).

    On the ground ``buf[B_GEO]`` must hold the edge geometry of ``q``, as at every sub-step's start
    (:func:`move_rest_shape`; backward Euler is the only method there).
    """
    q, v, prm, buf, J, ibuf = s.q, s.v, s.prm, s.buf, s.J, s.ibuf
    n = q.size
    q0, v0 = buf[B_Q0], buf[B_V0]
    if medium == MEDIUM_GROUND:
        # first guess of the contacts: slow nodes stick, the rest slide, and a stuck node whose
        # holding force at the start of the step (the rest shape already moved) exceeds
        # mu_s F_N slides, as _update_contacts would release it after a whole contact pass
        # (halves the Newton iterations under random actions); _update_contacts then makes
        # the contacts consistent with the end of the step
        state, switches, vslide = ibuf[I_FRICTION], ibuf[I_SWITCHES], buf[B_VSLIDE]
        for i in range(n):
            q0[i] = q[i]
            v0[i] = vslide[i] = v[i]
        stuck_any = False
        for i in range(n // 2):
            switches[i] = 0
            stuck_any |= classify_contact(v, state, i, prm[P_VTOL], False)
        if stuck_any:  # the start-of-step forces, for the stuck nodes only
            F, m, fext = buf[B_F], buf[B_M], buf[B_FEXT]
            for i in range(n):
                F[i] = fext[i]
            geo = buf[B_GEO : B_GEO + 2]  # of this q (move_rest_shape's precondition)
            assemble_at(q, v, s.kbar, s.lbar, prm, F, J, 0.0, 0.0, False, False, geo)
            for i in range(n // 2):
                r0, r1 = 2 * i, 2 * i + 1
                hold = prm[P_MUS] * m[r0] * prm[P_G]
                if state[i] == STUCK and F[r0] * F[r0] + F[r1] * F[r1] > hold * hold:
                    _release(v, vslide, state, i, F[r0], F[r1], prm[P_VTOL])
    else:
        # predictor: extrapolate the velocity from the last step (v0 still holds its start;
        # set_state makes it the current velocity, so a fresh state starts with v)
        for i in range(n):
            q0[i] = q[i]
            v_prev = v0[i]
            v0[i] = v[i]
            v[i] += extrapolate * (v[i] - v_prev)
        if medium == MEDIUM_WATER and int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
            p0, geo = buf[B_P0], buf[B_GEO : B_GEO + 2]
            p0[:] = 0.0
            edge_geometry(q0, geo)
            fluid_momentum(geo, v0, prm, p0, 1.0, 0.0, J, 0.0, False)


@njit(cache=True, error_model="numpy", _nrt=False)
def _sdirk2_second_start(s, medium):
    """Turn the end of SDIRK2's first stage into the start of its second (docs/model.md §5a).

    The second stage is a backward-Euler step of ``GAMMA dt`` from the start moved along the
    first stage's change by ``(1 - GAMMA)/GAMMA``: position, velocity and, with the consistent
    added mass, the water's momentum. The step's start velocity is kept in ``buf[B_VSTEP]``.
    The first guess extrapolates the first stage's velocity change to the end of the step.
    Never on the ground (``SimConfig`` rejects it there), so no contacts to carry over.
    """
    q, v, prm, buf, J = s.q, s.v, s.prm, s.buf, s.J
    n = q.size
    q0, v0, vstep = buf[B_Q0], buf[B_V0], buf[B_VSTEP]
    c = (1.0 - GAMMA) / GAMMA
    if medium == MEDIUM_WATER and int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
        p0, p1, geo = buf[B_P0], buf[B_A], buf[B_GEO : B_GEO + 2]  # geo: the first stage's, of q
        p1[:] = 0.0
        fluid_momentum(geo, v, prm, p1, 1.0, 0.0, J, 0.0, False)
        for i in range(n):
            p0[i] += c * (p1[i] - p0[i])
    for i in range(n):
        vstep[i] = v0[i]
        change = v[i] - v0[i]
        q0[i] += c * (q[i] - q0[i])
        v0[i] += c * change
        v[i] = v0[i] + change


@njit(cache=True, error_model="numpy", _nrt=False)
def _be_newton(s, dt, medium):
    """Solve the implicit step that :func:`_be_start` set up; see :func:`_be_substep`."""
    q, v, prm, buf, J, ibuf = s.q, s.v, s.prm, s.buf, s.J, s.ibuf
    n = q.size
    vacc, dv = buf[B_VACC], buf[B_DV]
    R = buf[B_R]
    piv = ibuf[I_PIV]
    tol = prm[P_TOL]
    maxit = int(prm[P_MAXIT])
    norm2, rmax, p_fluid, p_fric = _be_residual(s, dt, medium, True)
    it = 0
    pass_it = 0
    factored = False  # J holds the factors of an earlier iterate's Jacobian (a chord step)
    fused = medium == MEDIUM_GROUND  # see the line search
    chord_rate = prm[P_CHORD]  # Integrator.newton_chord_rate
    searched_it = -1  # the last pass iteration whose full step the line search cut
    while True:
        if rmax <= tol:
            # stick-slip decided by the end of the step (docs/model.md §5): if a contact changes,
            # the step is solved again from the current iterate
            if medium != MEDIUM_GROUND or not _update_contacts(v, buf, ibuf, prm, dt, n):
                break
            norm2, rmax, p_fluid, p_fric = _be_residual(s, dt, medium, True)
            factored = False
            pass_it = 0  # the iteration cap holds per contact pass
            continue
        if pass_it == maxit or not math.isfinite(norm2):
            return NOT_CONVERGED, it, rmax, p_fluid, p_fric
        it += 1
        pass_it += 1
        chord = factored
        if not factored:
            s.out[O_NFACTOR] += 1.0
            if not band_factor(J, piv, n, PIVOT_THRESHOLD):
                return NOT_CONVERGED, it, rmax, p_fluid, p_fric
            factored = True
        for i in range(n):
            vacc[i] = v[i]
            dv[i] = -R[i]
        band_solve(J, piv, n, dv)
        if fused and _reversal_in_update(v, dv, buf[B_VSLIDE], ibuf, n):
            norm2, rmax, p_fluid, p_fric = _be_residual(s, dt, medium, True)
            factored = False
            pass_it = 0
            continue
        # backtracking line search on |R|^2. Off the ground most steps converge in one or two
        # iterations, so trials skip the Jacobian; a chord step (the factors of an earlier
        # Jacobian) that does not descend at full length is not searched: the Jacobian is
        # renewed. On the ground a contact pass takes several iterations, so the full step's
        # trial assembles the Jacobian too and, accepted, serves the next iteration; not once
        # rmax^2 <= tol, where Newton's quadratic convergence makes it the pass's last iterate,
        # nor right after an iteration whose full step was cut: that Jacobian goes unused (the
        # step cut again, or converged) 98 % of the time under random actions
        step = 1.0
        renew = fused and rmax * rmax > tol and searched_it != pass_it - 1
        for _ in range(12):
            for i in range(n):
                v[i] = vacc[i] + step * dv[i]
            trial = _be_residual(s, dt, medium, renew and step == 1.0)
            if trial[0] < norm2 * (1.0 - 1e-4 * step) or chord:
                break
            step *= 0.5
        rmax_prev = rmax
        if step < 1.0:
            searched_it = pass_it
        if chord and not trial[0] < norm2 * (1.0 - 1e-4):
            for i in range(n):
                v[i] = vacc[i]
            norm2, rmax, p_fluid, p_fric = _be_residual(s, dt, medium, True)
            factored = False
            continue
        norm2, rmax, p_fluid, p_fric = trial
        if fused:
            factored = False  # J was overwritten by the full step's Jacobian
            if rmax > tol and _stick_slow_nodes(v, ibuf, prm, n):
                # a sliding node that an iterate brings below V_tol would stick at the end of
                # the pass: stick it now instead of converging it into friction's smoothing
                norm2, rmax, p_fluid, p_fric = _be_residual(s, dt, medium, True)
                pass_it = 0
                continue
        if (
            rmax > tol
            and pass_it < maxit
            and math.isfinite(norm2)
            and not (renew and step == 1.0)
            and not (not fused and step == 1.0 and rmax <= chord_rate * rmax_prev)
        ):
            # the next iteration renews the Jacobian, at the accepted velocity (the residual is
            # recomputed bit for bit); off the ground, after a fast contraction, it keeps the factors
            # (modified Newton: a solve and a residual per iteration, to the same tolerance). Not
            # on the ground, where the full step's trial has already renewed the Jacobian
            _be_residual(s, dt, medium, True)
            factored = False
    return OK, it, rmax, p_fluid, p_fric


@njit(cache=True, error_model="numpy", _nrt=False)
def _symplectic_substep(s, dt, medium):
    """One explicit semi-implicit (symplectic) Euler step: kick with F(q, v), then drift.

    In water ``(M + M_A(q)) a = F``, plus with the consistent added mass the velocity terms of
    :func:`munk_force`. On the ground, friction is decided by the end of the kick (docs/model.md
    §5): a node whose frictionless end velocity ``w`` could be stopped within ``mu_s F_N`` sticks,
    any other slides with ``mu_d F_N`` against ``w`` (the lumped mass matrix is diagonal on the
    ground, so each node is decided on its own). Returns (fluid power, friction power).
    """
    q, v, kbar, lbar, prm, buf, J, ibuf = s.q, s.v, s.kbar, s.lbar, s.prm, s.buf, s.J, s.ibuf
    n = q.size
    F, a, m, fext = buf[B_F], buf[B_A], buf[B_M], buf[B_FEXT]
    for i in range(n):
        F[i] = fext[i]
    p_fluid = assemble(
        q, v, kbar, lbar, prm, F, J, 0.0, 0.0, False, medium == MEDIUM_WATER, buf[B_GEO : B_GEO + 2]
    )
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
            if not classify_contact(v, state, i, prm[P_MUS] * stop, True):
                # kinetic friction along the frictionless end velocity, explicit (a sub-step
                # is far shorter than the time friction needs to stop the node)
                fx, fy = kinetic_friction(q, v, i, m[r0] * prm[P_G], 0.0, prm)[:2]
                v[r0] += dt * fx / m[r0]
                v[r1] += dt * fy / m[r0]
                p_fric -= fx * v[r0] + fy * v[r1]
    for i in range(n):
        q[i] += dt * v[i]
    return p_fluid, p_fric


@njit(cache=True, error_model="numpy", _nrt=False)
def ledger_energies(s, geo_made=False):
    """Write the body's energies, the water's ``T_f`` and the energy ledger into ``out``.

    The body's kinetic and elastic energy and the water's ``T_f`` (0 out of water) go into
    ``out[O_E_KIN]``, ``out[O_E_ELASTIC]``, ``out[O_T_FLUID]`` [J], and the energy ledger since the
    start recorded at ``O_L0_*`` into ``out[O_LEDGER:]`` (``LEDGER_KEYS``); ``s`` is
    :class:`~soft_snake_gym.physics.layout.SimArrays` or the plain tuple of its arrays. Leaves
    the edge geometry of ``q`` in ``buf[B_GEO]``, where the observation reads it; ``geo_made``:
    it is there already (every step leaves it), so it is not made again.
    """
    s = borrowed_arrays(s)  # no reference counting inside (layout.borrowed)
    q, v, kbar, lbar, prm, buf, out = s.q, s.v, s.kbar, s.lbar, s.prm, s.buf, s.out
    m = buf[B_M]
    ke = 0.0
    for i in range(q.size):
        ke += 0.5 * m[i] * v[i] * v[i]
    out[O_E_KIN] = ke
    geo = buf[B_GEO : B_GEO + 2]
    if not geo_made:
        edge_geometry(q, geo)  # one square root an edge: the energy from q took about three
    out[O_E_ELASTIC] = elastic_energy(geo, kbar, lbar, prm)
    out[O_T_FLUID] = fluid_kinetic_energy(q, v, prm) if int(prm[P_MEDIUM]) == MEDIUM_WATER else 0.0
    ledger(out)


@njit(cache=True, error_model="numpy")
def start_from_state(s):
    """What a state written from outside needs before its first step; ``s`` as for :func:`ledger_energies`.

    The edges' order for the self-intersection sweep (by their smaller x, stable), every node
    sliding, the predictor's start at the current velocity, no BDF2 history (its next step is an
    SDIRK2 step), and the energy ledger started here: the energies now, with the work and
    dissipation accumulated so far, as its origin.
    """
    ledger_energies(s)
    s = borrowed_arrays(s)
    q, v, buf, ibuf, out = s.q, s.v, s.buf, s.ibuf, s.out
    ne = q.size // 2 - 1
    keys = np.empty(ne)
    for e in range(ne):
        keys[e] = min(q[2 * e], q[2 * e + 2])
    ibuf[I_ORDER, :ne] = np.argsort(keys, kind="mergesort")
    ibuf[I_FRICTION, :] = SLIDING
    buf[B_V0, :] = v
    buf[B_QPREV, :] = math.nan
    for k, e in enumerate((O_E_KIN, O_E_ELASTIC, O_T_FLUID, O_W_ACT, O_E_FLUID, O_E_DAMP, O_E_FRICTION)):
        out[O_L0_KIN + k] = out[e]
    out[O_LEDGER : O_LEDGER + N_LEDGER] = 0.0


@njit(cache=True, error_model="numpy")
def restart(s, x, v, kbar, lbar):
    """``Simulator.start``: the state ``x``, ``v`` (N, 2), ``kbar``, ``lbar`` written, then :func:`start_from_state`.

    Clears ``out`` (time, energies, counts), the external force and the length rates first.
    """
    a = borrowed_arrays(s)
    a.out[:] = 0.0
    a.buf[B_FEXT, :] = 0.0
    a.buf[B_LRATE, :] = 0.0
    for i in range(x.shape[0]):
        a.q[2 * i], a.q[2 * i + 1] = x[i, 0], x[i, 1]
        a.v[2 * i], a.v[2 * i + 1] = v[i, 0], v[i, 1]
    a.kbar[:] = kbar
    a.lbar[:] = lbar
    start_from_state(s)


@njit(cache=True, inline="always", error_model="numpy")
def ledger(out):
    """The energy ledger into ``out[O_LEDGER:]`` from the energies in ``out`` (:func:`ledger_energies`).

    ``lanes.energies`` computes the energies of sixteen robots at once; the ledger is this.
    """
    # the ledger since O_L0_*: actuator work = dissipation + energy changes + error
    work = out[O_W_ACT] - out[O_L0_W_ACT]
    error = work
    for k, (now, start) in enumerate(
        (
            (O_E_FLUID, O_L0_E_FLUID),
            (O_E_DAMP, O_L0_E_DAMP),
            (O_E_FRICTION, O_L0_E_FRICTION),
            (O_E_KIN, O_L0_KIN),
            (O_E_ELASTIC, O_L0_ELASTIC),
            (O_T_FLUID, O_L0_T_FLUID),
        )
    ):
        term = out[now] - out[start]
        out[O_LEDGER + 1 + k] = term
        error -= term
    out[O_LEDGER] = work
    out[O_LEDGER + 7] = error


@njit(cache=True, error_model="numpy", _nrt=False)
def _move_rest_shape(kbar, lbar, lrate, u_k, u_l, dt, tau):
    """Advance the rest shape by ``dt``; ``BAD_REST_LENGTH`` if a rest length ends <= 0.

    The curvatures move at ``u_k``. The lengths move at the actuators' rates ``lrate``, which
    follow ``u_l`` with the lag ``tau`` (docs/model.md §3), integrated exactly:
    ``lrate(t) = u_l + (lrate_0 - u_l) exp(-t/tau)``, so ``lbar`` gains ``dt u_l + (lrate_0 - u_l)
    tau (1 - exp(-dt/tau))``. With ``tau = 0`` the rates equal ``u_l`` and ``lbar`` gains ``dt u_l``.
    """
    for j in range(kbar.size):
        kbar[j] += dt * u_k[j]
    decay = math.exp(-dt / tau) if tau > 0.0 else 0.0
    carry = tau * (1.0 - decay)
    status = OK
    for k in range(lbar.size):
        lbar[k] += dt * u_l[k] + (lrate[k] - u_l[k]) * carry
        lrate[k] = u_l[k] + (lrate[k] - u_l[k]) * decay
        if not lbar[k] > 0.0:
            status = BAD_REST_LENGTH
    return status


@njit(cache=True, error_model="numpy", _nrt=False)
def _sdirk2_substep(s, dt, medium, u_k, u_l, damped):
    """One SDIRK2 step of ``dt`` (docs/model.md §5a): two backward-Euler stages of ``GAMMA dt``.

    The rest shape moves to each stage's time before it is solved. The step's energies are its
    powers at the two stage ends weighted by the method's quadrature, ``1 - GAMMA`` and
    ``GAMMA``. Returns (status, iterations of both stages, residual, fluid, damping and
    friction energy, actuator work) [J]. ``lanes.newton`` solves the stages of sixteen robots
    at once between the same :func:`sdirk2_stage_start` and :func:`sdirk2_stage_end`.
    """
    acc = (0, 0.0, 0.0, 0.0, 0.0, 0.0)
    status = OK
    for stage in range(2):
        status = sdirk2_stage_start(s, stage, dt, medium, u_k, u_l)
        if status != OK:
            break
        status, acc = sdirk2_stage_end(s, stage, dt, u_k, damped, _be_newton(s, GAMMA * dt, medium), acc)
        if status != OK:
            break
    iters, res, e_fluid, e_damp, e_fric, e_act = acc
    return status, iters, res, e_fluid, e_damp, e_fric, e_act


@njit(cache=True, error_model="numpy", _nrt=False)
def sdirk2_stage_start(s, stage, dt, medium, u_k, u_l):
    """Move the rest shape to SDIRK2 stage ``stage``'s time and set up its backward-Euler solve.

    Stage 0 starts from the step's start (:func:`_be_start`), stage 1 from the first stage's end
    (:func:`_sdirk2_second_start`). Returns ``OK``, or ``BAD_REST_LENGTH`` (nothing set up).
    """
    lrate = s.buf[B_LRATE, : s.lbar.size]
    stage_dt = (GAMMA if stage == 0 else 1.0 - GAMMA) * dt
    status = _move_rest_shape(s.kbar, s.lbar, lrate, u_k, u_l, stage_dt, s.prm[P_LAG])
    if status == OK:
        if stage == 0:
            _be_start(s, medium, GAMMA)
        else:
            _sdirk2_second_start(s, medium)
    return status


@njit(cache=True, error_model="numpy", _nrt=False)
def sdirk2_stage_end(s, stage, dt, u_k, damped, newton, acc):
    """Account SDIRK2 stage ``stage`` solved with ``newton`` (:func:`_be_newton`'s result).

    ``acc`` = (iterations, residual, fluid, damping and friction energy, actuator work) so far;
    returns (status, the new ``acc``), the stage's powers weighted by its quadrature weight
    (:func:`sdirk2_stage_sums`), from the edges of ``q`` that its last residual left in
    ``buf[B_GEO]``. After stage 1 the step's start velocity goes back into ``v0``.
    """
    q, v, kbar, prm, buf = s.q, s.v, s.kbar, s.prm, s.buf
    lrate, geo = buf[B_LRATE, : s.lbar.size], buf[B_GEO : B_GEO + 2]
    if stage == 1:
        copy_into(buf[B_V0], buf[B_VSTEP])  # the step's start, for the next step's first guess
    p_act = actuator_power(q, kbar, s.lbar, u_k, lrate, prm, geo)
    p_damp = damping_power(q, v, prm, geo) if damped else 0.0
    return sdirk2_stage_sums(stage, dt, damped, newton, p_act, p_damp, acc)


@njit(cache=True, inline="always", error_model="numpy")
def sdirk2_stage_sums(stage, dt, damped, newton, p_act, p_damp, acc):
    """:func:`sdirk2_stage_end`'s sums: ``acc`` plus the stage's iterations and powers times its weight.

    ``lanes.stage_end`` computes the powers of sixteen robots at once and sums them here.
    """
    status, it, res, p_fluid, p_fric = newton
    iters, _, e_fluid, e_damp, e_fric, e_act = acc
    w = (1.0 - GAMMA if stage == 0 else GAMMA) * dt
    e_fluid += w * p_fluid
    e_fric += w * p_fric
    e_act += w * p_act
    if damped:
        e_damp += w * p_damp
    return status, (iters + it, res, e_fluid, e_damp, e_fric, e_act)


@njit(cache=True, error_model="numpy", _nrt=False)
def _bdf2_substep(s, dt, medium):
    """One BDF2 step of ``dt``: a backward-Euler stage of ``2 dt / 3`` from ``(4 y_n - y_(n-1)) / 3``.

    ``y`` is the position, the velocity and, with the consistent added mass, the water's
    momentum; ``y_(n-1)`` is the last step's start (``buf[B_QPREV]``, ``buf[B_V0]``). Returns as
    :func:`_be_newton`.
    """
    q, prm, buf, J = s.q, s.prm, s.buf, s.J
    n = q.size
    qprev, vprev = buf[B_QPREV], buf[B_VSTEP]
    copy_into(vprev, buf[B_V0])
    _be_start(s, medium, 1.0)
    q0, v0 = buf[B_Q0], buf[B_V0]
    if medium == MEDIUM_WATER and int(prm[P_ADDED_MASS]) == ADDED_MASS_CONSISTENT:
        p0, p1, geo = buf[B_P0], buf[B_A], buf[B_GEO : B_GEO + 2]
        p1[:] = 0.0
        edge_geometry(qprev, geo)
        fluid_momentum(geo, vprev, prm, p1, 1.0, 0.0, J, 0.0, False)
        for i in range(n):
            p0[i] += (p0[i] - p1[i]) / 3.0
    for i in range(n):
        qn, vn = q0[i], v0[i]
        q0[i] += (qn - qprev[i]) / 3.0
        v0[i] += (vn - vprev[i]) / 3.0
        qprev[i] = qn
        vprev[i] = vn
    result = _be_newton(s, 2.0 * dt / 3.0, medium)
    copy_into(buf[B_V0], vprev)  # the step's start, for the next step's first guess and history
    return result


@njit(cache=True, inline="always")
def is_damped(prm):
    """True if the rod has material damping (bending or stretching): its power is then summed."""
    return prm[P_DBEND] > 0.0 or prm[P_DSTRETCH] > 0.0


@njit(cache=True, error_model="numpy", _nrt=False)
def move_rest_shape(s, u_k, u_l, dt):
    """The start of an integrator's sub-step of ``dt``: the actuator power, then the rest shape moved.

    Returns (status, the actuator power at the start): ``BAD_REST_LENGTH`` if a rest length
    ends <= 0. ``buf[B_GEO]`` holds the edge geometry of ``q``, as every sub-step, residual and
    state written from outside leaves it. The inputs' work over the sub-step is the trapezoidal
    rule on ``P_act`` (with :func:`implicit_energies`' power at the end): exact for a body that
    lags the rest shape and for one that follows it at once, where a one-point rule charges
    inputs that reverse every step with work never done.
    """
    q, kbar, lbar, prm, buf = s.q, s.kbar, s.lbar, s.prm, s.buf
    lrate, geo = buf[B_LRATE, : lbar.size], buf[B_GEO : B_GEO + 2]
    p_act0 = actuator_power(q, kbar, lbar, u_k, lrate, prm, geo)
    return _move_rest_shape(kbar, lbar, lrate, u_k, u_l, dt, prm[P_LAG]), p_act0


@njit(cache=True, error_model="numpy", _nrt=False)
def implicit_energies(s, u_k, dt, p_act0, p_fluid, p_fric):
    """The end of an implicit sub-step of ``dt``: (fluid, damping, friction energy, actuator work) [J].

    The powers where the step evaluates its forces, at its end; the actuator's work by the
    trapezoidal rule from ``p_act0`` (:func:`move_rest_shape`). Leaves the edge geometry of ``q``
    in ``buf[B_GEO]`` (made again: ``lanes.crawl`` has it in a lane, where copying it out cost
    more than making it).
    """
    q, v, kbar, lbar, prm, buf = s.q, s.v, s.kbar, s.lbar, s.prm, s.buf
    lrate, geo = buf[B_LRATE, : lbar.size], buf[B_GEO : B_GEO + 2]
    edge_geometry(q, geo)
    p_act1 = actuator_power(q, kbar, lbar, u_k, lrate, prm, geo)
    p_damp = damping_power(q, v, prm, geo) if is_damped(prm) else 0.0
    return implicit_sums(dt, p_act0, p_act1, p_damp, p_fluid, p_fric)


@njit(cache=True, inline="always", error_model="numpy")
def implicit_sums(dt, p_act0, p_act1, p_damp, p_fluid, p_fric):
    """:func:`implicit_energies`' energies from its powers (``envs.task.block_step``'s under BDF2 too)."""
    return dt * p_fluid, dt * p_damp, dt * p_fric, 0.5 * dt * (p_act0 + p_act1)


@njit(cache=True, error_model="numpy", _nrt=False)
def simulate(s, u_k, u_l, n_steps):
    """Advance one robot by ``n_steps`` steps of ``h`` with inputs held constant; stops at the first failure.

    Per step: rest shape moves by ``dt u`` each sub-step (the lengths through the actuators'
    lag, :func:`_move_rest_shape`), the state follows by the chosen integrator, then the state
    is checked.

    Args:
        s: the robot's :class:`~soft_snake_gym.physics.layout.SimArrays` (or, from Python, the
            plain tuple of its arrays: see ``layout``), advanced in place; diagnostics go into
            ``s.out`` (the energies of :func:`ledger_energies` once, at the end).
        u_k: curvature rates, (N-2,) [1/s].
        u_l: commanded rest-length rates, (N-1,) [m/s]; the lengths follow them through
            ``Rod.length_lag``.
        n_steps: steps of ``h``.

    Returns:
        The status code (``OK`` = 0).
    """
    s = borrowed_arrays(s)  # no reference counting inside (layout.borrowed)
    q, v, kbar, lbar, prm, buf, out = s.q, s.v, s.kbar, s.lbar, s.prm, s.buf, s.out
    h = prm[P_H]
    nsub = int(prm[P_SUBSTEPS])
    dt = h / nsub
    medium = int(prm[P_MEDIUM])
    symplectic = int(prm[P_METHOD]) == METHOD_SYMPLECTIC_EULER
    sdirk2 = int(prm[P_METHOD]) == METHOD_SDIRK2
    bdf2 = int(prm[P_METHOD]) == METHOD_BDF2
    damped = is_damped(prm)
    tau = prm[P_LAG]
    lrate = buf[B_LRATE, : lbar.size]  # the length actuators' rates (docs/model.md §3)
    geo = buf[B_GEO : B_GEO + 2]  # the edge geometry of q for the powers (geometry.edge_geometry)
    if tau == 0.0:
        copy_into(lrate, u_l)  # no lag: the rates jump to the inputs (and _move_rest_shape keeps them there)
    status = OK
    for _ in range(n_steps):
        e_fluid = 0.0
        e_fric = 0.0
        e_act = 0.0
        e_damp = 0.0
        niter = 0
        resid = 0.0
        out[O_NJAC] = out[O_NRES] = out[O_NFACTOR] = 0.0
        for _s in range(nsub):
            if sdirk2 or (bdf2 and math.isnan(buf[B_QPREV, 0])):
                if bdf2:  # a fresh state (Simulator.set_state): BDF2 starts with one SDIRK2 step
                    copy_into(buf[B_QPREV], q)
                status, it, res, ef, ed, efr, ea = _sdirk2_substep(s, dt, medium, u_k, u_l, damped)
            else:
                status, p_act0 = move_rest_shape(s, u_k, u_l, dt)
                if status != OK:
                    break
                # each power where the step evaluates its forces: start (explicit) or end (implicit)
                it, res = 0, 0.0
                if symplectic:  # the geometry of q is still geo's
                    p_act1 = actuator_power(q, kbar, lbar, u_k, lrate, prm, geo)
                    p_damp = damping_power(q, v, prm, geo) if damped else 0.0
                    p_fluid, p_fric = _symplectic_substep(s, dt, medium)
                    edge_geometry(q, geo)  # of the new q: the next sub-step's start reads it
                    ef, ed, efr, ea = dt * p_fluid, dt * p_damp, dt * p_fric, 0.5 * dt * (p_act0 + p_act1)
                else:
                    status, it, res, p_fluid, p_fric = (
                        _bdf2_substep(s, dt, medium) if bdf2 else _be_substep(s, dt, medium, 1.0)
                    )
                    ef, ed, efr, ea = implicit_energies(s, u_k, dt, p_act0, p_fluid, p_fric)
            niter = max(niter, it)
            resid = max(resid, res)
            e_fluid += ef
            e_damp += ed
            e_fric += efr
            e_act += ea
            if status != OK:
                break
        status = end_step(s, status, niter, resid, e_fluid, e_damp, e_fric, e_act)
        if status != OK:
            break
    # every sub-step, done or failed, leaves the edges of q in geo (its last residual's, or
    # the symplectic sub-step's own), and so does every state written from outside
    ledger_energies(s, True)
    return status


@njit(cache=True, inline="always", error_model="numpy")
def end_step(s, status, niter, resid, e_fluid, e_damp, e_fric, e_act):
    """Close a step of ``h``: check the state (unless it failed already) and record the step in ``out``.

    Takes the step's status, Newton iterations, residual and energies [J]; returns the status.
    """
    q, v, lbar, prm, buf, ibuf, out = s.q, s.v, s.lbar, s.prm, s.buf, s.ibuf, s.out
    h = prm[P_H]
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
    return status
