"""The Simulator's public API: state in and out, bad inputs, failures reported, never hidden."""

from __future__ import annotations

import ast
import math
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from soft_snake_gym import Integrator, Rod, SimConfig, SimulationError, Simulator, body_from_curvature
from soft_snake_gym.envs import task as T
from soft_snake_gym.physics import allocate_arrays, stepper
from soft_snake_gym.physics.layout import B_FEXT, B_LRATE, B_R, I_FRICTION, SLIDING, STUCK, sim_views


@pytest.mark.parametrize("heading", [0.0, 2.5])
def test_body_from_curvature_puts_the_head_ahead_along_the_heading(heading):
    kbar = np.array([0.3, -0.2, 0.1, 0.4])
    lbar = np.array([0.2, 0.18, 0.22, 0.2, 0.19])
    x = body_from_curvature(kbar, lbar, heading=heading, com=(1.0, 2.0))
    chord = x[-1] - x[0]
    assert math.atan2(chord[1], chord[0]) == pytest.approx(heading, abs=1e-12)
    w = np.array([0.5, 1, 1, 1, 1, 0.5])
    np.testing.assert_allclose(w @ x / w.sum(), [1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(np.hypot(*np.diff(x, axis=0).T), lbar)
    sim = Simulator(SimConfig(rod=Rod(N=6, edge_length=0.2)))
    sim.reset(x=x, lbar=lbar)
    np.testing.assert_allclose(sim.kappa, kbar, atol=1e-12)


def test_exact_curvature_rate_matches_a_finite_difference():
    sim = Simulator()
    rng = np.random.default_rng(3)
    sim.reset(x=body_from_curvature(rng.normal(0, 0.3, 8), sim.lbar), v=rng.normal(0, 0.2, (10, 2)))
    k0, kdot = sim.kappa, sim.kappa_dot
    eps = 1e-7
    sim.set_state(x=sim.x + eps * sim.v)
    np.testing.assert_allclose((sim.kappa - k0) / eps, kdot, rtol=1e-5, atol=1e-7)


def test_observables_and_energy_accounting():
    sim = Simulator()
    u = np.full(8, 0.5)
    for _ in range(100):
        assert sim.step(u_k=u)
    assert sim.time == pytest.approx(1.0)
    assert sim.fluid_power > 0 and sim.fluid_energy > 0
    assert sim.actuator_energy >= abs(sim.actuator_work) > 0
    np.testing.assert_allclose(sim.kbar, 0.5)
    assert sim.heading == pytest.approx(np.arctan2(*(sim.x[-1] - sim.x[0])[::-1]))
    np.testing.assert_allclose(sim.com, sim.masses @ sim.x / sim.masses.sum())
    assert 1 <= sim.newton_iterations <= 5
    sim.reset()
    assert sim.time == 0.0 and sim.fluid_energy == 0.0 and np.all(sim.kbar == 0)


@pytest.mark.parametrize("substeps", [1, 4])
def test_length_actuators_follow_the_inputs_through_an_exact_first_order_lag(substeps):
    tau, u = 0.05, np.linspace(-0.05, 0.05, 9)
    cfg = SimConfig(medium="ground", rod=Rod(length_lag=tau), integrator=Integrator(substeps=substeps))
    sim = Simulator(cfg)
    for n in range(1, 31):
        assert sim.step(u_l=u)
        t = n * sim.h  # lbar_dot = u (1 - exp(-t/tau)), integrated
        np.testing.assert_allclose(sim.lbar_dot, u * (1 - np.exp(-t / tau)), rtol=1e-12, atol=1e-15)
        expected = 0.18 + u * (t - tau * (1 - np.exp(-t / tau)))
        np.testing.assert_allclose(sim.lbar, expected, rtol=1e-12)
    # the actuators keep their rate when the command stops, and reset stops them
    rate = sim.lbar_dot
    assert sim.step(u_l=np.zeros(9))
    np.testing.assert_allclose(sim.lbar_dot, rate * np.exp(-sim.h / tau), rtol=1e-12)
    sim.reset()
    assert np.all(sim.lbar_dot == 0.0) and np.all(sim.lbar == 0.18)
    sim.set_state(lbar_dot=u)  # the lag's state, as for restoring a saved one
    assert sim.step(u_l=u)
    np.testing.assert_array_equal(sim.lbar_dot, u)
    np.testing.assert_allclose(sim.lbar, 0.18 + sim.h * u, rtol=1e-14)
    with pytest.raises(ValueError, match=r"lbar_dot has shape \(8,\); expected \(9,\)"):
        sim.set_state(lbar_dot=np.zeros(8))
    # without lag the rates are the inputs at once
    sim = Simulator(SimConfig(medium="ground", rod=Rod(length_lag=0.0)))
    assert sim.step(u_l=u)
    np.testing.assert_array_equal(sim.lbar_dot, u)
    np.testing.assert_allclose(sim.lbar, 0.18 + sim.h * u, rtol=1e-14)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"u_k": np.zeros(7)}, r"u_k has shape \(7,\); expected \(8,\)"),
        (
            {"u_k": np.array([0, 0, np.nan, 0, 0, 0, 0, 0])},
            r"u_k has non-finite entries at flat indices \[2\]",
        ),
        ({"u_l": np.zeros((9, 1))}, r"u_l has shape \(9, 1\); expected \(9,\)"),
        ({"u_l": [np.inf] + [0] * 8}, r"u_l has non-finite entries"),
    ],
)
def test_bad_inputs_raise_clear_errors(kwargs, match):
    sim = Simulator()
    x0 = sim.x
    with pytest.raises(ValueError, match=match):
        sim.step(**kwargs)
    assert np.array_equal(sim.x, x0) and sim.time == 0.0  # nothing happened


