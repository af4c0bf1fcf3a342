"""Threads per batch size: the batched step on 1 and on every numba thread, with and without torch.

For each robot count, the batched SoftEel-v0 step (random actions) on one thread and on
``NUMBA_NUM_THREADS`` threads, interleaved over rounds (medians), first alone and then with
torch imported and one PPO-sized forward pass per step on torch's threads (what a training
loop does between two env steps). The ratio of the two thread counts is what picks
``ROBOTS_PER_THREAD`` (the vector env's default: one thread per that many robots).

    python scripts/bench_threads.py                 # robots 16 64 128 256 1024
    NUMBA_THREADING_LAYER=workqueue python scripts/bench_threads.py
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numba
import numpy as np

import soft_snake_gym  # noqa: F401 - registers the ids


def _rate(venv, actions, seconds: float, between=None) -> float:
    steps, start = 0, time.perf_counter()
    while True:
        for a in actions:
            venv.step(a)
            if between is not None:
                between()
        steps += len(actions)
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return steps * venv.num_envs / elapsed


def main() -> None:
    """Print robot-steps/s per robot count and thread count, without and with torch."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[16, 64, 128, 256, 1024])
    p.add_argument("--seconds", type=float, default=1.0)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    all_threads = numba.config.NUMBA_NUM_THREADS
    rng = np.random.default_rng(0)
    envs = {}
    for n in args.robots:
        for t in sorted({1, all_threads}):
            venv = gym.make_vec("SoftEel-v0", num_envs=n, num_threads=t)
            venv.reset(seed=0)
            actions = rng.uniform(-1, 1, (16, n, 8))
            venv.step(actions[0])
            envs[(n, t)] = (venv, actions)
    state = {"n": 0}  # the robot count being stepped, for the torch pass's batch size
    for label in ("numba alone", "with torch"):
        between = None
        if label == "with torch":
            import torch  # here: the point of this half is what importing and using it changes

            net = torch.nn.Sequential(torch.nn.Linear(28, 64), torch.nn.Tanh(), torch.nn.Linear(64, 64))
            obs = {n: torch.zeros(n, 28) for n in args.robots}

            def between(net=net, obs=obs):
                with torch.no_grad():
                    net(obs[state["n"]])

        rates = {k: [] for k in envs}
        for _ in range(args.repeats):
            for (n, t), (venv, actions) in envs.items():
                state["n"] = n
                rates[(n, t)].append(_rate(venv, actions, args.seconds, between))
        extra = f", torch threads {torch.get_num_threads()}" if label == "with torch" else ""
        print(f"\n{label} (numba layer {numba.threading_layer()}{extra}); robot-steps/s, median of rounds")
        print(f"{'robots':>7} {'1 thread':>10} {f'{all_threads} threads':>11} {'ratio':>6}")
        for n in args.robots:
            one = statistics.median(rates[(n, 1)])
            many = statistics.median(rates[(n, all_threads)])
            print(f"{n:>7} {one:>10,.0f} {many:>11,.0f} {many / one:>6.2f}")


if __name__ == "__main__":
    main()
