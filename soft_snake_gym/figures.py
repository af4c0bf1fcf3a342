"""Figures: sweep heatmaps, a swimming snapshot over one gait cycle, and centralized vs
decentralized control from rest. Every function writes PNGs and returns their paths."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from soft_snake_gym.cli import subcommand

__all__ = ["sweep_heatmaps", "swim_snapshots", "controller_comparison", "rollout", "make_all_figures"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


_AXIS = {
    "alpha": ("amplitude alpha", "rad"),
    "omega": ("frequency omega", "rad/s"),
    "mu_s": ("static friction mu_s", "-"),
    "mu_d": ("kinetic friction mu_d", "-"),
}


def cell_edges(values: np.ndarray) -> np.ndarray:
    """Edges (n + 1,) of the heatmap cells of sorted grid values (n,): halfway between
    neighbours, and at the first and last value, so the axes span the grid and no more (a
    value on the border owns the half cell inside it). One value gets a cell of ±5 %."""
    values = np.asarray(values, dtype=float)
    if values.size == 1:
        half = 0.05 * abs(values[0]) or 0.5
        return np.array([values[0] - half, values[0] + half])
    return np.concatenate([values[:1], (values[1:] + values[:-1]) / 2, values[-1:]])


def sweep_heatmaps(study: Any, rows: list[dict[str, Any]], out_dir: str | Path) -> list[Path]:
    """One PNG per metric of ``study`` (a :class:`~soft_snake_gym.sweep.Study`), one panel per
    controller (or per bending modulus), cells annotated with their values."""
    plt = _plt()
    out_dir = Path(out_dir)
    if not rows:
        return []
    if study.name == "inch-friction":
        xk, yk, panel_key = "mu_s", "mu_d", "controller"
    else:
        xk, yk = "omega", "alpha"
        panel_key = "E_bend" if study.name == "swim-stiffness" else "controller"
    panels = list(dict.fromkeys(r[panel_key] for r in rows))
    xs = np.array(sorted({r[xk] for r in rows}))
    ys = np.array(sorted({r[yk] for r in rows}))
    paths = []
    for key, label, unit in study.metrics:
        grids = []
        for panel in panels:
            z = np.full((ys.size, xs.size), np.nan)
            for r in rows:
                if r[panel_key] == panel:
                    v = r.get(key, math.nan)
                    if r.get("failure"):
                        v = math.nan
                    z[np.searchsorted(ys, r[yk]), np.searchsorted(xs, r[xk])] = v
            grids.append(z)
        finite = np.concatenate([g[np.isfinite(g)] for g in grids]) if grids else np.array([])
        if finite.size == 0:
            continue
        vmin, vmax = float(finite.min()), float(finite.max())
        fig, axes = plt.subplots(
            1, len(panels), figsize=(4.2 * len(panels) + 0.8, 3.8), squeeze=False, constrained_layout=True
        )
        xe, ye = cell_edges(xs), cell_edges(ys)
        xc, yc = (xe[1:] + xe[:-1]) / 2, (ye[1:] + ye[:-1]) / 2  # centres of the drawn cells
        for ax, panel, z in zip(axes[0], panels, grids, strict=True):
            im = ax.pcolormesh(xe, ye, np.ma.masked_invalid(z), cmap="viridis", vmin=vmin, vmax=vmax)
            for values, axis in ((xs, ax.xaxis), (ys, ax.yaxis)):
                if values.size <= 8:  # tick the grid's own values
                    axis.set_ticks(values, [f"{v:.3g}" for v in values])
            if z.size <= 100:
                for iy, y in enumerate(ys):
                    for ix, x in enumerate(xs):
                        if np.isfinite(z[iy, ix]):
                            v = z[iy, ix]
                            ax.text(
                                xc[ix],
                                yc[iy],
                                f"{v:.3g}",
                                ha="center",
                                va="center",
                                fontsize=6,
                                color="white" if v < (vmin + vmax) / 2 else "black",
                            )
                        elif any(r[panel_key] == panel and r[xk] == x and r[yk] == y for r in rows):
                            ax.text(xc[ix], yc[iy], "fail", ha="center", va="center", fontsize=6, color="red")
            name = f"E_bend = {panel:.3g} Pa" if panel_key == "E_bend" else str(panel)
            ax.set_title(name)
            ax.set_xlabel(f"{_AXIS[xk][0]} [{_AXIS[xk][1]}]")
            ax.set_ylabel(f"{_AXIS[yk][0]} [{_AXIS[yk][1]}]")
        fig.colorbar(im, ax=axes[0].tolist(), label=f"{label} [{unit}]")
        fig.suptitle(f"{study.name}: {label}")
        path = out_dir / f"{study.name}_{key}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


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
    import gymnasium as gym

    from soft_snake_gym.envs import register_envs
    from soft_snake_gym.agents import make_policy

    register_envs()
    env = gym.make(env_id, max_episode_steps=int(round(seconds / 0.01)) + 1, **(env_kwargs or {}))
    policy = make_policy(policy_spec, env)
    obs, _ = env.reset(seed=0, options=reset_options)
    sim = env.unwrapped.sim
    steps = int(round(seconds / env.unwrapped.dt))
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
    """Body snapshots over one gait cycle of the thesis gait after ``settle_cycles`` cycles,
    coloured by time, with the head, tail and centre-of-mass traces."""
    plt = _plt()
    from soft_snake_gym.policies.open_loop import SerpenoidParams

    omega = SerpenoidParams().omega
    period = 2 * math.pi / omega
    tr = rollout(
        "SoftEel-v0", policy_spec, (settle_cycles + 1) * period, env_kwargs={"reset_noise_scale": 0.0}
    )
    sel = tr["t"] >= settle_cycles * period - 1e-9
    t, x, com = tr["t"][sel], tr["x"][sel], tr["com"][sel]
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    t_rel = t - t[0]
    for k in np.linspace(0, t.size - 1, snapshots).astype(int):
        ax.plot(x[k, :, 0], x[k, :, 1], "-o", ms=2.5, lw=1.5, color=cmap(t_rel[k] / t_rel[-1]))
    ax.plot(x[:, -1, 0], x[:, -1, 1], "--", color="crimson", lw=1, label="head (node N-1)")
    ax.plot(x[:, 0, 0], x[:, 0, 1], ":", color="gray", lw=1, label="tail (node 0)")
    ax.plot(com[:, 0], com[:, 1], "-", color="black", lw=2, label="centre of mass")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, t_rel[-1]))
    fig.colorbar(sm, ax=ax, label="time within the cycle [s]")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(
        f"SoftEel-v0, {policy_spec}, thesis gait (alpha = pi/6, omega = 2pi/3 rad/s): "
        f"cycle {settle_cycles + 1}",
        fontsize=9,
    )
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def rest_start_options(n_nodes: int = 10) -> dict[str, np.ndarray]:
    """Reset options: at rest, curvature (and rest curvature) equal to the thesis serpenoid at
    t = 0 (docs/model.md §7, the decentralized start)."""
    from soft_snake_gym.gaits import serpenoid, serpenoid_phase
    from soft_snake_gym.policies.open_loop import SerpenoidParams

    p = SerpenoidParams()
    kd, _ = serpenoid(
        serpenoid_phase(0.0, n_nodes - 2, p.omega, 2 * math.pi / (n_nodes - 2)), p.omega, p.alpha
    )
    return {"kbar": kd}


def controller_comparison(
    out: str | Path,
    seconds: float = 6.0,
    centralized: str = "pid:Kd=2,Ki=1",
    decentralized: str = "decentralized",
) -> tuple[Path, dict[str, float]]:
    """Centralized vs decentralized PID from rest: curvature error, curvature and input per
    node over time. Returns the PNG and the mean error after 2 s of each."""
    plt = _plt()
    runs = {
        name: rollout(
            "SoftEel-v0",
            spec,
            seconds,
            env_kwargs={"reset_noise_scale": 0.0},
            reset_options=rest_start_options(),
        )
        for name, spec in (("centralized", centralized), ("decentralized", decentralized))
    }
    fig, axes = plt.subplots(3, 2, figsize=(10, 7.5), sharex=True, sharey="row", constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    numbers = {}
    for col, (name, tr) in enumerate(runs.items()):
        t = tr["t"][:-1]
        n = tr["error"].shape[1]
        for j in range(n):
            c = cmap(j / max(1, n - 1))
            axes[0, col].plot(t, tr["error"][:, j], color=c, lw=0.9, label=f"node {j + 1}")
            axes[1, col].plot(tr["t"], tr["kappa"][:, j], color=c, lw=0.9)
            axes[2, col].plot(t, tr["u"][:, j], color=c, lw=0.9)
        spec = centralized if name == "centralized" else decentralized
        axes[0, col].set_title(f"{name} ({spec})")
        numbers[name] = float(tr["error"][t >= 2.0].mean())
    axes[0, 0].set_ylabel("|kappa_des - kappa| [-]")
    axes[1, 0].set_ylabel("curvature kappa [-]")
    axes[2, 0].set_ylabel("input u [1/s]")
    for ax in axes[2]:
        ax.set_xlabel("time [s]")
    axes[0, 1].legend(fontsize=6, ncol=2, loc="upper right")
    fig.suptitle(
        "From rest, curvature = desired at t = 0: mean error after 2 s "
        f"{numbers['centralized']:.4f} (centralized) vs {numbers['decentralized']:.4f} (decentralized)",
        fontsize=9,
    )
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out, numbers


def make_all_figures(out_dir: str | Path) -> dict[str, Any]:
    """The two trajectory figures; returns their paths and the comparison numbers."""
    out_dir = Path(out_dir)
    snap = swim_snapshots(out_dir / "swim_snapshots.png")
    comp, numbers = controller_comparison(out_dir / "centralized_vs_decentralized.png")
    return {"snapshots": snap, "comparison": comp, "comparison_errors": numbers}


def _figures_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="docs/img", help="folder for the PNGs (default docs/img)")


@subcommand(
    "figures", "draw the swimming snapshot and centralized-vs-decentralized figures", _figures_arguments
)
def _figures(args: argparse.Namespace) -> int:
    res = make_all_figures(args.out)
    print(f"wrote {res['snapshots']} and {res['comparison']}")
    e = res["comparison_errors"]
    print(
        f"mean curvature error after 2 s: centralized {e['centralized']:.4f}, "
        f"decentralized {e['decentralized']:.4f}"
    )
    return 0
