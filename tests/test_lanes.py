"""Sixteen eels per instruction (``physics.lanes``): every lane bit for bit what the scalar kernels give.

The block's residual, factorization, solve and Newton solve against ``_be_residual``,
``band_factor``, ``band_solve`` and ``_be_newton`` on the same robots, with lanes that differ in
their physics (damping on and off, stiffness, density), lanes that leave the common path, and
counts that show the block itself solved the lanes it says it did.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numba import njit

from soft_snake_gym import Fluid, Integrator, Rod, SimConfig
from soft_snake_gym.envs import SoftVectorEnv
from soft_snake_gym.envs import task as T
from soft_snake_gym.physics import banded, lanes, stepper
from soft_snake_gym.physics import layout as L
from soft_snake_gym.physics.layout import SimArrays

LANES = lanes.LANES
DT = stepper.GAMMA * 0.01  # SDIRK2's stage at the default h


def _eels(seed: int, steps: int = 30, method: str = "auto") -> SoftVectorEnv:
    """16 eels of different physics after ``steps`` random actions, on the integrator ``method``.

    Lanes 0-3 without any damping, half the others with stretching damping too.
    """
    venv = SoftVectorEnv(
        "SoftEel-v0", LANES, num_threads=1, max_episode_steps=None, integrator={"method": method}
    )
    venv.reset(seed=seed)
    for i, sim in enumerate(venv.batch.sims):
        damped = i >= 4
        rod = Rod(
            E_bend=1e5 * (1 + i % 5),
            damping_bend=0.5 * (1 + i % 3) if damped else 0.0,
            damping_stretch=20.0 * (i % 2) if damped else 0.0,
        )
        sim.set_config(
            SimConfig(fluid=Fluid(rho=900 + 20 * i), rod=rod, integrator=Integrator(method=method))
        )
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        venv.advance(rng.uniform(-1, 1, (LANES, 8)), np.ones(LANES, dtype=bool))
    return venv


@njit
def _start_stages(s, t, stage):
    """Every robot's action to rates and the start of SDIRK2 stage ``stage`` (as robot_step does)."""
    s, t = SimArrays(*s), T.TaskArrays(*t)
    for i in range(s.q.shape[0]):
        si, ti = T._robot(s, t, i)
        T.step_begin(si, ti)
        stepper.sdirk2_stage_start(si, stage, si.prm[L.P_H], L.MEDIUM_WATER, ti.uk, ti.ul)


@njit
def _scalar_residuals(s, dt, jac, res):
    s = SimArrays(*s)
    for i in range(s.q.shape[0]):
        r = stepper._be_residual(L.sim_views(s.f[i], s.ibuf[i]), dt, L.MEDIUM_WATER, jac)
        res[0, i], res[1, i], res[2, i] = r[0], r[1], r[2]


@njit
def _taken(s, uk):
    """The first LANES robots of ``s`` (inputs ``uk``) taken into a new block: (block, parameters).

    With the stage's start (``q0``, ``p0``, ``vstep``), which ``lanes.take`` leaves to
    ``lanes.stage_start``: here the stages were started robot by robot.
    """
    x = lanes.allocate(s.q.shape[1])
    x.J[:] = np.nan  # the band as no residual leaves it: one with its Jacobian writes every entry
    p = np.empty((lanes.N_LANE_PRM, LANES))
    lanes.take(s, uk, 0, x, p)
    for r in range(LANES):
        for k in range(s.q.shape[1]):
            x.q0[k * LANES + r] = s.buf[r, L.B_Q0, k]
            x.p0[k * LANES + r] = s.buf[r, L.B_P0, k]
            x.vstep[k * LANES + r] = s.buf[r, L.B_VSTEP, k]
    return x, p


@njit
def _block_residuals(s, uk, dt, jac, res):
    s = SimArrays(*s)
    x, p = _taken(s, uk)
    lanes.residual(x, p, dt, jac, res)
    return x


