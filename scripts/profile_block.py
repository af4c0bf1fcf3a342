"""Where a block's step goes: ``task.block_step`` cut after each of its parts, timed inside numba.

256 eels after 40 random-action steps, one thread, a new random action each. The script runs the
parts of ``block_step`` in its order (each robot's task start, ``lanes.take``, each stage's
``lanes.stage_start``, ``lanes.newton`` and ``lanes.stage_end`` with the sums, ``lanes.energies``
and ``lanes.put``, each robot's step end, ledger and task end) and stops after part ``k``,
every pass from the same saved state; a part's cost is the difference of the cuts after and
before it. The whole ``block_step`` is timed the same way, as a check on the sum. Medians of
interleaved rounds, in µs per eel. ``--integrator bdf2`` cuts BDF2's step instead: one stage
(``lanes.bdf2_start``, ``lanes.newton``, ``lanes.stage_end``) for SDIRK2's two; an eel reset
in the 40 steps has no history and takes its next step alone in the whole ``block_step``,
while the cuts step its lane with the others.

    python scripts/profile_block.py              # ~1 min once compiled
    python scripts/profile_block.py --integrator bdf2
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
from numba import njit

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.envs import task as T
from soft_snake_gym.physics import lanes, stepper
from soft_snake_gym.physics import layout as L

PARTS = (
    "task start (rates from actions)",
    "take: robots into the block",
    "stage 0: start",
    "stage 0: Newton",
    "stage 0: end (powers, sums)",
    "stage 1: start",
    "stage 1: Newton",
    "stage 1: end (powers, sums)",
    "energies; put: block into robots",
    "step end (state check, counters)",
    "ledger",
    "task end (observation, reward, metrics)",
)
PARTS_BDF2 = (
    "task start (rates from actions)",
    "take: robots and history into the block",
    "BDF2 start",
    "Newton",
    "end (powers, sums)",
    *PARTS[-4:],
)


@njit
def _cut(s, t, first, scratch, stop):
    """``block_step``'s parts for the block from ``first`` up to part ``stop`` (1-based), one sub-step."""
    x, p, result, sq, before, state, iters, acc, niter, resid, energy, go, ran, act0 = scratch
    bdf2 = int(s.prm[first, L.P_METHOD]) == L.METHOD_BDF2
    part = 0
    for r in range(lanes.LANES):
        si, ti = T._robot(s, t, first + r)
        sq[r] = T.step_begin(si, ti)
        before[0, r], before[1, r], before[2, r] = T.energies_before(si)
        si.out[L.O_NJAC] = si.out[L.O_NRES] = si.out[L.O_NFACTOR] = 0.0
    part += 1
    if part == stop:
        return
    lanes.take(s, t.uk, first, x, p)
    if bdf2:
        lanes.take_history(s, first, x)
    part += 1
    dt = s.prm[first, L.P_H]
    go[:] = True
    state[:] = L.OK
    if bdf2:
        if part == stop:
            return
        lanes.bdf2_start(x, p, dt)
        act0[:] = x.power[0]
        part += 1
        if part == stop:
            return
        lanes.newton(s, first, go, x, p, 2.0 * dt / 3.0, result)
        part += 1
        if part == stop:
            return
        lanes.stage_end(x, p, 1)
        for r in range(lanes.LANES):
            state[r], iters[r], acc[0, r] = int(result[0, r]), int(result[1, r]), result[2, r]
            acc[1, r], acc[2, r], acc[3, r], acc[4, r] = stepper.implicit_sums(
                dt, act0[r], x.power[0, r], x.power[1, r], result[3, r], result[4, r]
            )
        part += 1
    for stage in range(0 if bdf2 else 2):
        if part == stop:
            return
        lanes.stage_start(x, p, stage, dt)
        part += 1
        if part == stop:
            return
        lanes.newton(s, first, go, x, p, stepper.GAMMA * dt, result)
        part += 1
        if part == stop:
            return
        lanes.stage_end(x, p, stage)
        for r in range(lanes.LANES):
            newton = (int(result[0, r]), int(result[1, r]), result[2, r], result[3, r], result[4, r])
            sums = (iters[r], acc[0, r], acc[1, r], acc[2, r], acc[3, r], acc[4, r])
            state[r], (iters[r], acc[0, r], acc[1, r], acc[2, r], acc[3, r], acc[4, r]) = (
                stepper.sdirk2_stage_sums(stage, dt, True, newton, x.power[0, r], x.power[1, r], sums)
            )
        part += 1
    if part == stop:
        return
    lanes.energies(x, p)
    for r in range(lanes.LANES):
        lanes.put_state(s, first + r, x, r, x.v)
        if bdf2:
            lanes.put_history(s, first + r, x, r)
    part += 1
    if part == stop:
        return
    for r in range(lanes.LANES):
        si, ti = T._robot(s, t, first + r)
        stepper.end_step(si, L.OK, iters[r], acc[0, r], acc[1, r], acc[2, r], acc[3, r], acc[4, r])
        if stop > part + 1:
            si.out[L.O_E_KIN], si.out[L.O_E_ELASTIC] = x.energy[0, r], x.energy[1, r]
            stepper.ledger(si.out)
        if stop > part + 2:
            lanes.curvatures_into(x, r, ti.raw)
            T.step_end(si, ti, L.OK, sq[r], (before[0, r], before[1, r], before[2, r]), True)


