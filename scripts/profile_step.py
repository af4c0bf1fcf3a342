"""Where a robot step's time goes: Newton's work per step and the compiled parts, timed inside numba.

Drives 15 batched eels (fewer than a block of ``lanes.LANES``, so robot by robot: the path whose
kernels it times; the blocks' own parts are in docs/performance_history.md, "Sixteen eels per
instruction") with uniform random actions (an untrained policy, the benchmark's load) and with
the thesis gait, counts Newton iterations per step, compares the water's
integrators (CPU time per robot step of the batched env on one thread, interleaved rounds in
this process). Then, for SoftEel-v0 and SoftWorm-v0, counts Newton's work per robot step
(``Simulator.newton_work``: Jacobian assemblies, residuals alone, factorizations, and the
iterations, one solve each), times each kernel of the step on a representative state in a
compiled loop (no Python dispatch), and accounts for the compiled step: counts times costs is
Newton's share, the rest is the step's other work. Last, the Python side of
``gym.make("SoftEel-v0").step`` with cProfile.

    python scripts/profile_step.py
"""

from __future__ import annotations

import cProfile
import io
import pstats
import time

import gymnasium as gym
import numpy as np
from bench_envs import gait_actions  # scripts/ is on the path of a script
from count_instructions import _loop_copy, _loop_factor, _loop_solve
from numba import njit

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.envs import task as T
from soft_snake_gym.physics import forces, geometry, layout, stepper


@njit
def _loop_residual(k, sa, medium, jac):
    s = 0.0
    for _ in range(k):
        s += stepper._be_residual(sa, 0.01, medium, jac)[0]
    return s


@njit
def _loop_check(k, q, v, kbar, lbar, uk, ul, prm, buf, ibuf):
    s = 0.0
    for _ in range(k):
        geo = buf[layout.B_GEO : layout.B_GEO + 2]
        geometry.edge_geometry(q, geo)
        s += stepper.check_state(q, v, lbar, prm, buf, ibuf) + forces.actuator_power(
            q, kbar, lbar, uk, ul, prm, geo
        )
    return s


@njit
def _loop_observe(k, sa, ta):
    s = 0.0
    for _ in range(k):
        s += T._observe(sa, ta, False)
    return s


@njit
def _loop_step(k, A, sa, ta, f0, t0):
    """``robot_step`` through the actions ``A``, back to the blocks ``f0``, ``t0`` at each pass."""
    for s in range(k):
        j = s % A.shape[0]
        if j == 0:
            sa.f[:] = f0
            ta.f[:] = t0
        ta.act[:] = A[j]
        T.robot_step(sa, ta)


@njit
def _loop_simulate(k, UK, UL, sa, f0):
    """The physics alone: ``simulate`` with the rates ``robot_step`` made of the same actions."""
    for s in range(k):
        j = s % UK.shape[0]
        if j == 0:
            sa.f[:] = f0
        stepper.simulate(sa, UK[j], UL[j], 1)


def _us(fn, *args, k=20000) -> float:
    fn(10, *args)
    start = time.perf_counter()
    fn(k, *args)
    return (time.perf_counter() - start) / k * 1e6


def _actions(env_id: str, kind: str, steps: int, robots: int) -> np.ndarray:
    """(steps, robots, n_act) float32: uniform random in [-1, 1], or the thesis gait for every robot."""
    env = gym.make(env_id)
    if kind == "random":
        return (
            np.random.default_rng(0)
            .uniform(-1, 1, (steps, robots) + env.action_space.shape)
            .astype(np.float32)
        )
    return np.repeat(gait_actions(env, steps)[:, None, :], robots, axis=1)


ROBOTS = 15
"""Batched robots of the counts and costs: fewer than a block, so each is stepped by ``robot_step``."""


def newton_iterations(actions: str, robots: int = ROBOTS, steps: int = 300) -> np.ndarray:
    """Fraction of robot steps taking 0, 1, 2, ... Newton iterations, under random or gait actions."""
    venv = gym.make_vec("SoftEel-v0", num_envs=robots, num_threads=1)
    venv.reset(seed=0)
    its = [venv.step(a)[4]["newton_iterations"] for a in _actions("SoftEel-v0", actions, steps, robots)]
    return np.bincount(np.concatenate(its), minlength=6) / (steps * robots)