def test_simulator_over_given_arrays_uses_them_and_rejects_wrong_ones():
    stacked = allocate_arrays(10, (2,))
    sim = Simulator(arrays=stacked.row(1))
    sim.step(u_k=np.full(8, 0.5))
    assert np.array_equal(stacked.q[1], sim.x.ravel()) and not stacked.q[0].any()
    assert np.shares_memory(sim.arrays.kbar, stacked.kbar[1]) and stacked.kbar[1, 0] == pytest.approx(0.005)
    with pytest.raises(
        ValueError, match=r"arrays is SimArrays with q of shape \(2, 20\): need .* q of shape \(20,\)"
    ):
        Simulator(arrays=stacked)
    with pytest.raises(ValueError, match=r"arrays is tuple: need the SimArrays of one robot of N = 10"):
        Simulator(arrays=tuple(stacked.row(0)))


@pytest.mark.parametrize("batch", [(), (3,)])
def test_arrays_are_views_of_their_blocks_and_stay_so_when_pickled(batch):
    # the single env's compiled step takes the blocks (SimArrays.f, TaskArrays.f), Python reads the
    # named views: a copy of one without the other would let them drift apart silently
    sim = allocate_arrays(10, batch)
    task = T.allocate_task(10, 8, 25, batch, n_path=4)
    for arrays in (sim, task):
        for copy in (arrays, pickle.loads(pickle.dumps(arrays))):
            fields = [a for name, a in copy._asdict().items() if a.dtype == np.float64 and name != "f"]
            assert all(np.shares_memory(a, copy.f) for a in fields)
            copy.f[...] = 0.0
            fields[-1][..., -1] = 7.0  # the last view ends where its block ends
            assert copy.f[..., -1].tolist() == np.full(batch, 7.0).tolist()
    assert task.path.shape == batch + (4, 3) and task.obs.shape == batch + (25,)


def test_borrowed_tuples_in_compiled_code_are_the_same_arrays_member_by_member():
    # the batched step borrows its stacks and its per-thread scratch as whole (nested) tuples
    from numba import njit
    from numba.core.errors import TypingError

    from soft_snake_gym.physics.layout import borrowed

    @njit
    def mark(tup):
        sim, (a, (b, c)) = borrowed(tup)
        sim.q[0], sim.out[-1], a[0], b[1], c[2] = 1.0, 2.0, 3.0, 4.0, 5.0

    sim = allocate_arrays(4)
    a, b, c = np.zeros(3), np.zeros(3), np.zeros(3, dtype=np.int64)
    mark((sim, (a, (b, c))))  # a NamedTuple in a nested plain tuple
    assert (sim.q[0], sim.out[-1]) == (1.0, 2.0) and sim.q[1:].tolist() == [0.0] * (sim.q.size - 1)
    assert (a.tolist(), b.tolist(), c.tolist()) == ([3.0, 0, 0], [0, 4.0, 0], [0, 0, 5])
    with pytest.raises(TypingError):  # only arrays have a count to drop: anything else is refused
        njit(lambda t: borrowed(t))((a, 1))


def test_bad_state_raises_clear_errors():
    sim = Simulator()
    with pytest.raises(ValueError, match=r"x has shape \(9, 2\); expected \(10, 2\)"):
        sim.set_state(x=np.zeros((9, 2)))
    with pytest.raises(ValueError, match="lbar must be positive"):
        sim.set_state(lbar=np.zeros(9))
    with pytest.raises(ValueError, match="on top of their successors"):
        sim.set_state(x=np.zeros((10, 2)))
    with pytest.raises(ValueError, match="N = 10"):
        sim.set_config(SimConfig(rod=Rod(N=12)))


