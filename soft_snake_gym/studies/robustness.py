"""Robustness of learned and classical control of the eel (the library of ``soft-snake robustness``).

Three experiments, each a table (CSV, written row by row, so an interrupted study keeps what it
finished) and a figure:

- ``failure``: one actuator failed (its action forced to 0 on every step) at each interior node
  in turn, and none;
- ``message``: one node's messages lost (its curvature and rate read as 0) on a random fraction
  of the steps, the fraction swept;
- ``length``: the body length N (the shared local policy trained at N = 10 run at other N).

Compared (:data:`CONTROLLERS`): the shared local policy (``--policy``, default the shipped
``zoo:ppo`` of ``SoftEelSegments-v0``) and ``DecentralizedPhasePID`` on the segment team
(``SoftEelSegments-v0``, where a lost message reaches only the neighbours that receive it), the
centralized PPO eel (``zoo:ppo`` of ``SoftEel-v0``, only where its input size allows: N = 10)
and the centralized PID on ``SoftEel-v0`` (a lost message is a node's measurement lost on the
way to the central computer). Every controller runs on the same seeds, so at the same setting
its robot is bitwise the same robot.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from soft_snake_gym import plots
from soft_snake_gym.agents import make_policy
from soft_snake_gym.evaluation import evaluate, make_eval_env, summarize
from soft_snake_gym.multiagent.segments import SegmentsEnv, node_index
from soft_snake_gym.params import check_int, check_number
from soft_snake_gym.policies import PolicyEnvMismatch
from soft_snake_gym.tables import appending, read_rows

__all__ = [
    "CONTROLLERS",
    "CONTROLLER_KEYS",
    "EXPERIMENTS",
    "Controller",
    "Perturbation",
    "Perturbed",
    "format_table",
    "run_experiment",
]

#: The experiments, in order.
EXPERIMENTS = ("failure", "message", "length")
#: The metrics of each table cell, (key, label, unit).
METRICS = (("average_speed", "average speed", "m/s"), ("cost_of_transport", "cost of transport", "-"))


@dataclass(frozen=True)
class Controller:
    """One compared controller: a label, the env id it runs on and its policy spec."""

    label: str
    env_id: str
    spec: str


#: Short names of the compared controllers (``--controllers``).
CONTROLLER_KEYS = ("shared", "central-ppo", "decentralized", "pid")


def default_controllers(
    shared: str = "zoo:ppo", keys: tuple[str, ...] = CONTROLLER_KEYS
) -> tuple[Controller, ...]:
    """The compared controllers named in ``keys`` (:data:`CONTROLLER_KEYS`), the shared local policy ``shared``."""
    unknown = [k for k in keys if k not in CONTROLLER_KEYS]
    if unknown:
        raise ValueError(f"controller {unknown[0]!r} is unknown; choose from {', '.join(CONTROLLER_KEYS)}")
    every = {
        "shared": Controller("shared local PPO", "SoftEelSegments-v0", shared),
        "central-ppo": Controller("centralized PPO", "SoftEel-v0", "zoo:ppo"),
        "decentralized": Controller("decentralized PID", "SoftEelSegments-v0", "decentralized"),
        "pid": Controller("centralized PID", "SoftEel-v0", "pid"),
    }
    return tuple(every[k] for k in CONTROLLER_KEYS if k in keys)


CONTROLLERS = default_controllers()


@dataclass(frozen=True)
class Perturbation:
    """What goes wrong in an episode.

    Attributes:
        failed_node: the interior node (1 … N-2) whose action is forced to 0, or None.
        lost_node: the interior node whose messages are lost, or None.
        loss_fraction: the fraction of steps on which they are lost, in [0, 1].
    """

    failed_node: int | None = None
    lost_node: int | None = None
    loss_fraction: float = 0.0


class Perturbed(gym.Wrapper):
    """An eel env (``SoftEel-v0`` or ``SoftEelSegments-v0``) with a :class:`Perturbation`.

    The failed node's action is set to 0 before every step. A lost message, drawn on each step
    with probability ``loss_fraction`` from a generator seeded by ``reset(seed=...)``: on the
    segment team the node's curvature and rate read as 0 in its neighbours' observations (its own
    are intact); on ``SoftEel-v0`` they read as 0 in the central observation.
    """

    def __init__(self, env: gym.Env, perturbation: Perturbation) -> None:
        """Wrap ``env`` (arguments in the class docstring)."""
        super().__init__(env)
        inner = env.unwrapped
        n = inner.N - 2
        p = perturbation
        for name in ("failed_node", "lost_node"):
            node = getattr(p, name)
            if node is not None:
                node_index(f"node_{node}", inner.N)  # raises for a node that does not exist
        check_number("loss_fraction", p.loss_fraction, 0.0, 1.0)
        self.perturbation = p
        self._team = inner if isinstance(inner, SegmentsEnv) else None
        self._rng = np.random.default_rng()
        self._n = n

    def _lose(self, obs: np.ndarray) -> np.ndarray:
        p = self.perturbation
        if p.lost_node is None:
            return obs
        lost = bool(self._rng.random() < p.loss_fraction)
        j = p.lost_node - 1
        if self._team is not None:
            mask = np.zeros(self._n, dtype=np.bool_)
            mask[j] = lost
            self._team.lost_messages = mask
            return self._team.observe()
        if lost:
            obs = obs.copy()
            obs[j] = obs[self._n + j] = 0.0  # kappa_j, kappa_dot_j of SoftEel-v0's observation
        return obs

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env; a ``seed`` also seeds the message losses."""
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        return self._lose(obs), info

    def step(self, action):
        """Step with the failed node's action forced to 0; lose the message for this observation."""
        if self.perturbation.failed_node is not None:
            action = np.array(action, dtype=np.float32, copy=True)
            action[self.perturbation.failed_node - 1] = 0.0
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._lose(obs), reward, terminated, truncated, info