@njit
def _scalar_newton(s, dt, result):
    s = SimArrays(*s)
    for i in range(s.q.shape[0]):
        r = stepper._be_newton(L.sim_views(s.f[i], s.ibuf[i]), dt, L.MEDIUM_WATER)
        result[0, i], result[1, i], result[2, i], result[3, i], result[4, i] = r


@njit
def _block_newton(s, uk, go, dt, result):
    """The stages' start taken into a block, solved there, and the lanes that ran put back."""
    s = SimArrays(*s)
    x, p = _taken(s, uk)
    solved = lanes.newton(s, 0, go, x, p, dt, result)
    for r in range(LANES):
        if go[r]:
            lanes.put(s, r, x, r, x.v)
    return solved


def _newton_both_ways(sim, uk, go):
    """The stages set up in ``sim`` solved by ``_be_newton`` robot by robot, then from the same start by the block.

    Asserts that every lane with ``go`` ends bit for bit as ``_be_newton`` leaves it (its
    results, ``q``, ``v``, ``out`` and ``buf``'s rows); ``sim`` is left as the block leaves it.
    Returns ``_be_newton``'s results and how many lanes the block solved itself.
    """
    f0, i0 = sim.f.copy(), sim.ibuf.copy()
    want = np.empty((5, LANES))
    _scalar_newton(tuple(sim), DT, want)
    ref = L.sim_arrays_over(sim.f.copy(), i0)
    sim.f[:], sim.ibuf[:] = f0, i0
    got = np.empty((5, LANES))
    solved = _block_newton(tuple(sim), uk, go, DT, got)
    assert np.array_equal(_bits(got[:, go]), _bits(want[:, go]))
    for name in ("q", "v", "out"):
        assert np.array_equal(_bits(getattr(sim, name)[go]), _bits(getattr(ref, name)[go])), name
    for row in (L.B_F, L.B_R, L.B_A, L.B_Q0, L.B_V0, L.B_P0):
        assert np.array_equal(_bits(sim.buf[go, row]), _bits(ref.buf[go, row]))
    return want, solved


def _flat(a: np.ndarray) -> np.ndarray:
    """(LANES, ...) -> the block's flat layout, element i of lane r at i * LANES + r."""
    return np.ascontiguousarray(a.reshape(LANES, -1).T).ravel()


