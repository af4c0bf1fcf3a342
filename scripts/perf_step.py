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
    python scripts/perf_step.py SoftEel-v0 --robots 256 --mix soft_snake_gym.physics.lanes.residual
    python scripts/perf_step.py SoftWorm-v0 --robots 256 --mix soft_snake_gym.physics.lanes.crawl --windows 5

``--mix`` also reads the named function's machine code out of the process while it runs,
disassembles it with ``objdump`` and sorts its samples by the instruction at each sample's
address: what kind of work (vector multiplies, adds, divisions, loads and stores, scalar
arithmetic, integer and control) and how wide (512-, 256- or 128-bit registers). A timer's
sample stops the core at the oldest instruction not yet done, so the time shows where the core
waits: on a load whose data has not come, on an operation whose operands are not ready, on a
store whose data a slow instruction before it (a square root, a division) is still making.

Needs ``perf`` (Debian: ``apt install linux-perf``) and ``kernel.perf_event_paranoid`` at most 2;
``--mix`` needs ``objdump`` (binutils).
"""

from __future__ import annotations

import argparse
import ctypes
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter

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


def code_ranges(names: dict[int, str]) -> list[tuple[int, int, str]]:
    """``(start, size, name)`` of every function in ``names``: each runs up to the next one's start."""
    starts = sorted(names)
    ends = [*starts[1:], starts[-1] + 0x10000]
    return [
        (start, min(end - start, 0x100000), names[start]) for start, end in zip(starts, ends, strict=True)
    ]


def write_perf_map(ranges: list[tuple[int, int, str]], path: str) -> None:
    """``perf``'s map of code made at run time: ``start size name`` a line, of :func:`code_ranges`."""
    with open(path, "w") as f:
        for start, size, name in ranges:
            f.write(f"{start:x} {size:x} {name}\n")


WINDOW = 16
"""Instructions in each of ``--windows``' runs."""
_INSTRUCTION = re.compile(r"\s*([0-9a-f]+):\t(?:[0-9a-f]{2} )+\s*\t(\S+)\s*(.*)")
_VECTOR_KINDS = (("vmul", "multiply"), ("vadd", "add, subtract"), ("vsub", "add, subtract"),
                 ("vfm", "fused multiply-add"), ("vfnm", "fused multiply-add"), ("vdiv", "divide"),
                 ("vsqrt", "square root"))  # fmt: skip


def instruction_kind(mnemonic: str, operands: str) -> tuple[str, str]:
    """What an instruction (objdump's AT&T syntax) does and how wide: ``("vector multiply", "256-bit")``.

    The kinds: vector arithmetic by operation, vector loads and stores (moves with a memory
    operand, a store where it is the destination, the last operand), the other vector
    instructions (moves between registers, masks, compares, shuffles), scalar floating point
    (``sd``/``ss``) and the rest, integer and control.
    """
    width = "512-bit" if "%zmm" in operands else "256-bit" if "%ymm" in operands else "128-bit or none"
    if mnemonic.startswith("v") and mnemonic.endswith(("sd", "ss")) and width == "128-bit or none":
        return "scalar floating point", width
    if not mnemonic.startswith("v"):
        return "integer and control", width
    if mnemonic.startswith("vmov"):
        if "(" not in operands:
            return "vector other", width
        return ("vector store" if operands.endswith(")") else "vector load"), width  # AT&T: destination last
    for prefix, kind in _VECTOR_KINDS:
        if mnemonic.startswith(prefix):
            return f"vector {kind}", width
    return "vector other", width


