"""The package against an earlier commit of itself, in one process, in interleaved rounds.

On a machine whose speed drifts by half from one minute to the next, two benchmark runs do not
compare; two codes measured round by round in the same process do. This script checks out
``--base`` (a commit) as a second package, ``ssg_base``, beside the installed one, and times both
on the same cases, alternating: the single envs' ``step`` (unwrapped, random actions) and the
vector env's whole ``step`` at 256 robots (or ``--robots``) on one and two threads, each code first
in every other round (the code that ran second was measured 1.02 to 1.06 times faster against
itself, ``--base HEAD``). It prints each case's median rate for both and the median and range of
the per-round ratios. ``--base HEAD`` with the tree clean measures the method's own spread.

One process is not enough for a change of a few percent. Where the two codes' machine code and
arrays land in memory differs from one process to the next, and so does their speed: the same
kernels (8cfb3e7 against a7d5b2e, whose difference is docstrings; the compiled call of 256 eels
on one thread) measured 0.93, 0.99, 0.99, 1.00 and 0.99 times the base in five processes, the
first with a range of 0.89-0.95 over its 8 rounds.
``--processes K`` runs the comparison in K fresh processes one after the other and prints, for
each case, the median of the processes' ratios and their range (the range of the processes,
not of the rounds).

    python scripts/ab_versions.py --base 292cc90                  # ~3 min once the caches are warm
    python scripts/ab_versions.py --base HEAD~1 --rounds 8 --seconds 2
    python scripts/ab_versions.py --base HEAD~1 --robots 8 24 256   # PPO's 8 envs, a tail block, 256
    python scripts/ab_versions.py --base HEAD~1 --processes 5 --rounds 4   # for a change of a few %
    python scripts/ab_versions.py --base HEAD~1 --integrator bdf2   # the eels on another integrator

The copy lives in ``~/.cache/soft_snake_gym_ab/<commit>`` (its numba cache with it), so a second
run against the same commit compiles nothing. Both packages register the same env ids; the script
builds the env classes directly and never calls ``gym.make``.
"""

from __future__ import annotations

import argparse
import importlib
import io
import json
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BASE_NAME = "ssg_base"