def settings(experiment: str, n_nodes: int, fractions: list[float], lengths: list[int], lost_node: int):
    """The rows of an experiment: (row label, perturbation, N)."""
    if experiment == "failure":
        rows = [("none", Perturbation(), n_nodes)]
        rows += [(f"node_{j}", Perturbation(failed_node=j), n_nodes) for j in range(1, n_nodes - 1)]
        return rows
    if experiment == "message":
        return [(f"{f:g}", Perturbation(lost_node=lost_node, loss_fraction=f), n_nodes) for f in fractions]
    if experiment == "length":
        return [(f"N={n}", Perturbation(), n) for n in lengths]
    raise ValueError(f"experiment {experiment!r} is unknown; use one of {', '.join(EXPERIMENTS)}")


def run_experiment(
    experiment: str,
    out_dir: str | Path,
    controllers: tuple[Controller, ...] = CONTROLLERS,
    episodes: int = 3,
    seed: int = 0,
    n_nodes: int = 10,
    fractions: tuple[float, ...] = (0.0, 0.1, 0.25, 0.5, 1.0),
    lengths: tuple[int, ...] = (8, 10, 14, 20),
    lost_node: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Run one experiment; returns its rows and writes ``<experiment>.csv`` and ``<experiment>.png``.

    Cells (setting, controller) already in ``<experiment>.csv`` are read, not run again: an
    interrupted study resumes, and controllers can be added to a finished one (delete the CSV
    to start over, e.g. after changing the episodes or the policy).

    Args:
        experiment: one of :data:`EXPERIMENTS`.
        out_dir: folder of the CSV and the figure.
        controllers: the compared controllers.
        episodes: episodes per cell, on seeds ``seed, seed + 1, ...``.
        seed: the first seed.
        n_nodes: N of the failure and message experiments.
        fractions: loss fractions of the message experiment, each in [0, 1].
        lengths: body lengths of the length experiment (each >= 5).
        lost_node: the node whose messages are lost (default: the middle one, N // 2 - 1).
        env_kwargs: further keywords of both envs (physics, ``integrator.substeps``...).
        progress: called with a line per finished cell.

    Returns:
        The CSV's rows (strings, as read back), one per (setting, controller), this run's and any
        earlier run's: ``setting``, ``controller``, ``N`` and each metric's mean and std (NaN where
        the controller cannot run, with the reason in ``note``).

    Raises:
        ValueError: an unknown experiment, a bad number, a node that does not exist.
    """
    check_int("episodes", episodes, 1)
    check_int("n_nodes", n_nodes, 5, hint="the body length of the failure and message experiments")
    for f in fractions:
        check_number("loss fraction", f, 0.0, 1.0)
    for n in lengths:
        check_int("body length", n, 5, hint="nodes of the body (agents: N - 2)")
    lost = n_nodes // 2 - 1 if lost_node is None else lost_node
    node_index(f"node_{lost}", n_nodes)
    rows_spec = settings(experiment, n_nodes, list(fractions), list(lengths), lost)
    kwargs = dict(env_kwargs or {})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{experiment}.csv"
    fields = (
        ["setting", "controller", "N"]
        + [f"{k}_{s}" for k, _, _ in METRICS for s in ("mean", "std")]
        + ["note"]
    )
    done = {(r["setting"], r["controller"]) for r in read_rows(path)}  # an earlier run's cells
    with appending(path, fields) as write:
        for label, perturbation, n in rows_spec:
            for c in controllers:
                if (label, c.label) in done:
                    continue
                row: dict[str, Any] = {"setting": label, "controller": c.label, "N": n, "note": ""}
                kw = {**kwargs, "rod": {**kwargs.get("rod", {}), "N": n}}
                env = make_eval_env(
                    c.env_id, seed=seed, env_kwargs=kw, wrapper=lambda e, p=perturbation: Perturbed(e, p)
                )
                try:
                    policy = make_policy(c.spec, env)
                except PolicyEnvMismatch as err:  # e.g. the centralized PPO's input size at N != 10
                    policy, row["note"] = None, str(err).split(";")[0]
                if policy is not None:
                    summary = summarize(evaluate(policy, env, episodes=episodes))
                else:
                    summary = {}
                env.close()
                for key, _, _ in METRICS:
                    row[f"{key}_mean"], row[f"{key}_std"] = summary.get(key, (math.nan, math.nan))
                write(row)
                if progress is not None:
                    progress(f"{experiment} {label:>8} {c.label:<20} {row['average_speed_mean']:.4f} m/s")
    results = read_rows(path)  # every controller's cells, those of earlier runs too
    plot_experiment(experiment, results, out / f"{experiment}.png")
    return results


XLABELS = {
    "failure": "failed actuator (action forced to 0)",
    "message": "fraction of steps with the middle node's messages lost",
    "length": "body length (nodes)",
}


def plot_experiment(experiment: str, rows: list[dict[str, Any]], path: str | Path) -> Path:
    """The experiment's figure: each metric against the setting, one line per controller."""
    settings_ = list(dict.fromkeys(r["setting"] for r in rows))
    series: dict[str, dict[str, list[float]]] = {}
    for r in rows:
        s = series.setdefault(r["controller"], {k: [] for k, _, _ in METRICS})
        for key, _, _ in METRICS:
            s[key].append(float(r[f"{key}_mean"]))
    return plots.robustness_chart(
        settings_, series, list(METRICS), XLABELS[experiment], path, f"robustness: {experiment}"
    )


def format_table(experiment: str, rows: list[dict[str, Any]], key: str = "average_speed") -> str:
    """A Markdown table: one row per setting, one column per controller, ``key``'s mean ± std."""
    controllers = list(dict.fromkeys(r["controller"] for r in rows))
    label, unit = next((lab, u) for k, lab, u in METRICS if k == key)
    lines = [
        f"| {experiment} | " + " | ".join(f"{c} {label} [{unit}]" for c in controllers) + " |",
        "|---" * (len(controllers) + 1) + "|",
    ]
    for setting in dict.fromkeys(r["setting"] for r in rows):
        cells = []
        for c in controllers:
            r = next(x for x in rows if x["setting"] == setting and x["controller"] == c)
            mean, std = float(r[f"{key}_mean"]), float(r[f"{key}_std"])
            cells.append("n/a" if not math.isfinite(mean) else f"{mean:.4g} ± {std:.2g}")
        lines.append(f"| {setting} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
