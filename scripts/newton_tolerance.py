"""What Newton's tolerance costs and buys in water: the eels' block against ``integrator.newton_tol``.

Under random actions each SDIRK2 stage of an eel takes a Newton step and one chord step at the
default tolerance (1e-6 m/s, on the max-norm of the momentum residual over the node masses).
A block of 16 eels takes the chord step if any of its lanes needs it, so a looser tolerance
pays only where no lane of a block needs it. This script prints, per tolerance:

1. the cost: 256 eels on one thread under random actions, the compiled call's time a step
   relative to the first tolerance (interleaved rounds, medians) and the Newton iterations a
   robot step;
2. what it changes under random actions: the largest move of a centre of mass after 1.5 s of
   the same actions against the first tolerance, next to the same figure for a quarter step
   (``substeps=4``), the integrator's own error;
3. what a body at rest keeps: a body with a curved rest shape relaxing in water with damping
   (``tests/test_physics.py``'s circular arc), its largest node speed over the last 7.5 of
   15 s, where it should be at rest;
4. one step's own error: from 30 states of a random-action episode, one step against 16 steps
   of ``h/16`` at ``newton_tol=1e-9``, the median of the largest node velocity difference.

    python scripts/newton_tolerance.py
    python scripts/newton_tolerance.py --tolerances 1e-6 1e-4 1e-3 --rounds 5
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.params import Integrator, Rod, SimConfig
from soft_snake_gym.physics import Simulator
from soft_snake_gym.physics.layout import O_NITER
from soft_snake_gym.physics.simulator import body_from_curvature


def _eels(robots: int, **integrator) -> gym.vector.VectorEnv:
    venv = gym.make_vec(
        "SoftEel-v0", num_envs=robots, num_threads=1, max_episode_steps=None, integrator=integrator
    )
    venv.reset(seed=0)
    return venv


def _cost(venv, actions: np.ndarray, seconds: float) -> tuple[float, float]:
    """Compiled seconds a step and Newton iterations a robot step, over ``seconds`` of stepping.

    The iterations are averaged over all robots, so the few that an autoreset skips that step
    (an eel that crossed itself) count as 0.
    """
    u = venv.unwrapped
    u.kernel_seconds, steps, iterations = 0.0, 0, 0.0
    start = time.perf_counter()
    while steps == 0 or time.perf_counter() - start < seconds:
        for a in actions:
            venv.step(a)
            iterations += u.batch.sim.out[:, O_NITER].mean()
        steps += len(actions)
    return u.kernel_seconds / steps, iterations / steps


def _centres(robots: int, steps: int, **integrator) -> np.ndarray:
    """Centres of mass of ``robots`` eels after ``steps`` steps of random actions (seeded)."""
    venv = _eels(robots, **integrator)
    rng = np.random.default_rng(1)
    for _ in range(steps):
        _, _, terminated, _, info = venv.step(rng.uniform(-1, 1, venv.action_space.shape))
        if terminated.any():
            raise RuntimeError("an eel's episode ended; use fewer steps")
    return np.column_stack([info["x_position"], info["y_position"]])


def _speed_at_rest(tol: float) -> float:
    """Largest node speed [m/s] of a relaxing body over 7.5-15 s (it settles by 7.5 s at 1e-9)."""
    sim = Simulator(
        SimConfig(rod=Rod(N=12, damping_bend=2.0, damping_stretch=2.0), integrator=Integrator(newton_tol=tol))
    )
    kbar = np.full(10, 0.3)
    sim.reset(x=body_from_curvature(np.zeros(10), sim.lbar), kbar=kbar)
    speed = 0.0
    for k in range(1500):
        sim.step()
        if k >= 750:
            speed = max(speed, float(np.abs(sim.v).max()))
    return speed


OneStep = tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]
"""A state of item 4: the body (``reset`` options), the action, the reference's velocities after it."""


