"""Environment throughput: ``env.step`` calls per second for SoftEel-v0 and SoftWorm-v0.

Each environment is made with ``gym.make`` (so with Gymnasium's standard wrappers:
``PassiveEnvChecker``, ``OrderEnforcing``, ``TimeLimit`` at 1000 steps) and driven by two
action sources, resetting whenever an episode ends:

- ``random``: uniform actions in [-1, 1] (pre-sampled; full-scale random bending often folds
  the eel onto itself, so those episodes end early and resets are part of the figure);
- ``gait``: the thesis gait through the env's normalized actions (open-loop serpenoid,
  alpha = pi/6, omega = 2 pi/3 for the eel; inching wave, eps = 0.3, omega = 2 pi for the worm).

For reference the bare ``Simulator.step`` rate under the same gait inputs is printed too;
the difference is the env's overhead per step (observation, reward, info, wrappers).

    python scripts/bench_envs.py                  # ~2 s per case
    python scripts/bench_envs.py --seconds 5 --json bench_envs.json
"""

from __future__ import annotations

import argparse
import json
import math
import time

import gymnasium as gym
import numpy as np

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.gaits import length_wave, serpenoid, serpenoid_phase

IDS = ("SoftEel-v0", "SoftWorm-v0")


def gait_actions(env: gym.Env, steps: int = 1000) -> np.ndarray:
    """Normalized actions of one episode of the thesis gait, (steps, n_actions) float32."""
    u = env.unwrapped
    t = (np.arange(steps) + 0.5) * u.dt
    if env.spec.id == "SoftEel-v0":
        n, alpha, omega = u.N - 2, math.pi / 6, 2 * math.pi / 3
        rates = np.array(
            [serpenoid(serpenoid_phase(ti, n, omega, 2 * math.pi / n), omega, alpha)[1] for ti in t]
        )
        return (rates / u.max_curvature_rate).astype(np.float32)
    l0 = u.sim.config.rod.edge_length
    rates = np.array([length_wave(ti, u.N - 1, l0, 0.3, 2 * math.pi, math.pi / 4)[1] for ti in t])
    return (rates / u.max_length_rate).astype(np.float32)


def time_env(env: gym.Env, actions: np.ndarray, seconds: float) -> dict[str, float]:
    """Step ``env`` through ``actions`` (cycled) for about ``seconds``; returns the rate."""
    env.reset(seed=0)
    for a in actions[:50]:  # warm up (compiled kernels are loaded on first use)
        env.step(a)
    env.reset(seed=0)
    steps = resets = 0
    start = time.perf_counter()
    while True:
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            steps += 1
            if term or trunc:
                env.reset()
                resets += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            break
    return {"steps_per_s": steps / elapsed, "steps": steps, "episodes_ended": resets}


def time_sim(env: gym.Env, actions: np.ndarray, seconds: float) -> float:
    """Bare ``Simulator.step`` rate under the same physical inputs (no env, no wrappers)."""
    u = env.unwrapped
    sim = u.sim
    eel = env.spec.id == "SoftEel-v0"
    rates = actions.astype(np.float64) * (u.max_curvature_rate if eel else u.max_length_rate)
    env.reset(seed=0)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.reset(seed=0)
        for r in rates:
            ok = sim.step(r, None) if eel else sim.step(None, r)
            steps += 1
            if not ok:
                break
    return steps / (time.perf_counter() - start)


def main() -> None:
    """Time every case and print the results (and write them as JSON with ``--json``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="wall-clock seconds per case")
    parser.add_argument("--json", help="also write the results to this JSON file")
    args = parser.parse_args()

    results = []
    print(f"{'env':<12} {'actions':<7} {'env steps/s':>12} {'episodes ended':>15}")
    for env_id in IDS:
        env = gym.make(env_id)
        rng = np.random.default_rng(0)
        sources = {
            "random": rng.uniform(-1, 1, (1000,) + env.action_space.shape).astype(np.float32),
            "gait": gait_actions(env),
        }
        for name, actions in sources.items():
            r = time_env(env, actions, args.seconds)
            results.append({"env": env_id, "actions": name, **r})
            print(f"{env_id:<12} {name:<7} {r['steps_per_s']:>12.0f} {r['episodes_ended']:>15d}")
        sim_rate = time_sim(env, sources["gait"], args.seconds)
        env_rate = next(r["steps_per_s"] for r in results if r["env"] == env_id and r["actions"] == "gait")
        overhead = 1e6 / env_rate - 1e6 / sim_rate
        results.append(
            {
                "env": env_id,
                "actions": "gait (bare Simulator.step)",
                "steps_per_s": sim_rate,
                "env_overhead_us": overhead,
            }
        )
        print(
            f"{env_id:<12} {'sim':<7} {sim_rate:>12.0f}   (bare Simulator.step; env overhead "
            f"{overhead:.1f} us/step)"
        )
        env.close()
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)


if __name__ == "__main__":
    main()
