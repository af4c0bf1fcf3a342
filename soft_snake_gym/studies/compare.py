"""Several policies (trained agents and baselines) on the same seeds, with the same metrics.

As one table and one bar chart (the library of ``soft-snake compare``). A policy is one spec
(mean ± std over the episodes), or a *seed set*: the run folders of one configuration trained
with several seeds (``soft-snake train --seeds``), given as their parent folder or a glob. A
seed set is scored per run (the mean over the same episodes), and across runs by the
interquartile mean with a 95 % stratified-bootstrap confidence interval (``rliable``, Agarwal
et al. 2021): the statistic that stays honest with a handful of seeds.
"""

from __future__ import annotations

import glob
import math
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from soft_snake_gym import plots
from soft_snake_gym.agents import make_policy
from soft_snake_gym.config import ConfigError
from soft_snake_gym.distributed import RAY_INSTALL, RayNotInstalled
from soft_snake_gym.evaluation import NAV_METRICS, evaluate, make_eval_env, metric_columns, summarize

__all__ = [
    "BOOTSTRAP_REPS",
    "DEFAULT_POLICIES",
    "check_figure_path",
    "compare",
    "format_comparison",
    "iqm_intervals",
    "plot_comparison",
    "seed_runs",
]

#: Bootstrap resamples of the IQM's confidence interval (rliable's default, 50,000, takes a
#: minute per metric here; 2,000 move the interval's ends by well under its width).
BOOTSTRAP_REPS = 2000
#: Seed of the bootstrap, so that the same scores give the same interval.
BOOTSTRAP_SEED = 0

#: (metric key, label, unit) of the table and the chart, from the registry.
METRICS = metric_columns(("average_speed", "distance", "cost_of_transport", "energy_actuator", "return"))
CHART = ("average_speed", "cost_of_transport", "return")
#: What ``soft-snake compare ENV`` compares when no --policies are given.
DEFAULT_POLICIES = {
    "SoftEel-v0": ["zoo:ppo", "pid", "open-loop"],
    "SoftWorm-v0": ["zoo:ppo", "inching-pid", "inching"],
    "SoftEelGoal-v0": ["zoo:ppo", "los"],
    "SoftEelPath-v0": ["los", "pid"],  # no path-following agent is shipped yet (docs/navigation.md)
    # the shipped shared policy, the chain it imitated (no start-up), both closures, the clock
    "SoftEelSegments-v0": [
        "zoo:ppo",
        "decentralized:startup=0",
        "decentralized",
        "decentralized:closure=pacemaker",
        "pid",
    ],
}


def seed_runs(spec: str) -> list[Path] | None:
    """The run folders of a seed set, or None if ``spec`` is not one.

    A seed set is a glob (``"runs/eel_s*"``) or a folder that is not itself a run folder but
    holds run folders (``soft-snake train --seeds`` writes ``<parent>/s<seed>``); a run folder
    has a ``config.yaml``.

    Raises:
        ConfigError: a glob or folder without any run folder in it.
    """
    if any(c in spec for c in "*?["):
        runs = [Path(p) for p in sorted(glob.glob(spec)) if (Path(p) / "config.yaml").is_file()]
        if not runs:
            raise ConfigError(f"the seed set {spec!r} matches no run folder (a folder with a config.yaml)")
        return runs
    path = Path(spec)
    if not path.is_dir() or (path / "config.yaml").is_file() or any(path.glob("*.zip")):
        return None
    runs = sorted((p for p in path.iterdir() if (p / "config.yaml").is_file()), key=_natural)
    if not runs:
        raise ConfigError(
            f"{spec!r} is a folder with no run folder in it; give a run folder, or the parent of the "
            "run folders of `soft-snake train --seeds`"
        )
    return runs


def _natural(path: Path) -> tuple:
    """Sort key: s2 before s10."""
    digits = "".join(c for c in path.name if c.isdigit())
    return (path.name.rstrip("0123456789"), int(digits) if digits else -1, path.name)


def _rliable() -> tuple[ModuleType, ModuleType]:
    """``rliable.library`` and ``rliable.metrics``, or :class:`RayNotInstalled` naming the install line."""
    try:  # here, not above: optional, and rliable imports pandas, arch and seaborn (seconds)
        from rliable import library, metrics
    except ImportError:
        raise RayNotInstalled(
            f"the interquartile mean over seeds needs rliable, which is not installed; install it with: "
            f"{RAY_INSTALL}"
        ) from None
    except Exception as err:  # noqa: BLE001 - rliable 1.2 breaks at import with arch 7 on pandas 3
        raise RayNotInstalled(
            f"rliable fails to import ({type(err).__name__}: {err}); it needs arch < 8 and pandas < 3, "
            f"which {RAY_INSTALL} installs"
        ) from None
    return library, metrics


