"""Where a stepping loop's time goes, function by function: Linux ``perf`` with numba's names.

The other profiles time each compiled part alone (``profile_step.py``) or cut the block's step
after each part (``profile_block.py``). This one samples the real loop: a single ``gym.make`` env
or, with ``--robots``, the batched env, under uniform random actions in [-1, 1] (resetting as
the benchmark does). Numba's code is not in any file perf can read, so the script names it:
it reads the address of every function in the libraries numba has loaded (cached or not) and
writes them to ``/tmp/perf-<pid>.map``, where ``perf report`` looks for the names of code made
at run time. It then records itself with ``perf record -p`` and prints the functions with the
largest share of the samples (on every thread of the process), numba's under their Python
names, the interpreter's and the libraries' under their own.

    python scripts/perf_step.py SoftWorm-v0
    python scripts/perf_step.py SoftEel-v0 --robots 256 --threads 2 --seconds 10

Needs ``perf`` (Debian: ``apt install linux-perf``) and ``kernel.perf_event_paranoid`` at most 2.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time

import gymnasium as gym
import numpy as np
from numba.core.registry import CPUDispatcher

import soft_snake_gym  # noqa: F401 - registers the ids

_NESTED = re.compile(r"(\d+)")


def python_name(symbol: str) -> str:
    """``soft_snake_gym.physics.banded.band_factor`` from numba's mangled ``_ZN14soft_snake_gym7physics6banded11band_factorB...``.

    The Itanium nested name's parts (each a length and that many characters) up to the first
    part that is not one; a wrapper's prefix (``cpython.``, ``cfunc.``) is kept.
    """
    prefix, _, rest = symbol.partition("_ZN")
    if not rest:
        return symbol
    parts, i = [], 0
    while i < len(rest) and rest[i].isdigit():
        digits = _NESTED.match(rest, i).group(1)
        i += len(digits)
        parts.append(rest[i : i + int(digits)])
        i += int(digits)
    return prefix + ".".join(parts)


def numba_symbols() -> dict[int, str]:
    """Address -> Python name of every function numba has compiled or loaded in this process."""
    names: dict[int, str] = {}
    for module in list(sys.modules.values()):
        if not getattr(module, "__name__", "").startswith("soft_snake_gym"):
            continue
        for obj in list(vars(module).values()):
            if not isinstance(obj, CPUDispatcher):
                continue
            for cres in obj.overloads.values():
                lib = cres.library
                engine = lib._codegen._engine._ee
                for llvm_module in (
                    getattr(lib, "_final_module", None),
                    getattr(lib, "_shared_module", None),
                ):
                    for fn in llvm_module.functions if llvm_module is not None else ():
                        if fn.is_declaration:
                            continue
                        address = engine.get_function_address(fn.name)
                        if address:
                            names[address] = python_name(fn.name)
    return names


def write_perf_map(names: dict[int, str], path: str) -> None:
    """``perf``'s map of code made at run time: ``start size name`` a line, each up to the next start."""
    starts = sorted(names)
    with open(path, "w") as f:
        for start, end in zip(starts, [*starts[1:], starts[-1] + 0x10000], strict=True):
            f.write(f"{start:x} {min(end - start, 0x100000):x} {names[start]}\n")


def stepper(env_id: str, robots: int, threads: int):
    """The env and a function that steps it once (random actions, resets as the benchmark's)."""
    rng = np.random.default_rng(0)
    if robots == 0:
        env = gym.make(env_id)
        env.reset(seed=0)
        actions = rng.uniform(-1, 1, (1000,) + env.action_space.shape).astype(np.float32)
        count = iter(range(10**12))

        def step() -> None:
            _, _, term, trunc, _ = env.step(actions[next(count) % len(actions)])
            if term or trunc:
                env.reset()

        return env, step
    env = gym.make_vec(env_id, num_envs=robots, num_threads=threads)
    env.reset(seed=0)
    actions = rng.uniform(-1, 1, (32,) + env.action_space.shape).astype(np.float32)
    count = iter(range(10**12))
    return env, lambda: env.step(actions[next(count) % len(actions)])


def main() -> None:
    """Step the env, record it with perf, print the largest shares."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("env_id", nargs="?", default="SoftWorm-v0")
    parser.add_argument(
        "--robots", type=int, default=0, help="the batched env with this many robots (0: gym.make)"
    )
    parser.add_argument("--threads", type=int, default=1, help="the batched env's numba threads")
    parser.add_argument("--seconds", type=float, default=8.0, help="how long perf records")
    parser.add_argument("--top", type=int, default=30, help="functions to print")
    args = parser.parse_args()
    if args.robots < 0 or args.threads < 1 or args.seconds <= 0 or args.top < 1:
        parser.error("--robots must be >= 0, --threads and --top >= 1, --seconds > 0")

    env, step = stepper(args.env_id, args.robots, args.threads)
    for _ in range(300):  # every kernel the loop calls is loaded before the map is written
        step()
    map_path = f"/tmp/perf-{os.getpid()}.map"
    write_perf_map(numba_symbols(), map_path)
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        try:
            perf = subprocess.Popen(
                [
                    "perf",
                    "record",
                    "-q",
                    "-F",
                    "999",
                    "-p",
                    str(os.getpid()),
                    "-o",
                    data,
                    "--",
                    "sleep",
                    str(args.seconds),
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
        except FileNotFoundError:
            os.remove(map_path)
            sys.exit("perf is not installed: apt install linux-perf (Debian), then run this again")
        done = threading.Event()
        threading.Thread(target=lambda: (perf.wait(), done.set()), daemon=True).start()
        steps, start = 0, time.perf_counter()
        while not done.is_set():
            step()
            steps += 1
        elapsed = time.perf_counter() - start
        if perf.returncode != 0:
            os.remove(map_path)
            sys.exit(f"perf record failed ({perf.stderr.read().strip()}); see kernel.perf_event_paranoid")
        report = subprocess.run(
            ["perf", "report", "-i", data, "--no-children", "--sort", "sym", "--stdio", "-q"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    os.remove(map_path)
    env.close()
    shares: dict[str, float] = {}
    for line in report.splitlines():
        share, _, name = line.strip().partition("%")
        name = name.replace("[.]", "").replace("[k]", "").strip()
        if name:  # a function compiled twice (two specializations, or copies in two libraries) sums
            shares[name] = shares.get(name, 0.0) + float(share)
    groups = {"compiled (numba)": 0.0, "libc and libm": 0.0, "Python, numpy and the rest": 0.0}
    for name, share in shares.items():
        if name.startswith(("soft_snake_gym.", "cpython.", "cfunc.", "NRT_")):
            groups["compiled (numba)"] += share
        elif "@@GLIBC" in name or name.startswith("__mem"):
            groups["libc and libm"] += share
        else:
            groups["Python, numpy and the rest"] += share
    what = f"{args.env_id}, " + (
        f"{args.robots} robots on {args.threads} thread(s)" if args.robots else "gym.make"
    )
    per = (args.robots or 1) * steps / elapsed
    print(
        f"{what}: {steps} steps in {elapsed:.1f} s while perf recorded ({per:,.0f} robot-steps/s, under perf)"
    )
    print("share of the samples on every thread of the process:")
    for group, share in groups.items():
        print(f"  {share:6.2f} %  {group}")
    print(f"the top {args.top} functions:")
    for name, share in sorted(shares.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"  {share:6.2f} %  {name[:110]}")


if __name__ == "__main__":
    main()