def _unflat(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return a.reshape(-1, LANES).T.reshape(shape)


def _bits(a: np.ndarray, any_nan: bool = False) -> np.ndarray:
    """The bit patterns (signed zeros told apart); with ``any_nan``, every NaN as one pattern."""
    a = np.ascontiguousarray(a)
    if any_nan and a.dtype.kind == "f":
        a = np.where(np.isnan(a), np.nan, a).astype(a.dtype)
    return a.view(f"u{a.itemsize}")


@pytest.mark.parametrize("jac", [False, True])
def test_the_block_residual_is_be_residual_bit_for_bit(jac):
    venv = _eels(seed=1)
    sim, task = venv.batch.sim, venv.batch.task
    _start_stages(tuple(sim), tuple(task), 0)
    f0 = sim.f.copy()
    res = np.empty((3, LANES))
    _scalar_residuals(tuple(sim), DT, jac, res)
    ref = L.sim_arrays_over(sim.f.copy(), sim.ibuf)
    sim.f[:] = f0
    res_b = np.empty((3, LANES))
    x = _block_residuals(tuple(sim), task.uk, DT, jac, res_b)
    q, F, R, A, J = x.q, x.F, x.R, x.A, x.J
    assert np.array_equal(_bits(res_b), _bits(res))  # |R|^2, max |R|/m, drag power
    for flat, want in ((q, ref.q), (F, ref.buf[:, L.B_F]), (R, ref.buf[:, L.B_R]), (A, ref.buf[:, L.B_A])):
        assert np.array_equal(_bits(_unflat(flat, want.shape)), _bits(want))
    if jac:  # the block's band rows hold the entries a factorization without row exchanges uses
        band = ref.J[:, :, : lanes.BAND]
        assert np.array_equal(_bits(_unflat(J, band.shape)), _bits(band))
        assert not ref.J[:, :, lanes.BAND :].any()
    assert np.unique(ref.prm[:, L.P_DBEND]).size > 2  # the lanes' damping really differs


def test_the_block_factor_and_solve_are_band_factor_and_band_solve_bit_for_bit():
    """On the eels' backward-Euler bands, and on one lane that needs a row exchange (flagged)."""
    venv = _eels(seed=2)
    sim = venv.batch.sim
    _start_stages(tuple(sim), tuple(venv.batch.task), 0)
    _scalar_residuals(tuple(sim), DT, True, np.empty((3, LANES)))
    bands = np.array(sim.J)
    n = bands.shape[1]
    below = max(abs(bands[5, e, banded.KL - e]) for e in range(1, banded.KL + 1))
    bands[5, 0, banded.KL] = 0.01 * below  # lane 5's first pivot far below an entry under it
    rng = np.random.default_rng(0)
    b = rng.standard_normal((LANES, n))
    J_ref, b_ref, piv = bands.copy(), b.copy(), np.zeros((LANES, n), dtype=np.int64)
    for r in range(LANES):
        assert banded.band_factor(J_ref[r], piv[r], n, banded.PIVOT_THRESHOLD)
        banded.band_solve(J_ref[r], piv[r], n, b_ref[r])
    J_flat, b_flat, kept = _flat(bands[:, :, : lanes.BAND]), _flat(b), np.zeros(LANES, dtype=np.bool_)
    lanes.factor(J_flat, kept, n)
    lanes.solve(J_flat, b_flat, n)
    exchanged = (piv != np.arange(n)).any(axis=1)
    assert exchanged.tolist() == [r == 5 for r in range(LANES)]
    assert kept.tolist() == (~exchanged).tolist()
    ok = ~exchanged
    band = J_ref[:, :, : lanes.BAND]
    assert np.array_equal(_bits(_unflat(J_flat, band.shape)[ok]), _bits(band[ok]))
    assert not J_ref[ok][:, :, lanes.BAND :].any()  # no fill-in where no row moved
    assert np.array_equal(_bits(_unflat(b_flat, b.shape)[ok]), _bits(b_ref[ok]))


@pytest.mark.parametrize("stage", [0, 1])
def test_the_block_newton_leaves_every_robot_as_be_newton(stage):
    """Both SDIRK2 stages, with lanes off the common path.

    Lane 7 starts with a NaN velocity, lane 9 with a Newton cap of one iteration, lane 11 renews
    its Jacobian (no chord steps, a tolerance one step cannot meet), lane 13 sits out: they go
    to ``_be_newton`` or stay put; the block solves the rest.
    """
    venv = _eels(seed=3)
    sim, task = venv.batch.sim, venv.batch.task
    if stage == 1:  # the first stage solved, robot by robot
        _start_stages(tuple(sim), tuple(task), 0)
        _scalar_newton(tuple(sim), DT, np.empty((5, LANES)))
    sim.prm[9, L.P_MAXIT] = 1
    sim.prm[11, L.P_CHORD] = 0.0
    sim.prm[11, L.P_TOL] = 1e-14
    go = np.ones(LANES, dtype=np.bool_)
    go[13] = False
    if stage == 0:
        _start_stages(tuple(sim), tuple(task), 0)
    else:
        for i in range(LANES):
            stepper._sdirk2_second_start(venv.batch.sims[i].arrays, L.MEDIUM_WATER)
    sim.v[7, 4] = np.nan
    f0 = sim.f.copy()
    want, solved = _newton_both_ways(sim, task.uk, go)
    assert np.array_equal(_bits(sim.f[13]), _bits(f0[13]))  # the lane that sat out is untouched
    assert want[0, 7] == L.NOT_CONVERGED and want[1, 11] > 1  # those lanes really left the path
    assert solved == LANES - 4  # ... and the block solved all the others itself


def test_the_block_takes_as_many_chord_steps_as_be_newton_up_to_its_cap():
    """First guesses off by about 0.05 m/s, tolerances from 1e-6 to 1e-12: stages of two to five iterations.

    ``_be_newton`` takes chord steps while the residual contracts by at least the chord rate
    (0.5) a step; the block follows it for up to ``CHORD_STEPS`` of them, every lane bit for
    bit, and sends the lanes that need more (or a new Jacobian) to ``_be_newton``.
    """
    venv = _eels(seed=5)
    sim, task = venv.batch.sim, venv.batch.task
    _start_stages(tuple(sim), tuple(task), 0)
    sim.prm[:, L.P_CHORD] = 0.5
    sim.prm[:, L.P_TOL] = np.geomspace(1e-6, 1e-12, LANES)
    sim.v[:] += 0.05 * np.random.default_rng(1).standard_normal(sim.v.shape)
    sim.out[:, L.O_NJAC] = sim.out[:, L.O_NRES] = 0.0
    want, solved = _newton_both_ways(sim, task.uk, np.ones(LANES, dtype=np.bool_))
    # the stages _be_newton solved on the common path: one Jacobian, every iteration's residual
    iterations = want[1].astype(int)
    common = (sim.out[:, L.O_NJAC] == 1) & (sim.out[:, L.O_NRES] == iterations) & (want[0] == L.OK)
    in_block = common & (iterations <= lanes.CHORD_STEPS + 1)
    assert {2, 3, 4} <= set(iterations[in_block].tolist())  # one, two and three chord steps
    assert (common & (iterations > lanes.CHORD_STEPS + 1)).any()  # more than the block takes
    assert solved == in_block.sum()  # the block itself solved exactly those


def test_units_cover_every_robot_once_with_a_tail_block_from_tail_min():
    """``batch_step``'s units: full blocks, then the robots left a block of their own from ``TAIL_MIN`` on."""
    for n in range(1, 3 * LANES + 1):
        units = T.units(n)
        firsts = [T.first_robot(u, n) for u in range(units + 1)]
        sizes = [b - a for a, b in zip(firsts, firsts[1:], strict=False)]
        assert firsts[0] == 0 and firsts[-1] == n
        rest = n % LANES
        tail = [rest] if rest >= T.TAIL_MIN else [1] * rest
        assert sizes == [LANES] * (n // LANES) + tail, n


@pytest.mark.parametrize(("rest", "seed"), [(3, 7), (9, 11)])
def test_the_vector_env_steps_blocks_and_leftovers_as_single_envs_with_two_threads(rest, seed):
    """Eels in two blocks and three one by one, or a tail block of nine, against the same eels robot by robot.

    With nine, eels of the tail block fail (seed 11: eels 39 and 40), and their lanes idle after.
    """
    n = 2 * LANES + rest
    actions = np.random.default_rng(seed).uniform(-1, 1, (60, n, 8))

    def eels():
        venv = SoftVectorEnv("SoftEel-v0", n, num_threads=2, max_episode_steps=None, max_curvature_rate=30.0)
        venv.reset(seed=4)
        return venv

    status = _blocks_against_robot_step(eels, actions, threads=2)
    assert (status == L.OK).sum() > n // 2 and (status != L.OK).any()  # most swim, some fail
    if rest >= T.TAIL_MIN:
        assert (status[2 * LANES :] != L.OK).any()  # some in the tail block


def test_robots_that_fail_inside_a_block_step_end_as_robot_step_leaves_them():
    """A block with lanes whose stage solves fail or leave the common path, over two sub-steps.

    Lane 7 starts with a NaN velocity (its first stage fails), lane 9 may take one Newton
    iteration (it fails where one is not enough), lane 11 renews its Jacobian: ``_be_newton``
    solves them on their robots' arrays, the block takes them back, and puts a failed lane back
    at once. The failed robots are not stepped again: in the later steps their lanes idle in the
    block. Every robot's state and status against ``robot_step``.
    """

    def eels():
        venv = _eels(seed=6)
        sim = venv.batch.sim
        sim.prm[:, L.P_SUBSTEPS] = 2
        sim.prm[9, L.P_MAXIT] = 1
        sim.prm[11, L.P_CHORD] = 0.0
        sim.v[7, 4] = np.nan
        return venv

    status = _blocks_against_robot_step(
        eels, np.random.default_rng(8).uniform(-1, 1, (4, LANES, 8)), threads=1
    )
    assert status[7] == L.NON_FINITE and status[9] == L.NOT_CONVERGED  # they failed in a stage
    assert (status == L.OK).sum() == LANES - 2


def test_a_bdf2_block_leaves_every_robot_as_robot_step():
    """BDF2's one stage a sub-step in a block of sixteen eels, over two sub-steps a step.

    Lanes with and without damping; lane 3 without a history (a fresh state: it takes its
    SDIRK2 step alone, then joins the block), lane 7 with a NaN velocity (it fails), lane 9 with
    a Newton cap of one iteration, lane 11 renewing its Jacobian (both leave the common path).
    """

    def eels():
        venv = _eels(seed=9, method="bdf2")
        sim = venv.batch.sim
        assert not np.isnan(sim.buf[:, L.B_QPREV, 0]).any()  # every eel has its history
        sim.prm[:, L.P_SUBSTEPS] = 2
        sim.buf[3, L.B_QPREV] = np.nan
        sim.prm[9, L.P_MAXIT] = 1
        sim.prm[11, L.P_CHORD] = 0.0
        sim.v[7, 4] = np.nan
        return venv

    venv = eels()
    batch = venv.batch
    assert all(T.block_eligible(batch.sim.prm[i], batch.task.tp[i]) for i in range(LANES))  # one block
    status = _blocks_against_robot_step(
        eels, np.random.default_rng(10).uniform(-1, 1, (4, LANES, 8)), threads=1
    )
    assert status[7] == L.NON_FINITE and status[9] == L.NOT_CONVERGED
    assert (status == L.OK).sum() == LANES - 2


def test_eight_bdf2_eels_step_as_a_tail_block_as_robot_step_leaves_them():
    """PPO's eight envs under BDF2: one tail block, its lanes past the eighth idle, some eels failing."""

    def eels():
        venv = SoftVectorEnv(
            "SoftEel-v0", 8, max_episode_steps=None, max_curvature_rate=30.0, integrator={"method": "bdf2"}
        )
        venv.reset(seed=3)
        assert T.units(8) == 1  # one block of eight, not eight robots one by one
        return venv

    status = _blocks_against_robot_step(
        eels, np.random.default_rng(12).uniform(-1, 1, (200, 8, 8)), threads=1
    )
    assert (status == L.OK).sum() >= 4 and (status != L.OK).any()  # most swim, some fail


def _blocks_against_robot_step(make, actions: np.ndarray, threads: int, any_nan: bool = False) -> np.ndarray:
    """Step the robots of ``make()`` through ``actions`` by ``batch_step`` and robot by robot.

    Asserts that every array (but Newton's scratch) and every status end bit for bit the same
    (with ``any_nan``, a NaN's sign and payload aside); returns the statuses.
    """
    runs = []
    for blocks in (True, False):
        venv = make()
        sim, task = venv.batch.sim, venv.batch.task
        status = np.zeros(venv.num_envs, dtype=np.int64)
        for a in actions:
            task.act[:] = a
            active = status == L.OK
            if blocks:
                T.batch_step(active, tuple(sim), tuple(task), status, threads)
            else:
                _robot_by_robot(active, tuple(sim), tuple(task), status)
        runs.append((_state(sim, task), status.copy()))
    (a, status_a), (b, status_b) = runs
    assert all(np.array_equal(_bits(x, any_nan), _bits(y, any_nan)) for x, y in zip(a, b, strict=True))
    assert np.array_equal(status_a, status_b)
    return status_a


_KEPT_ROWS = [k for k in range(L.N_BUF) if k not in (L.B_VACC, L.B_DV, *lanes.STAGE_ROWS)]
"""``buf``'s rows that a step's result holds: all but its work (Newton's trial and step, ``lanes.STAGE_ROWS``)."""


def _state(sim, task) -> list[np.ndarray]:
    """Copies of a batch's arrays, all but the stages' work (Newton's band and ``buf``'s rows not in ``_KEPT_ROWS``)."""
    s = L.sim_arrays_over(sim.f.copy(), sim.ibuf)
    return [
        np.array(a) for a in (s.q, s.v, s.kbar, s.lbar, s.prm, s.out, s.buf[:, _KEPT_ROWS], task.f, task.obs)
    ]


@njit
def _robot_by_robot(active, s, t, status):
    s, t = SimArrays(*s), T.TaskArrays(*t)
    for i in range(status.size):
        if active[i]:
            si, ti = T._robot(s, t, i)
            status[i] = T.robot_step(si, ti)


# --- the ground: each lane a worker (lanes.crawl) ------------------------------------------------


def _worms(seed: int, steps: int = 40) -> SoftVectorEnv:
    """16 worms of different physics after ``steps`` random actions (the last half small), some nodes at rest.

    Lanes 0-3 without stretching damping, the friction and stiffness differ from lane to lane.
    """
    venv = SoftVectorEnv("SoftWorm-v0", LANES, num_threads=1, max_episode_steps=None)
    venv.reset(seed=seed)
    for i, sim in enumerate(venv.batch.sims):
        c = sim.config
        rod = dataclasses.replace(
            c.rod, damping_stretch=0.0 if i < 4 else 5.0 * (1 + i % 3), E=c.rod.E * (1 + 0.1 * (i % 5))
        )
        ground = dataclasses.replace(c.ground, mu_s=1.0 + 0.02 * i, mu_d=0.5 + 0.02 * i)
        sim.set_config(dataclasses.replace(c, rod=rod, ground=ground))
    rng = np.random.default_rng(seed)
    for k in range(steps):  # 9 edges' rates; gentler toward the end, so that some nodes come to rest
        venv.advance(
            rng.uniform(-1, 1, (LANES, 9)) * (1.0 if k < steps // 2 else 0.1), np.ones(LANES, dtype=bool)
        )
    return venv


@njit
def _ground_starts(s, t):
    """Every worm's action to rates, its rest shape moved and its implicit step set up (as simulate does)."""
    s, t = SimArrays(*s), T.TaskArrays(*t)
    for i in range(s.q.shape[0]):
        si, ti = T._robot(s, t, i)
        T.step_begin(si, ti)
        si.buf[L.B_LRATE, : si.lbar.size] = (
            ti.ul if si.prm[L.P_LAG] == 0.0 else si.buf[L.B_LRATE, : si.lbar.size]
        )
        stepper.move_rest_shape(si, ti.uk, ti.ul, si.prm[L.P_H])
        stepper._be_start(si, L.MEDIUM_GROUND, 1.0)


@njit
def _ground_block(s, dt):
    """The worms' steps set up, taken into the lanes of a new block and their residuals made there."""
    s = SimArrays(*s)
    x = lanes.allocate(s.q.shape[1])
    p = np.empty((lanes.N_LANE_PRM, LANES))
    wi = np.zeros((lanes.N_WORK_INT, LANES), dtype=np.int64)
    for r in range(LANES):
        si = L.sim_views(s.f[r], s.ibuf[r])
        lanes._start_solve(si, x, p, r)
        lanes._await(si, x, wi, r, lanes._POINT, True)  # as a sub-step's start awaits its first residual
    x.J[:] = np.nan  # as in _taken: the residual writes every entry of the band
    lanes.ground_residual(x, p, dt, x.res)
    return x


@njit
def _ground_residuals(s, dt, res):
    s = SimArrays(*s)
    for i in range(s.q.shape[0]):
        r = stepper._be_residual(L.sim_views(s.f[i], s.ibuf[i]), dt, L.MEDIUM_GROUND, True)
        res[0, i], res[1, i], res[2, i] = r[0], r[1], r[3]


def test_the_ground_residual_is_be_residual_on_the_ground_bit_for_bit():
    """Friction on the sliding nodes, held rows on the stuck ones, with its Jacobian."""
    venv = _worms(seed=1)
    sim, task = venv.batch.sim, venv.batch.task
    _ground_starts(tuple(sim), tuple(task))
    held = sim.ibuf[:, L.I_FRICTION, : sim.q.shape[1] // 2] == L.STUCK
    assert held.any(axis=1).sum() >= 4 and not held.all()  # lanes with nodes held, and sliding ones
    dt = 0.01
    x = _ground_block(tuple(sim), dt)
    res = np.empty((3, LANES))
    _ground_residuals(tuple(sim), dt, res)
    assert np.array_equal(_bits(x.res), _bits(res))  # |R|^2, max |R|/m, friction power
    ref = L.sim_arrays_over(sim.f, sim.ibuf)
    for flat, want in (
        (x.q, ref.q),
        (x.F, ref.buf[:, L.B_F]),
        (x.R, ref.buf[:, L.B_R]),
        (x.A, ref.buf[:, L.B_A]),
    ):
        assert np.array_equal(_bits(_unflat(flat, want.shape)), _bits(want))
    band = ref.J[:, :, : lanes.BAND]
    assert np.array_equal(_bits(_unflat(x.J, band.shape)), _bits(band))
    assert not ref.J[:, :, lanes.BAND :].any()


def test_a_worm_lane_whose_factors_would_exchange_rows_takes_band_factors_step():
    """Where the block's factorization would exchange rows, the lane's step is ``band_factor``'s own."""
    venv = _worms(seed=2)
    sim = venv.batch.sim
    _ground_starts(tuple(sim), tuple(venv.batch.task))
    x = _ground_block(tuple(sim), 0.01)
    r = 5
    x.J[lanes._jx(0, banded.KL, r)] *= 1e-3  # its first pivot far below the entries under it
    lanes.factor(x.J, x.kept, 20)
    assert x.kept.tolist() == [i != r for i in range(LANES)]
    ref = L.sim_arrays_over(sim.f[r].copy(), sim.ibuf[r].copy())  # _be_newton's step on a copy
    stepper._be_residual(ref, 0.01, L.MEDIUM_GROUND, True)
    piv, dv = np.zeros(20, dtype=np.int64), -ref.buf[L.B_R]
    assert banded.band_factor(ref.J, piv, 20, banded.PIVOT_THRESHOLD)
    banded.band_solve(ref.J, piv, 20, dv)
    si = venv.batch.sims[r].arrays
    njac = si.out[L.O_NJAC]
    assert _newton_step(si, x, r)
    assert si.out[L.O_NJAC] == njac  # the band made again is not counted: the lane's residual was
    assert np.array_equal(_bits(si.buf[L.B_DV]), _bits(dv)) and np.array_equal(si.buf[L.B_VACC], si.v)


@njit
def _newton_step(si, x, r):
    return lanes._newton_step(si, x, 0.01, r, False)


def test_worms_that_fail_inside_the_lanes_end_as_robot_step_leaves_them():
    """Worms over two sub-steps, 67 of them in 16 lanes, some failing.

    Robot 7 starts with a NaN velocity, robot 9 may take one Newton iteration, robot 11 has
    another step length (it goes robot by robot). Every robot's state and status against
    ``robot_step``, but for the sign and payload of robot 7's NaN diagnostics: the vector code
    may take a product's operands in the other order, and with two NaNs the first one's bits win.
    """
    n = T.CRAWL_MIN + 3

    def worms():
        venv = SoftVectorEnv("SoftWorm-v0", n, num_threads=1, max_episode_steps=None)
        venv.reset(seed=6)
        sim = venv.batch.sim
        sim.prm[:, L.P_SUBSTEPS] = 2
        sim.prm[9, L.P_MAXIT] = 1
        sim.prm[11, L.P_H] = 0.005
        sim.v[7, 4] = np.nan
        return venv

    status = _blocks_against_robot_step(
        worms, np.random.default_rng(8).uniform(-1, 1, (6, n, 9)), threads=1, any_nan=True
    )
    assert status[7] == L.NON_FINITE and status[9] == L.NOT_CONVERGED
    assert (status == L.OK).sum() == n - 2


def test_worms_in_lanes_on_two_threads_are_worms_robot_by_robot():
    """163 worms on two threads, each thread's share (96 and 67) in its lanes."""
    n = 10 * LANES + 3
    actions = np.random.default_rng(9).uniform(-1, 1, (20, n, 9))

    def worms():
        venv = SoftVectorEnv("SoftWorm-v0", n, num_threads=2, max_episode_steps=None)
        venv.reset(seed=4)
        return venv

    status = _blocks_against_robot_step(worms, actions, threads=2)
    assert (status == L.OK).all()


@njit
def _crawl(s, uk, ul, nsteps, status):
    s = SimArrays(*s)
    x = lanes.allocate(s.q.shape[1])
    p = np.empty((lanes.N_LANE_PRM, LANES))
    wi = np.empty((lanes.N_WORK_INT, LANES), dtype=np.int64)
    wf = np.empty((lanes.N_WORK, LANES))
    lanes.crawl(s, uk, ul, np.arange(s.q.shape[0]), nsteps, status, x, p, wi, wf)


def test_worms_whose_jobs_end_before_their_first_residual_hand_their_lanes_on():
    """Rest lengths driven below zero in the first sub-step: the job ends before any residual.

    Three of 20 worms (two in the first sixteen lanes, one taken later) get rates that no rest
    length survives; the lanes go on to the next worms. Every worm ends as ``stepper.simulate``
    leaves it, bit for bit (but Newton's scratch, as :func:`_state`, and the pivots), with its status.
    """
    n = LANES + 4
    venv = SoftVectorEnv("SoftWorm-v0", n, num_threads=1, max_episode_steps=None)
    venv.reset(seed=3)
    sim = venv.batch.sim
    rng = np.random.default_rng(3)
    uk = rng.uniform(-1.0, 1.0, (n, sim.kbar.shape[1]))
    ul = rng.uniform(-0.05, 0.05, (n, sim.lbar.shape[1]))
    bad = [0, 5, 17]
    ul[bad] = -1e3  # m/s: through the actuators' lag, minus metres in one sub-step
    nsteps = np.full(n, 2)
    refs = [L.sim_arrays_over(sim.f[i].copy(), sim.ibuf[i].copy()) for i in range(n)]
    want = [stepper.simulate(tuple(refs[i]), uk[i], ul[i], 2) for i in range(n)]
    assert [i for i in range(n) if want[i] != L.OK] == bad
    assert all(want[i] == L.BAD_REST_LENGTH for i in bad)
    status = np.full(n, -1)
    _crawl(tuple(sim), uk, ul, nsteps, status)
    assert status.tolist() == want
    for i in range(n):
        got = L.sim_arrays_over(sim.f[i], sim.ibuf[i])
        for a, b in zip(_robot_result(got), _robot_result(refs[i]), strict=True):
            assert np.array_equal(_bits(a), _bits(b)), i


def _robot_result(a: SimArrays) -> tuple[np.ndarray, ...]:
    """One robot's arrays that a step's result holds: all but Newton's scratch (``_KEPT_ROWS``) and the pivots."""
    return (a.q, a.v, a.kbar, a.lbar, a.prm, a.out, a.buf[_KEPT_ROWS], a.ibuf[L.I_FRICTION :])