@njit
def _loop(k, s, t, f0, i0, t0, status, stop):
    """``k`` passes from the saved blocks: cut after part ``stop`` (0: restore only; -1: all of ``block_step``)."""
    scratch = T._block_scratch(s.q.shape[1])
    active = np.ones(status.size, dtype=np.bool_)
    sb, tb = T._borrowed_stacks(s, t)  # as the batched kernels take them
    for _ in range(k):
        s.f[:] = f0
        s.ibuf[:] = i0
        t.f[:] = t0
        for b in range(status.size // lanes.LANES):
            if stop == -1:
                T.block_step(active, sb, tb, b * lanes.LANES, status, scratch)
            elif stop > 0:
                _cut(sb, tb, b * lanes.LANES, scratch, stop)


def main() -> None:
    """Time the cuts in interleaved rounds and print each part's cost and the whole step's."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--passes", type=int, default=200)
    parser.add_argument("--integrator", choices=["sdirk2", "bdf2"], default="sdirk2")
    args = parser.parse_args()
    n = args.robots
    parts = PARTS_BDF2 if args.integrator == "bdf2" else PARTS
    venv = gym.make_vec("SoftEel-v0", num_envs=n, num_threads=1, integrator={"method": args.integrator})
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(40):
        venv.step(rng.uniform(-1, 1, (n, 8)).astype(np.float32))
    s, t = venv.batch.sim, venv.batch.task
    t.act[:] = rng.uniform(-1, 1, t.act.shape)
    saved = (s.f.copy(), s.ibuf.copy(), t.f.copy())
    status = np.zeros(n, dtype=np.int64)
    cuts = list(range(len(parts) + 1)) + [-1]
    times = {c: [] for c in cuts}
    for c in cuts:
        _loop(1, s, t, *saved, status, c)
    for _ in range(args.rounds):
        for c in cuts:
            start = time.perf_counter()
            _loop(args.passes, s, t, *saved, status, c)
            times[c].append((time.perf_counter() - start) / args.passes / n * 1e6)
    us = {c: float(np.median(v)) for c, v in times.items()}
    print(
        f"{n} eels on {args.integrator}, one thread, µs per eel "
        f"(medians of {args.rounds} rounds of {args.passes} passes):"
    )
    total = 0.0
    for k, name in enumerate(parts, start=1):
        part = us[k] - us[k - 1]
        total += part
        print(f"  {name:42s} {part:6.3f}")
    print(f"  {'sum of the parts':42s} {total:6.3f}")
    print(f"  {'block_step, whole':42s} {us[-1] - us[0]:6.3f}")


if __name__ == "__main__":
    main()