def test_reset_and_start_forget_the_last_episode():
    """A used simulator, reset or started (the envs' reset, unchecked), runs as a new one.

    The used ones stepped under length rates with an external force, so their records, force and
    rates are not zero; the new one is given the same state by ``set_state``. All three then run
    the same steps to the same bits, the records (time, energies, ledger, Newton counts) included.
    """
    rng = np.random.default_rng(4)
    kbar, lbar = rng.uniform(-0.5, 0.5, 8), rng.uniform(0.08, 0.12, 9)
    x = body_from_curvature(kbar, lbar, heading=0.3, com=(0.2, -0.1))
    v = rng.uniform(-0.01, 0.01, (10, 2))
    config = SimConfig(medium="ground", rod=Rod(length_lag=0.05))
    sims = [Simulator(config) for _ in range(3)]
    sims[0].set_state(x=x, v=v, kbar=kbar, lbar=lbar)
    for sim, how in zip(sims[1:], ("reset", "start"), strict=True):
        sim.set_external_force(np.full((10, 2), 0.01))
        for _ in range(5):
            sim.step(u_k=np.full(8, 0.3), u_l=np.full(9, 0.02))
        assert sim.arrays.out.any() and sim.arrays.buf[B_LRATE].any()
        getattr(sim, how)(x=x, v=v, kbar=kbar, lbar=lbar)
    for _ in range(20):
        for sim in sims:
            sim.step(u_k=np.full(8, -0.2), u_l=np.full(9, 0.01))
    for sim in sims[1:]:
        for name in ("q", "v", "kbar", "lbar", "out"):
            assert np.array_equal(getattr(sim.arrays, name), getattr(sims[0].arrays, name)), name
        assert not sim.arrays.buf[B_FEXT].any()
    with pytest.raises(ValueError, match="lbar must be positive"):
        sims[1].reset(x=x, lbar=-lbar)


def test_self_intersection_is_reported_and_stops_the_simulation():
    sim = Simulator()
    x = body_from_curvature(np.zeros(8), sim.lbar)
    x[4:, 1] -= 0.1
    x[4:, 0] = x[4, 0] - (x[4:, 0] - x[4, 0])  # fold the front half back across the rear half
    x[4:, 1] += np.linspace(0.2, -0.2, 6)
    sim.reset(x=x)
    assert not sim.step()
    assert sim.failure == "self_intersection"
    with pytest.raises(SimulationError, match=r"failed \(self_intersection\).*call reset\(\)"):
        sim.step()
    sim.reset()
    assert sim.step() and sim.failure is None


def test_runaway_stretch_and_bad_rest_length_are_reported():
    sim = Simulator()
    u_l = np.zeros(9)
    u_l[3] = 2000.0  # the rest length races ahead of the edge within a step, through the lag
    assert not sim.step(u_l=u_l)
    assert sim.failure == "runaway_stretch"
    sim.reset()
    assert not sim.step(u_l=np.full(9, -1000.0))
    assert sim.failure == "non_positive_rest_length"


def test_non_finite_state_and_non_convergence_are_reported():
    # an explicit step far above the stability limit blows up; with the strain guard off,
    # the state goes non-finite, and that is reported rather than stepped on
    unstable = Integrator(
        method="symplectic_euler", substeps=1, max_strain=1e300, check_self_intersection=False
    )
    sim = Simulator(SimConfig(medium="none", integrator=unstable))
    sim.reset(x=body_from_curvature(np.full(8, 0.2), sim.lbar))
    steps = 0
    while sim.step() and steps < 10_000:
        steps += 1
    assert sim.failure == "non_finite_state"
    assert not np.all(np.isfinite(sim.x))
    sim = Simulator(SimConfig(integrator=Integrator(newton_max_iter=1, newton_tol=1e-15)))
    assert not sim.step(u_k=np.full(8, 3.0))
    assert sim.failure == "newton_not_converged"


def test_chord_steps_reach_the_full_newton_step_to_the_tolerance():
    """Reusing a factorization (``newton_chord_rate``) changes the iterations, not the answer."""
    rng = np.random.default_rng(3)
    inputs = rng.uniform(-3, 3, (100, 8))  # rates that jump every step, as random actions do
    sims = [Simulator(SimConfig(integrator=Integrator(newton_chord_rate=c))) for c in (0.1, 0.0)]
    iterations = []
    for sim in sims:
        sim.reset(x=body_from_curvature(np.full(8, 0.2), sim.lbar))
        total = 0
        for u in inputs:
            assert sim.step(u_k=u), sim.failure
            total += sim.newton_iterations
        iterations.append(total)
    chord, full = sims
    assert iterations[0] > iterations[1]  # chord steps: more, cheaper iterations
    # each step converges to |R|/m <= 1e-6 m/s either way: the states agree to that order
    assert np.abs(chord.x - full.x).max() < 1e-7  # 8e-9 m here
    assert np.abs(chord.v - full.v).max() < 1e-6  # 2e-8 m/s here, on speeds of 0.2 m/s


