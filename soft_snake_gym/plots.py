"""Every figure of the package.

Sweep heatmaps, the swimming snapshot, centralized vs decentralized control, the training learning
curve, the comparison bar chart and the benchmark chart.

Each function draws from numbers it is given (it runs no simulation) on its own
:class:`matplotlib.figure.Figure` with an Agg canvas, writes a PNG and returns its path: no
pyplot, no global backend (``matplotlib.use``), so drawing never disturbs a caller's own figures
or interactive session. matplotlib is imported when the first figure is drawn (importing it
takes about a second; ``soft-snake --help`` does not need it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "benchmark_chart",
    "cell_edges",
    "comparison_chart",
    "controller_comparison",
    "learning_curve",
    "robustness_chart",
    "swim_snapshots",
    "sweep_heatmaps",
]


def _figure(**kwargs: Any):
    """A new ``Figure`` on its own Agg canvas (``kwargs`` go to ``Figure``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: str | Path, dpi: int) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def _cmap(name: str):
    import matplotlib

    return matplotlib.colormaps[name]


_AXIS = {
    "alpha": ("amplitude alpha", "rad"),
    "omega": ("frequency omega", "rad/s"),
    "mu_s": ("static friction mu_s", "-"),
    "mu_d": ("kinetic friction mu_d", "-"),
}


def cell_edges(values: np.ndarray) -> np.ndarray:
    """Edges (n + 1,) of the heatmap cells of sorted grid values (n,).

    Halfway between neighbours, and at the first and last value, so the axes span the grid and no
    more (a value on the border owns the half cell inside it). One value gets a cell of ±5 %.
    """
    values = np.asarray(values, dtype=float)
    if values.size == 1:
        half = 0.05 * abs(values[0]) or 0.5
        return np.array([values[0] - half, values[0] + half])
    return np.concatenate([values[:1], (values[1:] + values[:-1]) / 2, values[-1:]])


def sweep_heatmaps(study: Any, rows: list[dict[str, Any]], out_dir: str | Path) -> list[Path]:
    """One PNG per metric of ``study`` (a :class:`~soft_snake_gym.studies.sweep.Study`).

    One panel per controller (or per bending modulus), cells annotated with their values.
    """
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
        fig = _figure(figsize=(4.2 * len(panels) + 0.8, 3.8), constrained_layout=True)
        axes = fig.subplots(1, len(panels), squeeze=False)
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
        paths.append(_save(fig, out_dir / f"{study.name}_{key}.png", dpi=110))
    return paths


def swim_snapshots(
    trajectory: dict[str, np.ndarray], out: str | Path, title: str, snapshots: int = 12
) -> Path:
    """Body snapshots over a stretch of a swimming trajectory, coloured by time.

    With the head, tail and centre-of-mass traces.

    Args:
        trajectory: ``t`` (T,) [s], ``x`` (T, N, 2) [m], ``com`` (T, 2) [m] of the stretch.
        out: the PNG.
        title: the axes' title.
        snapshots: bodies drawn, evenly spaced in the stretch.
    """
    import matplotlib.cm
    import matplotlib.colors

    t, x, com = trajectory["t"], trajectory["x"], trajectory["com"]
    fig = _figure(figsize=(8, 4), constrained_layout=True)
    ax = fig.subplots()
    cmap = _cmap("viridis")
    t_rel = t - t[0]
    for k in np.linspace(0, t.size - 1, snapshots).astype(int):
        ax.plot(x[k, :, 0], x[k, :, 1], "-o", ms=2.5, lw=1.5, color=cmap(t_rel[k] / t_rel[-1]))
    ax.plot(x[:, -1, 0], x[:, -1, 1], "--", color="crimson", lw=1, label="head (node N-1)")
    ax.plot(x[:, 0, 0], x[:, 0, 1], ":", color="gray", lw=1, label="tail (node 0)")
    ax.plot(com[:, 0], com[:, 1], "-", color="black", lw=2, label="centre of mass")
    sm = matplotlib.cm.ScalarMappable(cmap=cmap, norm=matplotlib.colors.Normalize(0, t_rel[-1]))
    fig.colorbar(sm, ax=ax, label="time within the cycle [s]")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=9)
    return _save(fig, out, dpi=120)


