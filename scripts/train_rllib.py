"""Train RLlib's PPO (current API stack) on SoftEel-v0: the envs in RLlib, on one machine or a cluster.

Needs RLlib in a venv of its own (it pins Gymnasium 1.2.2; README, RLlib)::

    python -m venv .venv-rllib && .venv-rllib/bin/pip install torch==2.13.0
    .venv-rllib/bin/pip install -e ".[rllib]"
    .venv-rllib/bin/python scripts/train_rllib.py --iterations 20 --env-runners 1

``--address host:port`` (or ``auto``) trains on a running Ray cluster (``ray start --head``);
without it a local Ray starts. Each iteration prints the environment steps sampled, the mean
episode return of the episodes that ended, and the wall time; ``--checkpoint DIR`` saves the
algorithm at the end (``Algorithm.from_checkpoint(DIR)`` restores it).
"""

from __future__ import annotations

import argparse
import math
import time

from soft_snake_gym.config import parse_assignments
from soft_snake_gym.distributed import connect
from soft_snake_gym.rllib import ppo_config


def main(argv: list[str] | None = None) -> None:
    """Parse the arguments, connect to Ray, train and print one line per iteration."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="SoftEel-v0", help="SoftEel-v0 or SoftWorm-v0")
    p.add_argument("--iterations", type=int, default=10, help="training iterations")
    p.add_argument("--env-runners", type=int, default=1, help="remote sampling actors (0: in the driver)")
    p.add_argument("--batch", type=int, default=4000, help="environment steps per iteration")
    p.add_argument("--minibatch", type=int, default=128, help="steps per SGD minibatch")
    p.add_argument("--epochs", type=int, default=10, help="passes over each batch")
    p.add_argument("--lr", type=float, default=3e-4, help="learning rate")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--env-kwarg", action="append", metavar="KEY=VALUE", help="env keyword, repeatable")
    p.add_argument("--address", help="Ray cluster address (host:port or auto; default: a local Ray)")
    p.add_argument("--checkpoint", metavar="DIR", help="save the algorithm here at the end")
    args = p.parse_args(argv)
    env_config = parse_assignments(args.env_kwarg, "--env-kwarg {item} is not key=value")
    config = ppo_config(
        args.env,
        env_config,
        num_env_runners=args.env_runners,
        train_batch_size=args.batch,
        minibatch_size=args.minibatch,
        num_epochs=args.epochs,
        lr=args.lr,
        seed=args.seed,
    )
    connect(args.address)
    algo = config.build_algo()
    t0 = time.time()
    print(f"PPO on {args.env} with {args.env_runners} env runner(s), {args.batch} steps per iteration")
    for _ in range(args.iterations):
        result = algo.train()
        runners = result.get("env_runners", {})
        ret = float(runners.get("episode_return_mean", math.nan))
        print(
            f"iteration {result['training_iteration']:3d}: {int(result.get('num_env_steps_sampled_lifetime', 0)):8,} "
            f"steps, {int(runners.get('num_episodes_lifetime', 0)):4d} episodes, "
            f"episode return mean {ret:8.3f}, {time.time() - t0:6.1f} s"
        )
    if args.checkpoint:
        print(f"saved {algo.save_to_path(args.checkpoint)}")
    algo.stop()


if __name__ == "__main__":
    main()