def _one_step_states(states: int = 30) -> list[OneStep]:
    """Item 4's ``states`` of a random-action episode, each with its reference step.

    The reference is 16 steps of ``h/16`` at ``newton_tol=1e-9``, made once for every tolerance.
    """
    ref = gym.make("SoftEel-v0", max_episode_steps=None, integrator={"substeps": 16, "newton_tol": 1e-9})
    ref = ref.unwrapped
    walk = gym.make("SoftEel-v0", max_episode_steps=None).unwrapped
    walk.reset(seed=3)
    rng = np.random.default_rng(5)
    out = []
    while len(out) < states:
        a = rng.uniform(-1, 1, walk.action_space.shape)
        if rng.random() < 0.1:
            s = walk.sim
            body = {"x": s.x, "v": s.v, "kbar": s.kbar, "lbar": s.lbar}
            ref.reset(seed=0, options=body)
            ref.step(a)
            out.append((body, a, ref.sim.v))
        if walk.step(a)[2]:
            walk.reset()
    return out


def _one_step_error(tol: float, states: list[OneStep]) -> float:
    """Median over ``states`` (:func:`_one_step_states`) of one step's largest node velocity error [m/s]."""
    env = gym.make("SoftEel-v0", max_episode_steps=None, integrator={"newton_tol": tol}).unwrapped
    errors = []
    for body, a, v_ref in states:
        env.reset(seed=0, options=body)
        env.step(a)
        errors.append(np.abs(env.sim.v - v_ref).max())
    return float(np.median(errors))


def main() -> None:
    """Print the four parts for each tolerance."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tolerances", type=float, nargs="+", default=[1e-6, 1e-5, 1e-4, 3e-4, 1e-3])
    p.add_argument("--robots", type=int, default=256)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--seconds", type=float, default=1.5)
    args = p.parse_args()
    if min(args.tolerances) <= 0 or args.robots < 1 or args.rounds < 1 or args.seconds <= 0:
        p.error("--tolerances must be > 0, --robots and --rounds >= 1, --seconds > 0")
    tols = args.tolerances
    envs = {tol: _eels(args.robots, newton_tol=tol) for tol in tols}
    actions = np.random.default_rng(0).uniform(-1, 1, (32,) + envs[tols[0]].action_space.shape)
    for venv in envs.values():
        _cost(venv, actions[:4], 0.0)  # compiled and warm
    rounds: dict[float, list[tuple[float, float]]] = {tol: [] for tol in tols}
    for _ in range(args.rounds):
        for tol, venv in envs.items():
            rounds[tol].append(_cost(venv, actions, args.seconds))
    centres = {tol: _centres(64, 150, newton_tol=tol) for tol in tols}
    ref = centres[tols[0]]
    quarter = np.abs(_centres(64, 150, newton_tol=tols[0], substeps=4) - ref).max()
    states = _one_step_states()
    base = statistics.median(t for t, _ in rounds[tols[0]])
    print(f"{args.robots} eels on one thread, random actions, medians of {args.rounds} rounds; "
          f"64 eels for 1.5 s: a quarter step moves a centre of mass by up to {quarter:.1e} m")  # fmt: skip
    columns = ("compiled call (x first)", "iterations/step", "centre moved [m]", "speed at rest [m/s]")
    print("newton_tol  " + "  ".join(columns) + "  one step's error [m/s]")
    for tol in tols:
        cost = statistics.median(t for t, _ in rounds[tol])
        its = statistics.median(i for _, i in rounds[tol])
        moved = np.abs(centres[tol] - ref).max()
        rest, one_step = _speed_at_rest(tol), _one_step_error(tol, states)
        print(f"{tol:9.0e}  {cost * 1e6:8.0f} us ({base / cost:4.2f}x)  {its:15.2f}  {moved:16.1e}  {rest:19.1e}  "
              f"{one_step:22.1e}")  # fmt: skip


if __name__ == "__main__":
    main()