def instruction_mix(
    data: str, ranges: list[tuple[int, int, str]], function: str, windows: int = 0
) -> list[str]:
    """The lines of a report of ``data``'s samples on ``function``'s code, by instruction kind and width.

    ``ranges`` are this process's :func:`code_ranges`: every compiled copy of the function (one
    per specialization and library) is read out of memory, up to the next function or the end of
    its mapping, and disassembled (what follows its last instruction decodes as junk, where no
    sample falls). With ``windows``, also the hottest runs of :data:`WINDOW` instructions, each
    instruction with its samples: where a wait shows (a store after a square root) and on what.
    """
    mapped = []  # this process's mappings: a copy is read no further than the end of its own
    with open("/proc/self/maps") as f:
        for line in f:
            low, high = line.split()[0].split("-")
            mapped.append((int(low, 16), int(high, 16)))
    copies = [
        (start, min(size, *(high - start for low, high in mapped if low <= start < high)))
        for start, size, name in ranges
        if name == function
    ]
    ips = subprocess.run(
        ["perf", "script", "-i", data, "-F", "ip"], capture_output=True, text=True, check=True
    ).stdout.split()
    counts = Counter(int(ip, 16) for ip in ips)
    by_kind: dict[str, int] = {}
    by_width: dict[str, int] = {}
    code: list[list[tuple[int, int, str]]] = []  # each copy's (offset, samples, instruction)
    total = 0
    with tempfile.TemporaryDirectory() as tmp:
        for start, size in copies:
            path = os.path.join(tmp, f"{start:x}.bin")
            with open(path, "wb") as f:
                f.write(ctypes.string_at(start, size))
            listing = subprocess.run(
                ["objdump", "-D", "-b", "binary", "-m", "i386:x86-64", f"--adjust-vma={start:#x}", path],
                capture_output=True,
                text=True,
                check=True,
            ).stdout
            code.append([])
            for line in listing.splitlines():
                match = _INSTRUCTION.match(line)
                if not match:
                    continue
                hits = counts[int(match.group(1), 16)]
                kind, width = instruction_kind(match.group(2), match.group(3))
                code[-1].append((int(match.group(1), 16) - start, hits, f"{match.group(2)} {match.group(3)}"))
                by_kind[kind] = by_kind.get(kind, 0) + hits
                by_width[width] = by_width.get(width, 0) + hits
                total += hits
    lines = [f"{function}: {total} samples in its {len(copies)} compiled copies"]
    for title, shares in (("by kind", by_kind), ("by register width", by_width)):
        lines.append(f"  {title}:")
        for key, hits in sorted(shares.items(), key=lambda kv: -kv[1]):
            lines.append(f"    {100 * hits / max(total, 1):6.2f} %  {key}")
    runs = [(k, copy[i : i + WINDOW]) for k, copy in enumerate(code) for i in range(0, len(copy), WINDOW)]
    runs.sort(key=lambda kr: -sum(hits for _, hits, _ in kr[1]))
    for k, run in runs[:windows]:
        share = 100 * sum(hits for _, hits, _ in run) / max(total, 1)
        lines.append(f"  {share:5.1f} % at {run[0][0]:#x}-{run[-1][0]:#x} of copy {k + 1}:")
        lines.extend(f"    {offset:#7x} {hits:6d}  {text}" for offset, hits, text in run)
    return lines


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
    parser.add_argument(
        "--mix",
        metavar="FUNCTION",
        help="a compiled function's samples by instruction kind (its Python name)",
    )
    parser.add_argument(
        "--windows", type=int, default=0, help="with --mix: its hottest runs of 16 instructions, listed"
    )
    args = parser.parse_args()
    if args.robots < 0 or args.threads < 1 or args.seconds <= 0 or args.top < 1 or args.windows < 0:
        parser.error("--robots and --windows must be >= 0, --threads and --top >= 1, --seconds > 0")
    if args.windows and not args.mix:
        parser.error("--windows lists a function's code: give the function with --mix")
    if args.mix and shutil.which("objdump") is None:
        parser.error("--mix needs objdump: apt install binutils (Debian), then run this again")

    env, step = stepper(args.env_id, args.robots, args.threads)
    for _ in range(300):  # every kernel the loop calls is loaded before the map is written
        step()
    ranges = code_ranges(numba_symbols())
    if args.mix and all(name != args.mix for _, _, name in ranges):
        sys.exit(
            f"--mix {args.mix}: no function of that name is compiled for this loop; give one that the "
            "report lists, as soft_snake_gym.physics.lanes.residual"
        )
    map_path = f"/tmp/perf-{os.getpid()}.map"
    write_perf_map(ranges, map_path)
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
        mix = instruction_mix(data, ranges, args.mix, args.windows) if args.mix else []
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
    for line in mix:
        print(line)


if __name__ == "__main__":
    main()
