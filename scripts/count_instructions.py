"""Instructions per robot step, by part, counted by valgrind's callgrind (independent of the load).

Wall-clock timings on a shared machine move with the other jobs; instruction counts do not.
This script runs the parts of a step in compiled loops and, under callgrind, brackets each with
callgrind's client requests (a tiny C helper, compiled here with ``cc``), so every part gets
its own dump; outside valgrind the requests do nothing and it just runs (and fills the numba
caches, which a valgrind run needs: compiling under valgrind takes minutes).

    python scripts/count_instructions.py                       # once, to compile and cache
    valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.%p python scripts/count_instructions.py
    python scripts/count_instructions.py --report /tmp/cg.<pid>

Instructions are not time (a divide costs more than an add, a cache miss more than both) but
they are what the kernels' changes change, and they count the same on a busy machine.
"""

from __future__ import annotations

import argparse
import ctypes
import glob
import math
import os
import subprocess
import tempfile

import gymnasium as gym
import numpy as np
from numba import njit

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.envs import observe
from soft_snake_gym.envs import task as T
from soft_snake_gym.gaits import serpenoid, serpenoid_phase
from soft_snake_gym.physics import banded, geometry, layout, stepper
from soft_snake_gym.physics.layout import SimArrays

ROBOTS, STEPS = 64, 40  # robot steps per batched part: ROBOTS * STEPS
K = 2000  # calls per compiled part

_HELPER = r"""
#include <valgrind/callgrind.h>
void cg_zero(void) { CALLGRIND_ZERO_STATS; }
void cg_dump(const char *name) { CALLGRIND_DUMP_STATS_AT(name); }
"""


