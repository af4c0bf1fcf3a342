"""``soft-snake compare``: several policies (trained agents and baselines) on the same seeds,
with the same metrics, as one table and one bar chart."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

__all__ = ["compare", "plot_comparison", "format_comparison"]

#: (metric key, label, unit) of the table and the chart.
METRICS = [
    ("average_speed", "average speed", "m/s"),
    ("distance", "distance", "m"),
    ("cost_of_transport", "cost of transport", "-"),
    ("energy_actuator", "actuator energy", "J"),
    ("return", "return", "-"),
]
CHART = ("average_speed", "cost_of_transport", "return")
#: What ``soft-snake compare ENV`` compares when no --policies are given.
DEFAULT_POLICIES = {
    "SoftEel-v0": ["zoo:ppo", "pid", "open-loop"],
    "SoftWorm-v0": ["zoo:ppo", "inching-pid", "inching"],
}


def compare(env_id: str, specs: list[str], episodes: int = 10, seed: int = 0,
            env_kwargs: dict[str, Any] | None = None) -> dict[str, dict[str, tuple[float, float]]]:
    """Evaluate each policy spec (see :func:`soft_snake_gym.policies.make_policy`) for
    ``episodes`` episodes on seeds ``seed, seed + 1, ...``; returns spec -> metric -> (mean, std)."""
    from soft_snake_gym.evaluation import evaluate, make_eval_env, summarize
    from soft_snake_gym.policies import make_policy

    env = make_eval_env(env_id, n_envs=1, seed=seed, env_kwargs=env_kwargs)
    policies = {spec: make_policy(spec, env) for spec in specs}  # all errors before any work
    results = {}
    for spec, policy in policies.items():
        env.seed(seed)
        results[spec] = summarize(evaluate(policy, env, episodes=episodes))
    env.close()
    return results


def format_comparison(results: dict[str, dict[str, tuple[float, float]]], title: str = "") -> str:
    """A plain-text table, one row per policy, mean ± std per metric."""
    width = max(12, *(len(s) for s in results))
    head = f"{'policy':<{width}}" + "".join(f"  {f'{label} [{unit}]':>24}" for _, label, unit in METRICS)
    lines = ([title] if title else []) + [head, "-" * len(head)]
    for spec, summary in results.items():
        cells = []
        for key, _, _ in METRICS:
            mean, std = summary.get(key, (math.nan, math.nan))
            cells.append(f"  {'n/a':>24}" if not math.isfinite(mean) else f"  {f'{mean:.4g} ± {std:.2g}':>24}")
        lines.append(f"{spec:<{width}}" + "".join(cells))
    return "\n".join(lines)


def plot_comparison(results: dict[str, dict[str, tuple[float, float]]], path: str | Path, title: str = "") -> Path:
    """Bar chart (mean with std error bars) of speed, cost of transport and return."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(results)
    fig, axes = plt.subplots(1, len(CHART), figsize=(4.2 * len(CHART), 3.6))
    labels = {k: (label, unit) for k, label, unit in METRICS}
    for ax, key in zip(axes, CHART, strict=True):
        means = [results[n].get(key, (math.nan, 0))[0] for n in names]
        stds = [results[n].get(key, (0, math.nan))[1] for n in names]
        ax.bar(range(len(names)), means, yerr=stds, capsize=4, color=[f"C{i}" for i in range(len(names))])
        ax.set_xticks(range(len(names)), names, rotation=20, ha="right")
        label, unit = labels[key]
        ax.set_ylabel(f"{label} [{unit}]")
        ax.set_title(label)
        ax.grid(axis="y", alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _episodes_on_seeds(episodes: int, seed: int) -> str:
    """``1 episode per policy, seed 0`` or ``10 episodes per policy, seeds 0..9``."""
    if episodes == 1:
        return f"1 episode per policy, seed {seed}"
    return f"{episodes} episodes per policy, seeds {seed}..{seed + episodes - 1}"


def _arguments(p) -> None:
    p.add_argument("env_id", nargs="?", default="SoftEel-v0", help="environment id (default SoftEel-v0)")
    p.add_argument("--policies", nargs="+", metavar="SPEC",
                   help="baselines (pid, open-loop, 'pid:alpha=0.6', inching-pid...), run folders, "
                        "model zips or zoo:ppo (default: the env's baselines and its shipped PPO agent)")
    p.add_argument("--episodes", type=int, default=10, help="episodes per policy (default 10)")
    p.add_argument("--seed", type=int, default=0, help="first seed; every policy gets the same (default 0)")
    p.add_argument("--out", metavar="PNG", help="bar chart path (default compare_<env_id>.png)")
    p.add_argument("--json", metavar="PATH", help="also write the figures as JSON")


def check_figure_path(path: str | Path) -> None:
    """Raise ``ValueError`` unless matplotlib can write a figure at ``path`` (by its suffix)."""
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in formats:
        raise ValueError(
            f"cannot draw a chart into {str(path)!r}: give a name ending in one of "
            f"{', '.join('.' + f for f in sorted(formats))} (the table is printed on stdout)"
        )
    if Path(path).is_dir():
        raise ValueError(f"{str(path)!r} is a folder; give the chart's file name")


def _run(args) -> int:
    from soft_snake_gym.cli import CLIError

    if args.episodes < 1:
        raise CLIError(f"--episodes {args.episodes} must be at least 1")
    try:
        check_figure_path(args.out or f"compare_{args.env_id}.png")
    except ValueError as err:
        raise CLIError(f"--out: {err}") from None
    if args.json and Path(args.json).is_dir():
        raise CLIError(f"--json {args.json!r} is a folder; give a file name")
    specs = args.policies or DEFAULT_POLICIES.get(args.env_id)
    if not specs:
        raise CLIError(f"give --policies for {args.env_id} (defaults exist for {', '.join(DEFAULT_POLICIES)})")
    results = compare(args.env_id, specs, args.episodes, args.seed)
    title = f"{args.env_id}: {_episodes_on_seeds(args.episodes, args.seed)}"
    print(format_comparison(results, title))
    out = plot_comparison(results, args.out or f"compare_{args.env_id}.png", title)
    print(f"wrote {out}")
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        clean = {s: {k: [m if math.isfinite(m) else None, d if math.isfinite(d) else None]
                     for k, (m, d) in r.items()} for s, r in results.items()}
        path.write_text(json.dumps({"env_id": args.env_id, "episodes": args.episodes, "seed": args.seed,
                                    "results": clean}, indent=2))
        print(f"wrote {path}")
    return 0


def _register() -> None:
    from soft_snake_gym.cli import subcommand

    subcommand("compare", "evaluate several policies on the same seeds: one table, one bar chart",
               _arguments)(_run)


_register()
