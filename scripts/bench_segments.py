"""Throughput of the two ways to make every segment agent a slot of an SB3 VecEnv.

The batched adapter :class:`soft_snake_gym.sb3.SegmentVecEnv` (every robot in one compiled call,
local observations and rewards gathered from the stacked arrays) against SuperSuit's
``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1`` over the PettingZoo env
``eel_segments_v0``, with the same number of robots and random actions (agent-steps per second).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python scripts/bench_segments.py [--robots 8] [--steps 2000]

Needs ``pip install 'soft_snake_gym[multiagent]'``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import supersuit as ss

from soft_snake_gym.multiagent import eel_segments_v0
from soft_snake_gym.sb3 import SegmentVecEnv


def agent_steps_per_second(venv, steps: int) -> float:
    """Agent-steps per second of ``venv`` (an SB3 VecEnv) under seeded uniform random actions."""
    venv.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, venv.num_envs, 1)).astype(np.float32)
    for a in actions[:20]:  # warm-up (numba's compiled kernels are loaded on the first call)
        venv.step(a)
    start = time.perf_counter()
    for a in actions:
        venv.step(a)
    return steps * venv.num_envs / (time.perf_counter() - start)


def main() -> None:
    """Time both and print agent-steps per second."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=8, help="eels (each N - 2 = 8 slots; default 8)")
    parser.add_argument("--steps", type=int, default=2000, help="vector steps timed (default 2000)")
    args = parser.parse_args()
    adapter = SegmentVecEnv(8 * args.robots, seed=0, num_threads=1)
    supersuit = ss.concat_vec_envs_v1(
        ss.pettingzoo_env_to_vec_env_v1(eel_segments_v0.parallel_env()),
        args.robots,
        num_cpus=0,
        base_class="stable_baselines3",
    )
    a = agent_steps_per_second(adapter, args.steps)
    s = agent_steps_per_second(supersuit, args.steps // 2)
    print(f"{args.robots} eels, {8 * args.robots} agent slots, random actions, one thread")
    print(f"batched adapter (SegmentVecEnv)              {a:10,.0f} agent-steps/s")
    print(f"SuperSuit pettingzoo_env_to_vec_env + concat {s:10,.0f} agent-steps/s")
    print(f"adapter / SuperSuit: {a / s:.1f}x")


if __name__ == "__main__":
    main()
