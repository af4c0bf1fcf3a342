"""Simulator throughput: steps per second and simulated seconds per wall-clock second.

Two ways of driving the simulator are timed, both with the thesis gaits as inputs:
``step()`` (one Python call per control step, as an environment does) and ``advance(n)``
(``n`` = 10 steps in one compiled call, inputs refreshed every 10 steps). Runs on one core
(``NUMBA_NUM_THREADS`` does not matter: the single-robot step is serial).

    python scripts/bench_simulator.py            # all cases, ~1 s each
    python scripts/bench_simulator.py --seconds 3 --json bench.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from soft_snake_gym import Integrator, Rod, SimConfig, Simulator, body_from_curvature
from soft_snake_gym.gaits import length_wave, serpenoid, serpenoid_phase

BODY_LENGTH, BODY_MASS = 1.62, 7.2  # the thesis robot: 9 edges of 0.18 m and 0.8 kg


def make(medium: str, method: str, N: int) -> tuple[Simulator, np.ndarray, np.ndarray]:
    """A simulator in its gait's initial shape and a table of one gait cycle of inputs."""
    rod = Rod(N=N, edge_length=BODY_LENGTH / (N - 1), edge_mass=BODY_MASS / (N - 1))
    sim = Simulator(SimConfig(rod=rod, medium=medium, integrator=Integrator(method=method)))
    h = sim.h
    if medium == "water":
        # the thesis gait (alpha = pi/6 at delta = pi/4, N = 10); the same body shape at any N
        omega, delta = 2 * np.pi / 3, 2 * np.pi / (N - 2)
        alpha = np.pi / 6 * delta / (np.pi / 4)
        times = np.arange(round(2 * np.pi / omega / h)) * h
        k0, _ = serpenoid(serpenoid_phase(0.0, N - 2, omega, delta), omega, alpha)
        sim.reset(x=body_from_curvature(k0, sim.lbar), kbar=k0)
        u_k = np.array(
            [serpenoid(serpenoid_phase(t + h / 2, N - 2, omega, delta), omega, alpha)[1] for t in times]
        )
        return sim, u_k, np.zeros((len(times), N - 1))
    eps, omega, delta = 0.2, np.pi, 2 * np.pi / (N - 1)
    times = np.arange(round(2 * np.pi / omega / h)) * h
    l0 = rod.edge_length
    lb0, _ = length_wave(0.0, N - 1, l0, eps, omega, delta)
    sim.reset(x=body_from_curvature(np.zeros(N - 2), lb0), lbar=lb0)
    u_l = np.array([length_wave(t + h / 2, N - 1, l0, eps, omega, delta)[1] for t in times])
    return sim, np.zeros((len(times), N - 2)), u_l


def run(medium: str, method: str, N: int, chunk: int, seconds: float) -> dict:
    """Time ``sim.advance(chunk, ...)`` for about ``seconds`` of wall time; returns one result row."""
    sim, u_k, u_l = make(medium, method, N)
    period = len(u_k)
    sim.advance(1, u_k[0], u_l[0])  # compile / load the cache outside the timing
    steps, n = 0, 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:  # a slow case (thousands of sub-steps) stops early
        i = n % period
        ok = sim.advance(chunk, u_k[i], u_l[i])
        if not ok:
            raise RuntimeError(f"{medium}/{method}/N={N} failed: {sim.failure}")
        n += chunk
        steps += chunk
    wall = time.perf_counter() - start
    rate = steps / wall
    return {
        "medium": medium,
        "method": method,
        "N": N,
        "call": "step()" if chunk == 1 else f"advance({chunk})",
        "substeps": sim.substeps,
        "steps_per_s": rate,
        "sim_s_per_wall_s": rate * sim.h,
        "us_per_step": 1e6 / rate,
        "newton_iterations_last": sim.newton_iterations,
    }


def main() -> None:
    """Time every (medium, method, N) case and print the results (and write them as JSON with ``--json``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="timing per case [s]")
    parser.add_argument("--json", help="also write the results to this JSON file")
    args = parser.parse_args()
    methods = {  # SDIRK2 and BDF2 do not run on the ground (docs/model.md §5a)
        "water": ("sdirk2", "bdf2", "backward_euler", "symplectic_euler"),
        "ground": ("backward_euler", "symplectic_euler"),
    }
    cases = [(m, meth, N) for m in methods for meth in methods[m] for N in (10, 50, 200)]
    rows = []
    header = f"{'medium':7s} {'integrator':17s} {'N':>4s} {'call':12s} {'sub':>4s} {'steps/s':>10s} {'sim s/wall s':>13s} {'us/step':>9s} {'us/step/node':>13s}"
    print(header)
    print("-" * len(header))
    for medium, method, N in cases:
        for chunk in (1, 10):
            r = run(medium, method, N, chunk, args.seconds)
            rows.append(r)
            print(
                f"{medium:7s} {method:17s} {N:4d} {r['call']:12s} {r['substeps']:4d} {r['steps_per_s']:10.0f} "
                f"{r['sim_s_per_wall_s']:13.1f} {r['us_per_step']:9.2f} {r['us_per_step'] / N:13.3f}"
            )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
