"""Where PPO's time goes, batched env against ``SubprocVecEnv``: the rollout and the update apart.

``soft-snake benchmark`` times the whole ``model.learn``; its ratio of the two kinds mixes the
env's cost with what both pay alike (the policy's forward pass in the rollout, the gradient
updates). This script times ``collect_rollouts`` and ``train`` separately, at the package's PPO
settings for the env, in interleaved rounds, with one and with two torch threads (and, as
``soft-snake train`` runs it, ``torch.distributions`` unchecked):

    python scripts/ppo_phases.py SoftEel-v0 --rounds 4
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from stable_baselines3.common.callbacks import CallbackList

from soft_snake_gym.benchmark import ppo_model
from soft_snake_gym.training import torch_for_learning


def main() -> None:
    """Time both kinds' phases in interleaved rounds and print the medians and the ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("env_id", nargs="?", default="SoftEel-v0")
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    with torch_for_learning():
        _time_phases(args)


def _time_phases(args: argparse.Namespace) -> None:
    """The rounds and the report of :func:`main`."""
    models = {kind: ppo_model(kind, args.env_id) for kind in ("batched", "subproc")}
    times: dict[tuple[str, int], list[tuple[float, float]]] = {}
    try:
        for _ in range(args.rounds):
            for threads in (1, 2):
                torch.set_num_threads(threads)
                for kind, model in models.items():
                    callback = CallbackList([])
                    callback.init_callback(model)
                    start = time.perf_counter()
                    model.collect_rollouts(model.env, callback, model.rollout_buffer, model.n_steps)
                    mid = time.perf_counter()
                    model.train()
                    times.setdefault((kind, threads), []).append((mid - start, time.perf_counter() - mid))
    finally:
        for model in models.values():
            model.get_env().close()
    steps = models["batched"].n_steps * models["batched"].n_envs
    print(f"{args.env_id}, {steps} steps an iteration, medians of {args.rounds} rounds")
    print("kind      torch threads  rollout s  update s  steps/s")
    total = {}
    for (kind, threads), rows in times.items():
        rollout = statistics.median(r for r, _ in rows)
        update = statistics.median(u for _, u in rows)
        total[kind, threads] = statistics.median(r + u for r, u in rows)
        print(f"{kind:9s} {threads:13d} {rollout:10.3f} {update:9.3f} {steps / total[kind, threads]:8.0f}")
    for threads in (1, 2):
        print(
            f"batched vs subproc, {threads} torch thread(s): {total['subproc', threads] / total['batched', threads]:.2f}x"
        )


if __name__ == "__main__":
    main()