def controller_comparison(
    runs: dict[str, dict[str, np.ndarray]], specs: dict[str, str], errors: dict[str, float], out: str | Path
) -> Path:
    """Curvature error, curvature and input per node over time, one column per controller.

    Args:
        runs: controller name -> trajectory with ``t`` (T + 1,) [s], ``kappa`` (T + 1, n) [-],
            ``error`` (T, n) [-] and ``u`` (T, n) [1/s].
        specs: controller name -> its policy spec (in the column title).
        errors: ``centralized`` and ``decentralized`` mean errors (in the figure title).
        out: the PNG.
    """
    fig = _figure(figsize=(10, 7.5), constrained_layout=True)
    axes = fig.subplots(3, 2, sharex=True, sharey="row")
    cmap = _cmap("viridis")
    for col, (name, tr) in enumerate(runs.items()):
        t = tr["t"][:-1]
        n = tr["error"].shape[1]
        for j in range(n):
            c = cmap(j / max(1, n - 1))
            axes[0, col].plot(t, tr["error"][:, j], color=c, lw=0.9, label=f"node {j + 1}")
            axes[1, col].plot(tr["t"], tr["kappa"][:, j], color=c, lw=0.9)
            axes[2, col].plot(t, tr["u"][:, j], color=c, lw=0.9)
        axes[0, col].set_title(f"{name} ({specs[name]})")
    axes[0, 0].set_ylabel("|kappa_des - kappa| [-]")
    axes[1, 0].set_ylabel("curvature kappa [-]")
    axes[2, 0].set_ylabel("input u [1/s]")
    for ax in axes[2]:
        ax.set_xlabel("time [s]")
    axes[0, 1].legend(fontsize=6, ncol=2, loc="upper right")
    fig.suptitle(
        "From rest, curvature = desired at t = 0: mean error after 2 s "
        f"{errors['centralized']:.4f} (centralized) vs {errors['decentralized']:.4f} (decentralized)",
        fontsize=9,
    )
    return _save(fig, out, dpi=110)


def learning_curve(
    rows: list[dict[str, str]], cfg: Any, metrics: Sequence[tuple[str, str, str]], out: str | Path
) -> Path:
    """A run's evaluations.

    The agent's average speed and cost of transport (mean ± std over the evaluation episodes)
    against environment steps, with the baseline's figures on the same seeds as horizontal lines.

    Args:
        rows: the rows of learning_curve.csv (text, as ``csv.DictReader`` gives them).
        cfg: the run's :class:`~soft_snake_gym.training.TrainConfig`.
        metrics: the two panels' (key, label, unit); the CSV has ``<key>_mean``, ``<key>_std`` and
            ``baseline_<key>``.
        out: the PNG.
    """
    steps = np.array([int(r["timesteps"]) for r in rows])
    fig = _figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2)
    for ax, (key, label, unit) in zip(axes, metrics, strict=True):
        mean = np.array([float(r[f"{key}_mean"]) for r in rows])
        std = np.array([float(r[f"{key}_std"]) for r in rows])
        ax.plot(steps, mean, "o-", ms=3, label=f"{cfg.algo} agent")
        ax.fill_between(steps, mean - std, mean + std, alpha=0.25)
        if f"baseline_{key}" in rows[0]:
            ax.axhline(
                float(rows[0][f"baseline_{key}"]),
                color="C3",
                ls="--",
                label=f"baseline ({cfg.baseline_spec})",
            )
        ax.set_xlabel("environment steps")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.grid(alpha=0.3)
        ax.legend()
    axes[1].set_ylim(bottom=0)
    fig.suptitle(f"{cfg.env_id}: evaluation on {cfg.eval_episodes} fixed seeds every {cfg.eval_freq} steps")
    fig.tight_layout()
    return _save(fig, out, dpi=110)


