"""The trajectory figures.

A swimming snapshot over one gait cycle, and centralized vs decentralized control from rest. Each
function runs the episodes, draws them with :mod:`soft_snake_gym.plots` and returns the PNG's path.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from soft_snake_gym import plots
from soft_snake_gym.agents import make_policy
from soft_snake_gym.envs import register_envs
from soft_snake_gym.gaits import SerpenoidParams, serpenoid, serpenoid_phase
from soft_snake_gym.studies.sweep import control_step

__all__ = [
    "COMPARISON_CENTRALIZED",
    "SETTLED_AFTER",
    "controller_comparison",
    "make_all_figures",
    "mean_error_after",
    "rest_start_options",
    "rollout",
    "swim_snapshots",
]

SETTLED_AFTER = 2.0
"""Time [s] after which the comparison's mean curvature error is taken (the start-up is over)."""

COMPARISON_CENTRALIZED = "pid:Kd=2,Ki=1"
"""The centralized controller of :func:`controller_comparison`: the decentralized one's gains."""


def rollout(
    env_id: str,
    policy_spec: str,
    seconds: float,
    env_kwargs: dict | None = None,
    reset_options: dict | None = None,
) -> dict[str, np.ndarray]:
    """Run one episode of a baseline and keep its trajectory.

    Returns:
        ``t`` (T,), ``x`` (T, N, 2), ``com`` (T, 2), ``kappa``/``error``/``u`` (T, n) where the
        policy is a bending controller (error: the policy's own |desired - measured|).
    """
    register_envs()
    steps = int(round(seconds / control_step(env_id, env_kwargs)))
    env = gym.make(env_id, max_episode_steps=steps + 1, **(env_kwargs or {}))
    policy = make_policy(policy_spec, env)
    obs, _ = env.reset(seed=0, options=reset_options)
    sim = env.unwrapped.sim
    t, xs, com, kappa, err, u = [0.0], [sim.x], [sim.com], [sim.kappa], [], []
    state, start = None, np.array([True])
    for _ in range(steps):
        action, state = policy.predict(obs[None], state, start)
        start = np.array([False])
        err.append(policy.last_error[0])
        u.append(policy.last_rates[0])
        obs, _, terminated, truncated, info = env.step(action[0])
        t.append(sim.time)
        xs.append(sim.x)
        com.append(sim.com)
        kappa.append(sim.kappa)
        if terminated or truncated:
            break
    env.close()
    return {
        "t": np.array(t),
        "x": np.array(xs),
        "com": np.array(com),
        "kappa": np.array(kappa),
        "error": np.array(err),
        "u": np.array(u),
    }


def swim_snapshots(
    out: str | Path, policy_spec: str = "pid", settle_cycles: int = 2, snapshots: int = 12
) -> Path:
    """Body snapshots over one gait cycle of the thesis gait, coloured by time.

    After ``settle_cycles`` cycles, with the head, tail and centre-of-mass traces.
    """
    omega = SerpenoidParams().omega
    period = 2 * math.pi / omega
    tr = rollout(
        "SoftEel-v0", policy_spec, (settle_cycles + 1) * period, env_kwargs={"reset_noise_scale": 0.0}
    )
    sel = tr["t"] >= settle_cycles * period - 1e-9
    cycle = {"t": tr["t"][sel], "x": tr["x"][sel], "com": tr["com"][sel]}
    title = (
        f"SoftEel-v0, {policy_spec}, thesis gait (alpha = pi/6, omega = 2pi/3 rad/s): "
        f"cycle {settle_cycles + 1}"
    )
    return plots.swim_snapshots(cycle, out, title, snapshots)


def rest_start_options(n_nodes: int = 10) -> dict[str, np.ndarray]:
    """Reset options.

    At rest, curvature (and rest curvature) equal to the thesis serpenoid at t = 0 (docs/model.md
    §7, the decentralized start).
    """
    p = SerpenoidParams()
    kd, _ = serpenoid(
        serpenoid_phase(0.0, n_nodes - 2, p.omega, 2 * math.pi / (n_nodes - 2)), p.omega, p.alpha
    )
    return {"kbar": kd}


def mean_error_after(trajectory: dict[str, np.ndarray], start: float = SETTLED_AFTER) -> float:
    """Mean curvature error [-] of a :func:`rollout` over the steps from ``start`` [s] on."""
    return float(trajectory["error"][trajectory["t"][:-1] >= start].mean())


def controller_comparison(
    out: str | Path,
    seconds: float = 6.0,
    centralized: str = COMPARISON_CENTRALIZED,
    decentralized: str = "decentralized:startup=0",
) -> tuple[Path, dict[str, float]]:
    """Centralized vs decentralized PID from rest: curvature error, curvature and input per node over time.

    The decentralized chain runs from the first step (``startup=0``), as the sources start it.

    Returns the PNG and the mean error after :data:`SETTLED_AFTER` of each.
    """
    specs = {"centralized": centralized, "decentralized": decentralized}
    runs = {
        name: rollout(
            "SoftEel-v0",
            spec,
            seconds,
            env_kwargs={"reset_noise_scale": 0.0},
            reset_options=rest_start_options(),
        )
        for name, spec in specs.items()
    }
    numbers = {name: mean_error_after(tr) for name, tr in runs.items()}
    return plots.controller_comparison(runs, specs, numbers, out), numbers


def make_all_figures(out_dir: str | Path) -> dict[str, Any]:
    """The two trajectory figures; returns their paths and the comparison numbers."""
    out_dir = Path(out_dir)
    snap = swim_snapshots(out_dir / "swim_snapshots.png")
    comp, numbers = controller_comparison(out_dir / "centralized_vs_decentralized.png")
    return {"snapshots": snap, "comparison": comp, "comparison_errors": numbers}