def newton_work(
    env_id: str, actions: str, robots: int = ROBOTS, steps: int = 200
) -> tuple[dict[str, float], float]:
    """Newton's work per robot step and the compiled call's wall-clock microseconds per robot step.

    ``robots`` batched robots on one thread from a seeded reset; the work is ``Simulator.newton_work``
    and the iterations (one solve each) of the robots that stepped, read after every step.
    """
    venv = gym.make_vec(env_id, num_envs=robots, num_threads=1)
    venv.reset(seed=0)
    A = _actions(env_id, actions, steps, robots)
    for a in A[:5]:  # loads the compiled code
        venv.step(a)
    venv.reset(seed=0)
    out = venv.batch.sim.out
    work = dict.fromkeys(("jacobians", "residuals", "factorizations", "solves"), 0.0)
    n, kernel = 0, venv.kernel_seconds
    for a in A:
        info = venv.step(a)[4]
        stepped = info["_forward_speed"]  # the reward terms' mask: the robots stepped (not reset)
        work["jacobians"] += out[stepped, layout.O_NJAC].sum()
        work["residuals"] += out[stepped, layout.O_NRES].sum()
        work["factorizations"] += out[stepped, layout.O_NFACTOR].sum()
        work["solves"] += info["newton_iterations"][stepped].sum()
        n += stepped.sum()
    return {k: float(v) / n for k, v in work.items()}, (venv.kernel_seconds - kernel) / n * 1e6


def compiled_parts(env_id: str) -> dict[str, float]:
    """Microseconds per call of the step's kernels, on the state after 30 random steps of ``env_id``.

    The whole step and the physics alone run 64 random actions from that state, over and over;
    each kernel runs on that one state.
    """
    env = gym.make(env_id)
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    for a in rng.uniform(-1, 1, (30,) + env.action_space.shape).astype(np.float32):
        env.step(a)
    u = env.unwrapped
    medium = int(u.sim.arrays.prm[layout.P_MEDIUM])
    n_act, n_path = u.task.act.size, u.task.path.shape[0]

    def sim():  # views of a copy of the robot's blocks, as the kernels see them
        return layout.sim_arrays_over(u.sim.arrays.f.copy(), u.sim.arrays.ibuf.copy())

    def task():
        return T.task_arrays_over(u.task.f.copy(), u.task.obs.copy(), u.N, n_act, n_path)

    sa, ta = sim(), task()
    f0, t0 = sa.f.copy(), ta.f.copy()
    A = rng.uniform(-1, 1, (64, n_act))
    UK, UL = np.empty((64, u.task.uk.size)), np.empty((64, u.task.ul.size))
    for j, a in enumerate(A):  # the rates robot_step makes of the actions, for the physics alone
        ta.act[:] = a
        assert T.robot_step(sa, ta) == layout.OK
        UK[j], UL[j] = ta.uk, ta.ul
    q, v, kbar, lbar, prm, buf, J, ibuf, out = sa[:9]  # the named arrays (sa.f is their block)
    _loop_residual(1, sa, medium, True)  # a Jacobian to factor
    piv = ibuf[layout.I_PIV].copy()
    Jw, b, bw = np.empty_like(J), np.ones(q.size), np.empty(q.size)
    copy = _us(_loop_copy, J, Jw, b, bw)
    factor_solve = _us(_loop_factor, J, Jw, piv, b, bw) - copy
    _loop_factor(1, J, Jw, piv, b, bw)  # Jw: the factors, for the solves alone
    solve = _us(_loop_solve, Jw, piv, b, bw)  # with its right-hand side's copy (20 numbers)
    return {
        "whole robot_step (random actions)": _us(_loop_step, A, sim(), task(), f0, t0, k=6400),
        "physics alone (simulate, same steps)": _us(_loop_simulate, UK, UL, sim(), f0, k=6400),
        "residual + Jacobian": _us(_loop_residual, sim(), medium, True),
        "residual alone": _us(_loop_residual, sim(), medium, False),
        "banded factorization": factor_solve - solve,
        "banded solve": solve,
        "state check + actuator power": _us(
            _loop_check, q, v, kbar, lbar, u.task.uk, u.task.ul, prm, buf.copy(), ibuf.copy()
        ),
        "observation": _us(_loop_observe, sim(), task()),
    }