def iqm_intervals(
    scores: dict[str, np.ndarray], reps: int = BOOTSTRAP_REPS, seed: int = BOOTSTRAP_SEED
) -> dict[str, tuple[float, float, float]]:
    """Interquartile mean and its 95 % stratified-bootstrap interval of each metric's scores.

    ``rliable.library.get_interval_estimates`` with ``rliable.metrics.aggregate_iqm``, one task
    (so the bootstrap resamples runs), ``reps`` resamples drawn from ``RandomState(seed)``.

    Args:
        scores: metric -> one score per run, shape (n_runs,).
        reps: bootstrap resamples.
        seed: the bootstrap's random seed.

    Returns:
        metric -> (IQM, lower, upper); NaN for a metric with a non-finite score.

    Raises:
        RayNotInstalled: rliable (part of the ``ray`` extra) is missing.
    """
    library, metrics = _rliable()
    out = {}
    for key, values in scores.items():
        runs = np.asarray(values, float).reshape(-1, 1)  # (n_runs, 1 task)
        if not np.isfinite(runs).all():
            out[key] = (math.nan, math.nan, math.nan)
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # arch: random_state is being renamed
            point, interval = library.get_interval_estimates(
                {key: runs},
                lambda x: np.array([metrics.aggregate_iqm(x)]),
                reps=reps,
                random_state=np.random.RandomState(seed),  # each metric's own draws
            )
        out[key] = (float(point[key][0]), float(interval[key][0, 0]), float(interval[key][1, 0]))
    return out


def _columns(results: dict[str, dict[str, tuple[float, float]]]) -> list[tuple[str, str, str]]:
    """:data:`METRICS`, then the navigation metrics that some policy's results have."""
    nav = [n for n in NAV_METRICS if any(n in summary for summary in results.values())]
    return METRICS + metric_columns(nav)


def compare(
    env_id: str,
    specs: list[str],
    episodes: int = 10,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
    scores: dict[str, dict[str, dict[str, float]]] | None = None,
) -> dict[str, dict[str, tuple[float, ...]]]:
    """Evaluate each policy spec; returns spec -> metric -> (mean, std), or (IQM, lower, upper).

    Specs as in :func:`soft_snake_gym.agents.make_policy`, for ``episodes`` episodes on seeds
    ``seed, seed + 1, ...``; a seed set (:func:`seed_runs`) is each of its runs on those
    episodes, summarized across runs by :func:`iqm_intervals` of the runs' means.

    Args:
        env_id: the env.
        specs: the policies.
        episodes: episodes per policy (per run of a seed set).
        seed: the first episode seed.
        env_kwargs: the env's keywords.
        scores: if given, filled with seed set -> run folder -> metric -> the run's mean.
    """
    env = make_eval_env(env_id, n_envs=1, seed=seed, env_kwargs=env_kwargs)
    sets = {spec: seed_runs(spec) for spec in specs}  # all errors before any work
    if any(sets.values()):
        _rliable()  # missing: say so before loading anything
    policies: dict[str, Any] = {}
    for spec, runs in sets.items():
        policies[spec] = {str(r): make_policy(str(r), env) for r in runs} if runs else make_policy(spec, env)
    results: dict[str, dict[str, tuple[float, ...]]] = {}
    for spec, policy in policies.items():
        if not isinstance(policy, dict):
            env.seed(seed)
            results[spec] = summarize(evaluate(policy, env, episodes=episodes))
            continue
        per_run = {}
        for run, p in policy.items():
            env.seed(seed)
            per_run[run] = {k: m for k, (m, _) in summarize(evaluate(p, env, episodes=episodes)).items()}
        keys = [k for k, _, _ in METRICS]
        results[spec] = iqm_intervals(
            {k: np.array([r.get(k, math.nan) for r in per_run.values()]) for k in keys}
        )
        if scores is not None:
            scores[spec] = per_run
    env.close()
    return results


def format_comparison(results: dict[str, dict[str, tuple[float, ...]]], title: str = "") -> str:
    """A plain-text table, one row per policy: mean ± std, or a seed set's IQM [95 % CI]."""
    width = max(12, *(len(s) for s in results))
    columns = _columns(results)
    cell = 30 if any(len(v) == 3 for r in results.values() for v in r.values()) else 24
    head = f"{'policy':<{width}}" + "".join(f"  {f'{label} [{unit}]':>{cell}}" for _, label, unit in columns)
    lines = ([title] if title else []) + [head, "-" * len(head)]
    for spec, summary in results.items():
        cells = []
        for key, _, _ in columns:
            value = summary.get(key, (math.nan, math.nan))
            if not math.isfinite(value[0]):
                text = "n/a"
            elif len(value) == 3:
                text = f"{value[0]:.4g} [{value[1]:.4g}, {value[2]:.4g}]"
            else:
                text = f"{value[0]:.4g} ± {value[1]:.2g}"
            cells.append(f"  {text:>{cell}}")
        lines.append(f"{spec:<{width}}" + "".join(cells))
    if cell == 30:
        lines.append(
            "seed sets: interquartile mean over runs [95 % stratified-bootstrap CI] of each run's mean "
            "(rliable); other policies: mean ± std over episodes"
        )
    return "\n".join(lines)


def plot_comparison(
    results: dict[str, dict[str, tuple[float, ...]]], path: str | Path, title: str = ""
) -> Path:
    """Bar chart of speed, cost of transport and return: mean ± std, or a seed set's IQM and CI.

    And of the success rate or the cross-track error in a navigation task.
    """
    labels = {k: (label, unit) for k, label, unit in _columns(results)}
    chart = list(CHART) + [k for k in ("success", "cross_track_error") if k in labels]
    return plots.comparison_chart(results, [(k, *labels[k]) for k in chart], path, title)


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