def _helper():
    """The ctypes handle of the client-request helper, or None where no compiler or header exists."""
    d = tempfile.mkdtemp()
    src, lib = os.path.join(d, "cg.c"), os.path.join(d, "cg.so")
    with open(src, "w") as f:
        f.write(_HELPER)
    try:
        subprocess.run(["cc", "-O1", "-shared", "-fPIC", src, "-o", lib], check=True, capture_output=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    h = ctypes.CDLL(lib)
    h.cg_dump.argtypes = [ctypes.c_char_p]
    return h


@njit(cache=True)
def _loop_residual(k, sa, jac):
    s = 0.0
    for _ in range(k):
        s += stepper._be_residual(sa, 0.01, layout.MEDIUM_WATER, jac)[0]
    return s


@njit(cache=True)
def _loop_factor(k, J, Jw, piv, b, bw):
    for _ in range(k):
        Jw[:, :] = J
        bw[:] = b
        banded.band_factor(Jw, piv, Jw.shape[0], banded.PIVOT_THRESHOLD)
        banded.band_solve(Jw, piv, Jw.shape[0], bw)


@njit(cache=True)
def _loop_lu(k, J, Jw, piv, b, bw):
    for _ in range(k):
        Jw[:, :] = J
        bw[:] = b
        banded.band_lu(Jw, piv, Jw.shape[0])
        banded.band_solve(Jw, piv, Jw.shape[0], bw)


@njit(cache=True)
def _loop_solve(k, Jw, piv, b, bw):
    for _ in range(k):
        bw[:] = b
        banded.band_solve(Jw, piv, Jw.shape[0], bw)


@njit(cache=True)
def _loop_copy(k, J, Jw, b, bw):
    for _ in range(k):
        Jw[:, :] = J
        bw[:] = b


@njit(cache=True)
def _loop_observe(k, q, v, kbar, w, low, high, raw, obs):
    s = 0.0
    geo = np.empty((2, q.size))
    for _ in range(k):
        geometry.edge_geometry(q, geo)  # counted with the observation, as before steps left it made
        s += observe.swim_observation(q, v, kbar, w, 0.0, low, high, raw, obs, geo)
    return s


def _gait(steps: int, robots: int) -> np.ndarray:
    n, omega, alpha = 8, 2 * math.pi / 3, math.pi / 6
    t = (np.arange(steps) + 0.5) * 0.01
    r = np.array([serpenoid(serpenoid_phase(ti, n, omega, 2 * math.pi / n), omega, alpha)[1] for ti in t])
    return np.repeat((r / (2 * math.pi))[:, None, :], robots, axis=1).astype(np.float32)


def run(h) -> None:
    """Run every part, each bracketed by a zero and a dump of callgrind's counters."""

    def part(name, fn):
        fn()  # warm: first calls load code
        if h:
            h.cg_zero()
        fn()
        if h:
            h.cg_dump(name.encode())

    rng = np.random.default_rng(0)
    for env_id in ("SoftEel-v0", "SoftWorm-v0"):
        venv = gym.make_vec(env_id, num_envs=ROBOTS, num_threads=1)
        venv.reset(seed=0)
        shape = venv.action_space.shape
        A = rng.uniform(-1, 1, (STEPS,) + shape).astype(np.float32)
        sim, tsk, st = tuple(venv.batch.sim), tuple(venv.batch.task), venv._status
        on = np.ones(ROBOTS, dtype=np.bool_)

        def kernel(A=A, sim=sim, tsk=tsk, st=st, on=on, venv=venv):
            for a in A:
                venv.batch.task.act[:] = a
                T.batch_step_serial(on, sim, tsk, st)

        def vstep(A=A, venv=venv):
            for a in A:
                venv.step(a)

        tag = env_id.split("-")[0]
        part(f"{tag} batch_step_serial random x{ROBOTS * STEPS}", kernel)
        part(f"{tag} SoftVectorEnv.step random x{ROBOTS * STEPS}", vstep)
        if env_id == "SoftEel-v0" and hasattr(layout, "P_CHORD"):  # full Newton, for comparison
            venv.batch.sim.prm[:, layout.P_CHORD] = 0.0
            part(f"{tag} batch_step_serial random, no chord steps x{ROBOTS * STEPS}", kernel)
            venv.batch.sim.prm[:, layout.P_CHORD] = venv.envs[0].sim.config.integrator.newton_chord_rate
        if env_id == "SoftEel-v0":
            G = _gait(STEPS, ROBOTS)
            part(f"{tag} batch_step_serial gait x{ROBOTS * STEPS}", lambda G=G, kernel=kernel: kernel(G))
        env = gym.make(env_id)
        env.reset(seed=0)
        a1 = A[:, 0]

        def single(env=env, a1=a1):
            for a in a1:
                _, _, term, trunc, _ = env.step(a)
                if term or trunc:
                    env.reset()

        part(f"{tag} gym.make step random x{STEPS}", single)
        if env_id == "SoftEel-v0":
            _compiled_parts(part, env.unwrapped)


def _compiled_parts(part, u) -> None:
    """The compiled parts of an eel's step, on ``u``'s current state."""
    sa = SimArrays(*(a.copy() for a in u.sim.arrays))
    q, v, kbar, lbar, prm, buf, J, ibuf, out = sa[:9]  # the named arrays (sa.f is their block)
    _loop_residual(1, sa, True)
    J0 = J.copy()
    piv = ibuf[layout.I_PIV].copy()
    Jw, b, bw = np.empty_like(J), np.ones(q.size), np.empty(q.size)
    part(f"residual+Jacobian x{K}", lambda: _loop_residual(K, sa, True))
    part(f"residual only x{K}", lambda: _loop_residual(K, sa, False))
    part(f"copy (subtract) x{K}", lambda: _loop_copy(K, J0, Jw, b, bw))
    part(f"pivoted band LU + solve x{K}", lambda: _loop_lu(K, J0, Jw, piv, b, bw))
    if hasattr(banded, "band_factor"):  # the threshold-pivoting factorization, where it exists
        part(f"band_factor + solve x{K}", lambda: _loop_factor(K, J0, Jw, piv, b, bw))
        part(f"band_solve only x{K}", lambda: _loop_solve(K, Jw, piv, b, bw))
    t = u.task
    raw, obs = t.raw.copy(), t.obs.copy()
    part(f"observation x{K}", lambda: _loop_observe(K, q, v, kbar, t.w, t.low, t.high, raw, obs))


def report(prefix: str) -> None:
    """Print instructions per unit for each dump of a callgrind run (files ``prefix.N``)."""
    rows = []
    for f in sorted(glob.glob(prefix + ".*"), key=lambda p: int(p.rsplit(".", 1)[1])):
        name, total = None, None
        with open(f) as fh:
            for line in fh:
                if line.startswith("desc: Trigger: Client Request: "):
                    name = line.split(": ", 3)[3].strip()
                elif line.startswith("totals:") or line.startswith("summary:"):
                    total = int(line.split()[1])
        if name and total is not None:
            rows.append((name, total))
    copy = next((t for n, t in rows if n.startswith("copy")), 0)
    for name, total in rows:
        per = int(name.rsplit("x", 1)[1])
        net = total - copy if ("LU" in name or "band_factor +" in name) else total
        print(f"  {name:<50} {net / per:>12,.0f} instructions per call")


def main() -> None:
    """Run the parts (under valgrind to count), or print a finished run's counts."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--report", help="print the counts of a callgrind run's dumps (its out-file prefix)")
    args = p.parse_args()
    if args.report:
        report(args.report)
    else:
        run(_helper())


if __name__ == "__main__":
    main()
