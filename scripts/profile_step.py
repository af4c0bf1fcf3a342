"""Where a robot step's time goes: the compiled parts of one SoftEel-v0 step, timed inside numba.

Drives 64 batched eels with uniform random actions (an untrained policy, the benchmark's
load) and with the thesis gait, counts Newton iterations per step, compares the water's
integrators (CPU time per robot step of the batched env on one thread, interleaved rounds in
this process), then times each kernel of the step on a representative state in a compiled
loop (no Python dispatch), and the Python side of ``gym.make("SoftEel-v0").step`` with cProfile.

    python scripts/profile_step.py
"""

from __future__ import annotations

import cProfile
import io
import math
import pstats
import time

import gymnasium as gym
import numpy as np
from count_instructions import _loop_copy, _loop_factor  # scripts/ is on the path of a script
from numba import njit

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.envs import observe
from soft_snake_gym.envs import task as T
from soft_snake_gym.gaits import serpenoid, serpenoid_phase
from soft_snake_gym.physics import forces, layout, stepper
from soft_snake_gym.physics.layout import SimArrays


@njit
def _loop_residual(k, sa, jac):
    s = 0.0
    for _ in range(k):
        s += stepper._be_residual(sa, 0.01, layout.MEDIUM_WATER, jac)[0]
    return s


@njit
def _loop_check(k, q, v, kbar, lbar, uk, ul, prm, buf, ibuf):
    s = 0.0
    for _ in range(k):
        s += stepper.check_state(q, v, lbar, prm, buf, ibuf) + forces.actuator_power(
            q, kbar, lbar, uk, ul, prm
        )
    return s


@njit
def _loop_observe(k, q, v, kbar, w, low, high, raw, obs):
    s = 0.0
    for _ in range(k):
        s += observe.swim_observation(q, v, kbar, w, 0.0, low, high, raw, obs)
    return s


@njit
def _loop_step(k, A, sa, ta):
    for s in range(k):
        ta.act[:] = A[s % A.shape[0]]
        T.robot_step(sa, ta)


def _us(fn, *args, k=20000) -> float:
    fn(10, *args)
    start = time.perf_counter()
    fn(k, *args)
    return (time.perf_counter() - start) / k * 1e6


def newton_iterations(actions: str, robots: int = 64, steps: int = 300) -> np.ndarray:
    """Fraction of robot steps taking 0, 1, 2, ... Newton iterations, under random or gait actions."""
    venv = gym.make_vec("SoftEel-v0", num_envs=robots, num_threads=1)
    venv.reset(seed=0)
    if actions == "random":
        A = np.random.default_rng(0).uniform(-1, 1, (steps, robots, 8)).astype(np.float32)
    else:
        n, omega, alpha = 8, 2 * math.pi / 3, math.pi / 6
        t = (np.arange(steps) + 0.5) * 0.01
        r = np.array([serpenoid(serpenoid_phase(ti, n, omega, 2 * math.pi / n), omega, alpha)[1] for ti in t])
        A = np.repeat((r / (2 * math.pi))[:, None, :], robots, axis=1).astype(np.float32)
    its = [venv.step(a)[4]["newton_iterations"] for a in A]
    return np.bincount(np.concatenate(its), minlength=6) / (steps * robots)


def method_costs(methods=("sdirk2", "bdf2", "backward_euler"), robots=64, steps=150, rounds=11) -> None:
    """Print CPU microseconds per robot step and Newton iterations per step of each water integrator.

    64 batched eels on one thread under the same uniform random actions, each round from the
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

    env = gym.make("SoftEel-v0")
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    for a in rng.uniform(-1, 1, (30, 8)).astype(np.float32):
        env.step(a)
    u = env.unwrapped
    sa = SimArrays(*(a.copy() for a in u.sim.arrays))
    q, v, kbar, lbar, prm, buf, J, ibuf, out = sa[:9]  # the named arrays (sa.f is their block)
    _loop_residual(1, sa, True)  # a Jacobian to factor
    piv = ibuf[layout.I_PIV].copy()
    Jw, b, bw = np.empty_like(J), np.ones(q.size), np.empty(q.size)
    A = rng.uniform(-1, 1, (64, 8))
    parts = {
        "whole robot_step (random actions)": _us(
            _loop_step,
            A,
            SimArrays(*(a.copy() for a in sa)),
            type(u.task)(*(a.copy() for a in u.task)),
            k=5000,
        ),
        "residual + Jacobian (assemble, drag, added mass)": _us(
            _loop_residual, SimArrays(*(a.copy() for a in sa)), True
        ),
        "residual only (line-search trial)": _us(_loop_residual, SimArrays(*(a.copy() for a in sa)), False),
        "banded factor + solve (2N = 20, KL = KU = 5)": _us(_loop_factor, J, Jw, piv, b, bw)
        - _us(_loop_copy, J, Jw, b, bw),
        "state check + actuator power": _us(
            _loop_check, q, v, kbar, lbar, u.task.uk, u.task.ul, prm, buf.copy(), ibuf.copy()
        ),
        "observation (kappa, kappa_dot, kbar, body velocity)": _us(
            _loop_observe, q, v, kbar, u.task.w, u.task.low, u.task.high, u.task.raw.copy(), u.task.obs.copy()
        ),
    }
    print("\nCompiled parts, microseconds per call (in a compiled loop, no dispatch):")
    for name, us in parts.items():
        print(f"  {name:<55} {us:7.2f}")

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