def base_copy(rev: str) -> Path:
    """The package at ``rev``, renamed ``ssg_base``, in a cache folder; returns the folder to put on the path."""
    sha = subprocess.run(
        ["git", "rev-parse", "--short=12", rev], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.strip()
    home = Path.home() / ".cache" / "soft_snake_gym_ab" / sha
    if (home / BASE_NAME / "__init__.py").exists():
        return home
    archive = subprocess.run(
        ["git", "archive", sha, "soft_snake_gym"], cwd=ROOT, capture_output=True, check=True
    )
    home.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
        tar.extractall(home, filter="data")
    (home / "soft_snake_gym").rename(home / BASE_NAME)
    for f in (home / BASE_NAME).rglob("*"):
        if f.suffix in (".py", ".yaml", ".yml"):
            f.write_text(f.read_text().replace("soft_snake_gym", BASE_NAME))
    return home


def _eel_integrator(body: str, method: str | None) -> dict:
    """The env keywords of ``--integrator``: for the eels only (the ground has backward Euler alone)."""
    return {"integrator": {"method": method}} if method and body == "eel" else {}


def single(swim, inch, body: str, seconds: float, rng: np.random.Generator, method: str | None = None):
    """A round of the single env of ``body``: steps per second over ``seconds``."""
    env = (swim.SwimEnv if body == "eel" else inch.InchEnv)(**_eel_integrator(body, method))
    env.reset(seed=0)
    acts = rng.uniform(-1, 1, (1000,) + env.action_space.shape)

    def run() -> float:
        n, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            for a in acts[(n % 1000) : (n % 1000) + 100]:
                _, _, terminated, truncated, _ = env.step(a)
                if terminated or truncated:
                    env.reset()
            n += 100
        return n / (time.perf_counter() - start)

    return run


def batched(
    vector,
    body: str,
    n: int,
    threads: int,
    seconds: float,
    rng: np.random.Generator,
    method: str | None = None,
):
    """A round of ``n`` robots of ``body`` in the vector env: robot-steps per second over ``seconds``."""
    env = (vector.SwimVectorEnv if body == "eel" else vector.InchVectorEnv)(
        num_envs=n, num_threads=threads, **_eel_integrator(body, method)
    )
    env.reset(seed=0)
    acts = rng.uniform(-1, 1, (50, n) + env.single_action_space.shape)

    def run() -> float:
        steps, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            env.step(acts[steps % 50])
            steps += 1
        return steps * n / (time.perf_counter() - start)

    return run


def main(argv: list[str] | None = None) -> None:
    """Time both codes on every case, interleaved, and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the commit to compare against (any git revision)")
    parser.add_argument(
        "--rounds", type=int, default=8, help="interleaved rounds per case (default 8: each code first in 4)"
    )
    parser.add_argument("--seconds", type=float, default=1.0, help="seconds per case and round (default 1)")
    parser.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=[256],
        help="vector env sizes (default 256; two threads from 64)",
    )
    parser.add_argument(
        "--processes", type=int, default=1, help="fresh processes to repeat it in (default 1; see above)"
    )
    parser.add_argument(
        "--integrator",
        choices=["sdirk2", "bdf2", "backward_euler"],
        help="the eels' integrator.method (default: the env's; the worms keep theirs)",
    )
    parser.add_argument("--json", help=argparse.SUPPRESS)  # a process of --processes writes its rates here
    args = parser.parse_args(argv)
    if args.rounds < 1 or not args.seconds > 0 or min(args.robots) < 1 or args.processes < 1:
        parser.error("--rounds, --robots and --processes must be at least 1 and --seconds positive")
    base_copy(args.base)  # made once, before any process needs it
    if args.processes == 1:
        rates = measure(args)
        if args.json:
            Path(args.json).write_text(json.dumps(rates))
            return
        runs = [rates]
    else:
        runs = []
        same = ["--base", args.base, "--rounds", str(args.rounds), "--seconds", str(args.seconds)]
        same += ["--integrator", args.integrator] if args.integrator else []
        same += ["--robots"]
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(args.processes):
                print(f"process {k + 1}/{args.processes}", file=sys.stderr)
                out = Path(tmp) / f"{k}.json"
                cmd = [sys.executable, __file__, *same, *map(str, args.robots), "--json", str(out)]
                subprocess.run(cmd, check=True)
                runs.append(json.loads(out.read_text()))
    report(args, runs)


def measure(args: argparse.Namespace) -> dict[str, tuple[list[float], list[float]]]:
    """One process's interleaved rounds: each case's rates, (base, now), round by round."""
    sys.path.insert(0, str(base_copy(args.base)))
    codes = {}
    for name in ("soft_snake_gym", BASE_NAME):
        codes[name] = [importlib.import_module(f"{name}.envs.{m}") for m in ("swim", "inch", "vector")]
    rng = np.random.default_rng(0)
    cases = {}
    for body in ("eel", "worm"):
        cases[f"{body}, single env"] = [
            single(s, i, body, args.seconds, rng, args.integrator) for s, i, _ in codes.values()
        ]
    for n in args.robots:
        for body in ("eel", "worm"):
            for threads in (1, 2) if n >= 64 else (1,):
                label = f"{n} {body}s, {threads} thread{'s' if threads > 1 else ''}"
                cases[label] = [
                    batched(v, body, n, threads, args.seconds, rng, args.integrator)
                    for _, _, v in codes.values()
                ]
    for now, base in cases.values():  # compile or load the caches outside the rounds
        now()
        base()
    rates = {label: ([], []) for label in cases}
    for r in range(args.rounds):
        print(f"round {r + 1}/{args.rounds}", file=sys.stderr)
        for label, (now, base) in cases.items():  # each code first in every other round
            if r % 2:
                rates[label][1].append(now())
                rates[label][0].append(base())
            else:
                rates[label][0].append(base())
                rates[label][1].append(now())
    return rates


def report(args: argparse.Namespace, runs: list[dict[str, tuple[list[float], list[float]]]]) -> None:
    """The table: each case's median rates over every round; its ratio's median and range.

    Over the rounds with one process, over the processes' own medians with several.
    """
    k = len(runs)
    what = f"{args.rounds} rounds" if k == 1 else f"{k} processes of {args.rounds} rounds"
    eels = f", the eels on {args.integrator}" if args.integrator else ""
    print(f"now against {args.base}{eels}: steps/s (single envs) or robot-steps/s, medians of {what}")
    print(
        f"{'case':22s} {'base':>10s} {'now':>10s}  now/base: median (range{'' if k == 1 else ' of processes'})"
    )
    for label in runs[0]:
        base = np.concatenate([run[label][0] for run in runs])
        now = np.concatenate([run[label][1] for run in runs])
        ratios = [np.array(run[label][1]) / np.array(run[label][0]) for run in runs]
        ratio = ratios[0] if k == 1 else np.array([np.median(r) for r in ratios])
        print(
            f"{label:22s} {np.median(base):10,.0f} {np.median(now):10,.0f}  "
            f"{np.median(ratio):.2f} ({ratio.min():.2f}-{ratio.max():.2f})"
        )


if __name__ == "__main__":
    main()
