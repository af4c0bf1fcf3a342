"""Several policies (trained agents and baselines) on the same seeds, with the same metrics.

As one table and one bar chart (the library of ``soft-snake compare``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from soft_snake_gym import plots
from soft_snake_gym.agents import make_policy
from soft_snake_gym.evaluation import evaluate, make_eval_env, metric_columns, summarize

__all__ = ["DEFAULT_POLICIES", "check_figure_path", "compare", "format_comparison", "plot_comparison"]

#: (metric key, label, unit) of the table and the chart, from the registry.
METRICS = metric_columns(("average_speed", "distance", "cost_of_transport", "energy_actuator", "return"))
CHART = ("average_speed", "cost_of_transport", "return")
#: What ``soft-snake compare ENV`` compares when no --policies are given.
DEFAULT_POLICIES = {
    "SoftEel-v0": ["zoo:ppo", "pid", "open-loop"],
    "SoftWorm-v0": ["zoo:ppo", "inching-pid", "inching"],
    "SoftEelSegments-v0": ["zoo:ppo", "decentralized", "decentralized:closure=pacemaker", "pid"],
}


def compare(
    env_id: str, specs: list[str], episodes: int = 10, seed: int = 0, env_kwargs: dict[str, Any] | None = None
) -> dict[str, dict[str, tuple[float, float]]]:
    """Evaluate each policy spec; returns spec -> metric -> (mean, std).

    Specs as in :func:`soft_snake_gym.agents.make_policy`, for ``episodes`` episodes on seeds
    ``seed, seed + 1, ...``.
    """
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
            cells.append(
                f"  {'n/a':>24}" if not math.isfinite(mean) else f"  {f'{mean:.4g} ± {std:.2g}':>24}"
            )
        lines.append(f"{spec:<{width}}" + "".join(cells))
    return "\n".join(lines)


def plot_comparison(
    results: dict[str, dict[str, tuple[float, float]]], path: str | Path, title: str = ""
) -> Path:
    """Bar chart (mean with std error bars) of speed, cost of transport and return."""
    labels = {k: (label, unit) for k, label, unit in METRICS}
    return plots.comparison_chart(results, [(k, *labels[k]) for k in CHART], path, title)


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