def account(env_id: str) -> None:
    """Print the parts' costs, Newton's work per step, and how much of the compiled step Newton is."""
    parts = compiled_parts(env_id)
    print(f"\n{env_id}: compiled parts, microseconds per call (in a compiled loop, no dispatch):")
    for name, us in parts.items():
        print(f"  {name:<40} {us:7.2f}")
    task = parts["whole robot_step (random actions)"] - parts["physics alone (simulate, same steps)"]
    print(f"  the task's own work (rates, observation, reward, metrics): {task:.2f} us a step")
    cost = {
        "jacobians": parts["residual + Jacobian"],
        "residuals": parts["residual alone"],
        "factorizations": parts["banded factorization"],
        "solves": parts["banded solve"],
    }
    for kind in ("random", "gait"):
        work, step = newton_work(env_id, kind)
        newton = sum(work[k] * cost[k] for k in cost)
        print(f"  Newton's work per robot step, {kind} actions ({ROBOTS} robots, one thread):")
        for k in cost:
            print(f"    {k:<16} {work[k]:5.2f} x {cost[k]:5.2f} us = {work[k] * cost[k]:6.2f} us")
        print(
            f"    Newton {newton:.2f} us of the compiled step's {step:.2f} us ({100 * newton / step:.0f} %); "
            f"the rest, by difference, {step - newton:.2f} us"
        )


def method_costs(methods=("sdirk2", "bdf2", "backward_euler"), robots=ROBOTS, steps=150, rounds=11) -> None:
    """Print CPU microseconds per robot step and Newton iterations per step of each water integrator.

    ``robots`` batched eels on one thread under the same uniform random actions, each round from the
    same seeded reset; medians of ``rounds`` rounds, the methods interleaved.
    """
    venvs = {
        m: gym.make_vec("SoftEel-v0", num_envs=robots, num_threads=1, integrator={"method": m})
        for m in methods
    }
    A = np.random.default_rng(0).uniform(-1, 1, (steps, robots, 8)).astype(np.float32)
    cpu = {m: [] for m in methods}
    its = {m: 0 for m in methods}
    for _ in range(rounds + 1):  # the first round loads the compiled code
        for m, venv in venvs.items():
            venv.reset(seed=0)
            start, n = time.thread_time(), 0
            for a in A:
                n += venv.step(a)[4]["newton_iterations"].sum()
            cpu[m].append((time.thread_time() - start) / (steps * robots) * 1e6)
            its[m] = n / (steps * robots)
    base = float(np.median(cpu[methods[0]][1:]))
    print(f"\nCPU per robot step, {robots} eels on one thread, random actions (medians of {rounds} rounds):")
    for m in methods:
        us = float(np.median(cpu[m][1:]))
        print(
            f"  {m:<16} {us:6.2f} us  {its[m]:.2f} Newton iterations per step  {base / us:.2f}x {methods[0]}"
        )


def main() -> None:
    """Print the Newton-iteration histograms, the integrators' costs, the parts' times, the Python profile."""
    for kind in ("random", "gait"):
        frac = newton_iterations(kind)
        mean = float(frac @ np.arange(frac.size))
        print(
            f"Newton iterations per step, {kind} actions: mean {mean:.2f}; "
            + ", ".join(f"{i}: {100 * f:.0f} %" for i, f in enumerate(frac) if f > 0)
        )
    method_costs()

    for env_id in ("SoftEel-v0", "SoftWorm-v0"):
        account(env_id)

    env = gym.make("SoftEel-v0")
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    pr = cProfile.Profile()
    acts = rng.uniform(-1, 1, (3000, 8)).astype(np.float32)
    pr.enable()
    for a in acts:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    pr.disable()
    s = io.StringIO()
    pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(10)
    print("\ncProfile of 3000 gym.make('SoftEel-v0').step calls (tottime, top 10):")
    print("\n".join(line for line in s.getvalue().splitlines() if line.strip())[:3000])


if __name__ == "__main__":
    main()
