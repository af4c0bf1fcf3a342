"""The default build against ``SOFT_SNAKE_GYM_VECTOR_BITS=512``, in pairs of fresh processes.

numba compiles every function of a process for one set of CPU features, so the two vector widths
cannot run in one process (as ``ab_versions.py`` runs two codes). Each pair runs the case in a
fresh process with the default width, then in one with 512 bits; each process steps the env 100
times, then times five windows of ``--steps`` steps (random actions in [-1, 1]) and reports the
median window's µs a step and, for a vector env, a compiled call. The script prints each pair's
ratio (the default's time over the 512-bit one's) and their median and range. The first 512-bit
process compiles the package for those features (a few minutes; numba caches it apart).

    python scripts/vector_bits.py                          # 256 eels and worms, 1 and 2 threads
    python scripts/vector_bits.py --cases SoftEel-v0:1:0 SoftWorm-v0:1:0 --pairs 4   # single envs
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

CHILD = """
import json, sys, time
import numpy as np, gymnasium as gym
import soft_snake_gym  # noqa: F401
from soft_snake_gym.envs.vector import SoftVectorEnv
env_id, robots, threads, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
rng = np.random.default_rng(0)
if robots:
    env = SoftVectorEnv(env_id, robots, num_threads=threads)
    env.reset(seed=0)
    shape = (robots,) + env.single_action_space.shape
else:
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    shape = env.action_space.shape
actions = rng.uniform(-1, 1, (32,) + shape).astype(np.float32)
def run(n):
    for s in range(n):
        out = env.step(actions[s % 32])
        if not robots and (out[2] or out[3]):
            env.reset()
run(100)
windows = []
for _ in range(5):
    if robots:
        env.kernel_seconds = 0.0
    start = time.perf_counter()
    run(steps)
    call = env.kernel_seconds / steps * 1e6 if robots else 0.0
    windows.append(((time.perf_counter() - start) / steps * 1e6, call))
windows.sort()
print(json.dumps(windows[2]))
"""


def _case(text: str) -> tuple[str, int, int]:
    env_id, threads, robots = text.split(":")
    return env_id, int(threads), int(robots)


def measure(env_id: str, threads: int, robots: int, steps: int, bits: str) -> tuple[float, float]:
    """(µs a step, µs a compiled call) in a fresh process with ``SOFT_SNAKE_GYM_VECTOR_BITS=bits``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU_")}
    env["SOFT_SNAKE_GYM_VECTOR_BITS"] = bits
    out = subprocess.run(
        [sys.executable, "-c", CHILD, env_id, str(robots), str(threads), str(steps)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    step, call = json.loads(out.stdout.splitlines()[-1])
    return step, call


def main() -> None:
    """Run the pairs and print the ratios."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--cases",
        nargs="+",
        type=_case,
        default=[
            _case(c)
            for c in ("SoftEel-v0:1:256", "SoftWorm-v0:1:256", "SoftEel-v0:2:256", "SoftWorm-v0:2:256")
        ],
        help="ENV:THREADS:ROBOTS each (ROBOTS 0: the single env)",
    )
    parser.add_argument("--pairs", type=int, default=6, help="pairs of processes a case (default 6)")
    parser.add_argument("--steps", type=int, default=600, help="steps a window (default 600)")
    args = parser.parse_args()
    for env_id, threads, robots in args.cases:
        steps = args.steps * (1 if robots else 8)
        step_ratios, call_ratios = [], []
        for k in range(args.pairs):
            base = measure(env_id, threads, robots, steps, "256")
            wide = measure(env_id, threads, robots, steps, "512")
            step_ratios.append(base[0] / wide[0])
            if robots:
                call_ratios.append(base[1] / wide[1])
            print(f"  pair {k + 1}: {base[0]:.1f} and {wide[0]:.1f} µs a step", flush=True)
        name = f"{env_id}, {robots} robots, {threads} thread(s)" if robots else f"{env_id}, single env"
        for label, ratios in (("compiled call", call_ratios), ("whole step", step_ratios)):
            if ratios:
                print(
                    f"{name}: {label} 512 bits {statistics.median(ratios):.3f}x "
                    f"(pairs {min(ratios):.3f} to {max(ratios):.3f})",
                    flush=True,
                )


if __name__ == "__main__":
    main()
