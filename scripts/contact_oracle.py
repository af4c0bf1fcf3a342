"""What a worm step's Newton would cost with its contacts known: the ceiling of guessing them better.

A worm step (backward Euler on the ground, docs/model.md §5) starts from a guess of its contacts
(which nodes stick, which slide) and of its velocity, and Newton's loop makes both consistent
with the end of the step: a node that turns against its slide is held, a held node pushed past
``mu_s F_N`` is released, and each change starts a new pass. This script replays the steps of
``SoftWorm-v0`` under uniform random actions (the benchmark's load) from their saved starts, each
with a different guess, and counts factorizations and residuals per step:

1. as the env steps them (a check: the replay must count as the env did, and end on its bits);
2. with each node's contact at the end of the step given at its start (an oracle: the most that
   guessing the contacts could save);
3. each node that ``_be_start`` lets slide at its velocity at the end of the step, the contacts
   as ``_be_start`` guesses them (the most that guessing the velocities could save);
4. a kinematic first guess: the sliding nodes' velocities moved so that every edge grows at its
   rest length's new rate, the stuck nodes (or, with none, the centre of mass) kept in place.

It prints, per guess, the mean factorizations and residuals per step, how far the step's end
moved from the env's (the same solution to Newton's tolerance, or another consistent set of
contacts), and the steps that failed.

    python scripts/contact_oracle.py
    python scripts/contact_oracle.py --steps 3000
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from numba import njit

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.physics import layout as L
from soft_snake_gym.physics import stepper

GUESSES = ("as stepped", "final contacts", "final velocities", "kinematic velocities")


@njit(cache=True)
def _start(f, ibuf, uk, ul):
    """A sub-step's start as ``stepper.simulate`` makes it: the rest shape moved, ``_be_start``'s guess; returns its ``dt``."""
    s = L.sim_views(f, ibuf)
    dt = s.prm[L.P_H] / int(s.prm[L.P_SUBSTEPS])
    stepper.move_rest_shape(s, uk, ul, dt)
    stepper._be_start(s, L.MEDIUM_GROUND, 1.0)
    return dt


@njit(cache=True)
def _newton(f, ibuf, dt):
    """Newton's loop of a sub-step of ``dt`` from the guess in the arrays: (status, factorizations, residuals)."""
    s = L.sim_views(f, ibuf)
    s.out[L.O_NFACTOR] = s.out[L.O_NJAC] = s.out[L.O_NRES] = 0.0
    status = stepper._be_newton(s, dt, L.MEDIUM_GROUND)[0]
    return status, s.out[L.O_NFACTOR], s.out[L.O_NJAC] + s.out[L.O_NRES]


def _guess(s: L.SimArrays, guess: int, state_end: np.ndarray, v_end: np.ndarray) -> None:
    """Overwrite ``_be_start``'s guess in ``s`` with guess number ``guess`` of :data:`GUESSES`."""
    v, state = s.v.reshape(-1, 2), s.ibuf[L.I_FRICTION][: s.v.size // 2]
    v_end = v_end.reshape(-1, 2)
    if guess == 1:
        v[(state_end == L.STUCK) & (state == L.SLIDING)] = 0.0
        for i in np.flatnonzero((state_end == L.SLIDING) & (state == L.STUCK)):
            # released as _update_contacts releases, pushed the way the node ends
            stepper._release(s.v, s.buf[L.B_VSLIDE], state, i, v_end[i, 0], v_end[i, 1], s.prm[L.P_VTOL])
        state[:] = state_end
    elif guess == 2:  # the contacts as _be_start guessed them
        v[state == L.SLIDING] = v_end[state == L.SLIDING]
    elif guess == 3:
        q = s.q.reshape(-1, 2)
        edges = np.diff(q, axis=0)
        tangents = edges / np.linalg.norm(edges, axis=1)[:, None]
        grow = s.buf[L.B_LRATE, : s.lbar.size] - (np.diff(v, axis=0) * tangents).sum(axis=1)
        move = np.vstack([np.zeros(2), np.cumsum(grow[:, None] * tangents, axis=0)])
        stuck = state == L.STUCK
        move -= move[stuck].mean(axis=0) if stuck.any() else move.mean(axis=0)
        v[~stuck] += move[~stuck]


def main() -> None:
    """Replay the steps under each guess and print the counts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    env = gym.make("SoftWorm-v0")
    robot = env.unwrapped
    arrays, task = robot.sim.arrays, robot.task
    rng = np.random.default_rng(args.seed)
    env.reset(seed=args.seed)
    counts = np.zeros((len(GUESSES), 3))
    moved = [[] for _ in GUESSES]
    env_counts = np.zeros(2)
    for _ in range(args.steps):
        f0, ibuf0 = arrays.f.copy(), arrays.ibuf.copy()
        _, _, terminated, truncated, _ = env.step(
            rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        )
        env_counts += arrays.out[L.O_NFACTOR], arrays.out[L.O_NJAC] + arrays.out[L.O_NRES]
        state_end, v_end = arrays.ibuf[L.I_FRICTION][: arrays.v.size // 2].copy(), arrays.v.copy()
        for g in range(len(GUESSES)):
            f, ibuf = f0.copy(), ibuf0.copy()
            dt = _start(f, ibuf, task.uk.copy(), task.ul.copy())
            s = L.sim_arrays_over(f, ibuf)
            _guess(s, g, state_end, v_end)
            status, factorizations, residuals = _newton(f, ibuf, dt)
            counts[g] += factorizations, residuals, status != stepper.OK
            moved[g].append(np.abs(s.v - v_end).max())
        if terminated or truncated:
            env.reset()
    steps = args.steps
    print(f"SoftWorm-v0, {steps} steps under random actions (seed {args.seed}): per step")
    print(
        f"  the env                         factorizations {env_counts[0] / steps:.2f}  residuals {env_counts[1] / steps:.2f}"
    )
    for g, name in enumerate(GUESSES):
        far = np.array(moved[g])
        print(
            f"  {name:31s} factorizations {counts[g, 0] / steps:.2f}  residuals {counts[g, 1] / steps:.2f}"
            f"  end velocity from the env's: median {np.median(far):.1e}, largest {far.max():.1e} m/s,"
            f" {np.mean(far > 1e-6):.1%} of steps past 1e-6  failed {int(counts[g, 2])}"
        )


if __name__ == "__main__":
    main()