def comparison_chart(
    results: dict[str, dict[str, tuple[float, ...]]],
    metrics: Sequence[tuple[str, str, str]],
    path: str | Path,
    title: str = "",
) -> Path:
    """Bar chart, one panel per metric, one bar per policy, with its error bar.

    A bar is a mean with a symmetric std error bar, or an estimate with its interval (an
    asymmetric error bar from ``lower`` to ``upper``, hatched).

    Args:
        results: policy spec -> metric key -> (mean, std) or (estimate, lower, upper).
        metrics: the panels' (key, label, unit).
        path: the PNG.
        title: the figure's title.
    """
    names = list(results)
    fig = _figure(figsize=(4.2 * len(metrics), 3.6))
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    for ax, (key, label, unit) in zip(axes, metrics, strict=True):
        values = [results[n].get(key, (math.nan, math.nan)) for n in names]
        means = [v[0] for v in values]
        below = [v[0] - v[1] if len(v) == 3 else v[1] for v in values]
        above = [v[2] - v[0] if len(v) == 3 else v[1] for v in values]
        bars = ax.bar(
            range(len(names)),
            means,
            yerr=[below, above],
            capsize=4,
            color=[f"C{i}" for i in range(len(names))],
        )
        for bar, v in zip(bars, values, strict=True):
            if len(v) == 3:  # an interval, not a spread
                bar.set_hatch("//")
        ax.set_xticks(range(len(names)), names, rotation=20, ha="right")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.set_title(label)
        ax.grid(axis="y", alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if any(len(v) == 3 for r in results.values() for v in r.values()):
        fig.subplots_adjust(bottom=0.3)
        fig.text(0.01, 0.01, "hatched: IQM over seeds, 95 % bootstrap CI; plain: mean ± std", fontsize=8)
    return _save(fig, path, dpi=110)


def benchmark_chart(res: dict[str, Any], path: str | Path) -> Path:
    """Throughput bars (log scale) and cost per robot step against N, as a PNG.

    From :func:`soft_snake_gym.benchmark.run_benchmark`'s result.
    """
    fig = _figure(figsize=(12, 4.8))
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.6, 1]})
    rows = res["throughput"] + [
        {"case": f"PPO learn, {r['kind']} (n_envs={r['n_envs']})", "steps_per_s": r["steps_per_s"]}
        for r in res["ppo"]
    ]
    names = [r["case"] for r in rows]
    vals = [r["steps_per_s"] for r in rows]
    colors = ["#1f77b4" if "SoftEel" in n else "#ff7f0e" if "Swimmer" in n else "#2ca02c" for n in names]
    y = np.arange(len(rows))
    ax1.barh(y, vals, color=colors)
    ax1.set_yticks(y, names, fontsize=7)
    ax1.invert_yaxis()
    ax1.set_xscale("log")
    ax1.set_xlabel("robot-steps per second (median round)")
    swimmer = next((r["steps_per_s"] for r in res["throughput"] if r["case"] == "Swimmer-v5 gym.make"), None)
    if swimmer:
        ax1.axvline(swimmer, color="#ff7f0e", ls="--", lw=1)
        ax1.axvline(10 * swimmer, color="#ff7f0e", ls=":", lw=1)
        ax1.text(10 * swimmer, len(rows) - 0.5, " 10x Swimmer-v5", fontsize=7, color="#ff7f0e")
    ax1.set_title("Throughput, one run, one machine", fontsize=10)
    if res["nodes"]:
        N = np.array([r["N"] for r in res["nodes"]], dtype=float)
        us = np.array([r["us_per_robot_step"] for r in res["nodes"]])
        ax2.loglog(N, us, "o-", label="batched SoftEel, 1 thread")
        ax2.loglog(N, us[0] * N / N[0], "k--", lw=1, label="linear in N")
        ax2.set_xlabel("nodes N")
        ax2.set_ylabel("microseconds per robot step")
        ax2.set_title(f"Cost per step against N ({res['nodes'][0]['robots']} robots)", fontsize=10)
        ax2.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path, dpi=120)


def robustness_chart(
    settings: Sequence[str],
    series: dict[str, dict[str, list[float]]],
    metrics: Sequence[tuple[str, str, str]],
    xlabel: str,
    path: str | Path,
    title: str = "",
) -> Path:
    """One panel per metric: its value at each setting, one line (with markers) per controller.

    Args:
        settings: the x tick labels, in order.
        series: controller -> metric key -> values, one per setting (NaN: not run there).
        metrics: the panels' (key, label, unit).
        xlabel: the x axis's label.
        path: the PNG.
        title: the figure's title.
    """
    fig = _figure(figsize=(5.2 * len(metrics), 3.8))
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    x = np.arange(len(settings))
    for ax, (key, label, unit) in zip(axes, metrics, strict=True):
        for i, (name, values) in enumerate(series.items()):
            ax.plot(x, values[key], marker="o", color=f"C{i}", label=name)
        ax.set_xticks(x, list(settings), rotation=30 if len(settings) > 6 else 0)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"{label} [{unit}]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path, dpi=110)