def _work(sim, inputs, ground=False) -> np.ndarray:
    """(steps, 4): iterations, Jacobian assemblies, residuals alone, factorizations per step."""
    rows = []
    for u in inputs:
        assert sim.step(None, u) if ground else sim.step(u_k=u), sim.failure
        w = sim.newton_work
        rows.append((sim.newton_iterations, w["jacobians"], w["residuals"], w["factorizations"]))
    return np.array(rows)


def test_newton_work_counts_the_jacobians_residuals_and_factorizations_of_each_step():
    """``Simulator.newton_work`` follows Newton's structure step by step (docs/performance_history.md)."""
    rng = np.random.default_rng(3)
    inputs = rng.uniform(-3, 3, (60, 8))
    start = body_from_curvature(np.full(8, 0.2), Simulator(SimConfig()).lbar)
    work = {}
    for chord in (0.0, 0.1):
        sim = Simulator(SimConfig(integrator=Integrator(newton_chord_rate=chord)))
        sim.reset(x=start)
        work[chord] = _work(sim, inputs)
    # full Newton: every iteration assembles a Jacobian, factors it, solves and tries one step
    its, jac, res, fac = work[0.0].T
    assert (jac == its).all() and (fac == its).all() and (res == its).all()
    # chord steps: each of SDIRK2's two stages assembles and factors a Jacobian, later iterations reuse it
    its, jac, res, fac = work[0.1].T
    assert (jac >= 2).all() and (fac == jac).all() and (res == its).all()
    assert its.sum() > fac.sum()
    # on the ground every iteration factors the Jacobian its full step's trial assembled (no chord steps)
    sim = Simulator(SimConfig(medium="ground"))
    sim.reset()
    its, jac, res, fac = _work(sim, rng.uniform(-0.05, 0.05, (100, sim.N - 1)), ground=True).T
    assert (fac == its).all() and (jac >= fac).all() and its.sum() > 0
    # the explicit integrator has no Newton
    sim = Simulator(SimConfig(integrator=Integrator(method="symplectic_euler")))
    sim.reset(x=start)
    assert not _work(sim, inputs[:3]).any()


@pytest.mark.parametrize("medium", ["ground", "water"])
def test_a_residual_is_the_same_bits_with_or_without_its_jacobian(medium):
    """What lets Newton choose when to assemble a Jacobian without moving a digit of the answer.

    On the ground the full step's trial assembles it or not by a rule (not right after a cut
    full step); in water the trials never do, and an accepted iterate's residual is computed
    again with it. Either way the residual, powers and position must not depend on the choice.
    """
    rng = np.random.default_rng(5)
    sim = Simulator(SimConfig(medium=medium))
    sim.reset(x=body_from_curvature(np.full(8, 0.3), sim.lbar))
    for _ in range(30):
        assert sim.step(u_k=rng.uniform(-3, 3, 8), u_l=rng.uniform(-0.05, 0.05, 9)), sim.failure
    s = sim_views(sim.arrays.f, sim.arrays.ibuf)
    code = stepper.MEDIUM_GROUND if medium == "ground" else stepper.MEDIUM_WATER
    stepper._be_start(s, code, 1.0)
    if medium == "ground":
        assert set(s.ibuf[I_FRICTION, : sim.N].tolist()) == {SLIDING, STUCK}  # both laws in play
    s.v[:] += rng.uniform(-0.01, 0.01, s.v.size)  # an iterate off the solution
    results = []
    for jac in (False, True, False):
        results.append((stepper._be_residual(s, sim.h, code, jac), s.buf[B_R].copy(), s.q.copy()))
    for r, R, q in results[1:]:
        assert r == results[0][0] and np.array_equal(R, results[0][1]) and np.array_equal(q, results[0][2])


def test_the_kernels_run_as_python_with_numba_disabled_and_agree_with_the_compiled_ones():
    # NUMBA_DISABLE_JIT=1 is how the stepper's passes are traced (docs/performance_history.md); the
    # kernels' borrowed views (layout.borrowed, an intrinsic in compiled code) are the arrays there
    code = (
        "import numpy as np, gymnasium as gym, soft_snake_gym\n"
        "env = gym.make('SoftWorm-v0'); env.reset(seed=0)\n"
        "a = np.linspace(-0.5, 0.5, env.action_space.shape[0]).astype(np.float32)\n"
        "print(repr([env.step(a)[0].tolist() for _ in range(3)]))\n"
    )
    runs = {}
    for jit in ("0", "1"):
        env = {**os.environ, "NUMBA_DISABLE_JIT": jit}
        done = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300
        )
        assert done.returncode == 0, done.stderr[-2000:]
        runs[jit] = np.array(ast.literal_eval(done.stdout))
    np.testing.assert_allclose(runs["1"], runs["0"], rtol=1e-12, atol=1e-12)
