"""What several test modules share that is not a fixture: a tiny training run, the CLI in a subprocess."""

from __future__ import annotations

import signal
import subprocess
import sys

#: ``--hyperparams`` of a training run scaled down to seconds (two envs, one short evaluation).
TINY_TRAINING = [
    "n_envs=2",
    "n_steps=64",
    "batch_size=64",
    "n_epochs=2",
    "eval_freq=128",
    "checkpoint_freq=128",
    "eval_episodes=1",
    "env_kwargs.max_episode_steps=100",
]


CLI = [sys.executable, "-m", "soft_snake_gym.cli"]


def cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """``soft-snake ARGS`` in a subprocess, its output captured."""
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout)


def cli_in_background(*args: str) -> subprocess.Popen:
    """``soft-snake ARGS`` started in a subprocess that the test will interrupt, its output piped.

    SIGINT is at its default in the child, as from a terminal: a job started in the background
    (``cmd &`` in a script) ignores SIGINT and its children inherit that; Python then never
    raises KeyboardInterrupt, and a run meant to be stopped by Ctrl-C would finish instead.
    """
    return subprocess.Popen(
        [*CLI, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=sigint_at_default,
    )


def sigint_at_default() -> None:
    """A child's ``preexec_fn``: SIGINT at its default, as from a terminal (see :func:`cli_in_background`)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
