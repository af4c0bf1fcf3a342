"""Convergence in the time step (docs/model.md §5a, §10): is a result made by the model or by the integrator?

:func:`convergence` runs ONE seeded episode of a policy at the env's integration step and with
that step divided by each refinement factor, through the env's own keyword
``integrator.substeps`` (the control step stays ``dt``; a config that already takes ``k``
internal steps runs ``k * factor``). Every run starts from the same initial state (the env's
reset, noise included, drawn from ``seed``) and, for a policy with a seed, gets the same
actions from it, so only the integration step differs. The episode metrics of
:mod:`soft_snake_gym.evaluation` are then compared with the finest run:

- water (``SoftEel-v0``): ``average_speed``, ``mean_fluid_power``, ``energy_actuator``,
  ``curvature_error``, within :data:`RELATIVE_TOLERANCE` = 5 %;
- ground (``SoftWorm-v0``): ``distance``, ``energy_friction``, ``energy_actuator``,
  ``length_error``, within 10 %.

A metric passes if ``|value - finest| <= max(rtol |finest|, atol)`` at every factor. The
absolute tolerances :data:`ABSOLUTE_TOLERANCE` only matter where a metric is near zero (a
policy that does not move, a controller that tracks almost perfectly), where a relative
difference measures nothing physical. Each is about 1 % of the value the metric takes under
the thesis's gaits (tracking errors: 0.2 % of the gait's amplitude):

- ``average_speed`` 1e-3 m/s: 1 % of the eel's 0.13 m/s serpenoid speed, 0.5 % of a body
  length (1.62 m) per 10 s;
- ``distance`` 1e-2 m: 0.6 % of the body length (1.62 m) and under 1 % of the 1.27 m the
  default inching pulse moves the worm in 10 s. A gait that anchors nothing (the sinusoidal
  wave, random actions) moves the worm only by stick-slip chatter, a few millimetres either
  way, whose value carries no physics; this bound says such a result is zero at every step;
- ``mean_fluid_power`` 0.05 W: 1 % of the 5.7 W of the PID eel;
- ``energy_friction`` and ``energy_actuator`` 0.5 J: 1 % of the eel's 61 J and the worm's
  90 J per 10 s episode;
- ``curvature_error`` 1e-3: 0.2 % of the serpenoid's curvature amplitude
  ``2 tan(alpha/2) = 0.54`` at alpha = pi/6, a seventh of the PID's 0.007 (tracking errors
  are smaller than the other metrics relative to their scale, so this one is stricter);
- ``length_error`` 1e-4 m: 0.2 % of the wave's compression ``eps l0 = 0.054 m``, a third of
  the inching PID's 3.3e-4 m.

A metric that is NaN at every factor (no tracking error for a trained agent or random actions)
is reported as ``n/a`` and not checked; an episode that fails (``info["failure"]``) at any
factor fails the check.

The fixed random-action sequence is the policy ``"random"`` (:class:`RandomActions`):
uniform actions in ``[-scale, scale]`` from a generator seeded with ``seed``, one draw per
control step, so every factor gets the same sequence.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from soft_snake_gym.agents import make_policy
from soft_snake_gym.config import ConfigError
from soft_snake_gym.evaluation import evaluate, make_eval_env, metric_columns
from soft_snake_gym.policies import parse_policy_spec

__all__ = [
    "ABSOLUTE_TOLERANCE",
    "METRICS",
    "RELATIVE_TOLERANCE",
    "ConvergenceResult",
    "DEFAULT_FACTORS",
    "RandomActions",
    "convergence",
    "format_convergence",
]

#: The metrics checked per medium (keys of :func:`soft_snake_gym.evaluation.evaluate`'s dicts).
METRICS: dict[str, tuple[str, ...]] = {
    "water": ("average_speed", "mean_fluid_power", "energy_actuator", "curvature_error"),
    "ground": ("distance", "energy_friction", "energy_actuator", "length_error"),
}

#: Relative tolerance per medium (docs/model.md §10).
RELATIVE_TOLERANCE: dict[str, float] = {"water": 0.05, "ground": 0.10}

#: Absolute tolerance per metric, for values near zero (justified in the module docstring).
ABSOLUTE_TOLERANCE: dict[str, float] = {
    "average_speed": 1e-3,
    "distance": 1e-2,
    "mean_fluid_power": 0.05,
    "energy_friction": 0.5,
    "energy_actuator": 0.5,
    "curvature_error": 1e-3,
    "length_error": 1e-4,
}

DEFAULT_FACTORS = (1, 4, 16)


class RandomActions:
    """A fixed seeded random-action sequence with SB3's ``predict``.

    Uniform in ``[-scale, scale]``, one draw of the generator per call (control step), restarted
    from ``seed`` at every episode start.

    Args:
        action_space: the env's Box action space (its shape is used).
        seed: seed of ``numpy.random.default_rng``.
        scale: half-width of the uniform distribution, in (0, 1] (actions are in [-1, 1]).
    """

    def __init__(self, action_space: Any, seed: int = 0, scale: float = 1.0) -> None:
        """Check ``scale`` and seed the generator (arguments in the class docstring)."""
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale <= 1:
            raise ValueError(f"random policy: scale = {scale!r} must be in (0, 1]")
        self.shape = tuple(action_space.shape)
        self.seed, self.scale = int(seed), float(scale)
        self.rng = np.random.default_rng(self.seed)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """Uniform random actions (one draw per call), restarting the generator at an episode start."""
        obs = np.asarray(observation)
        if episode_start is not None and bool(np.asarray(episode_start).reshape(-1)[0]):
            self.rng = np.random.default_rng(self.seed)
        n = obs.shape[0] if obs.ndim > 1 else None
        shape = self.shape if n is None else (n, *self.shape)
        action = self.scale * self.rng.uniform(-1.0, 1.0, size=shape)
        return action.astype(np.float32), state

    def __repr__(self) -> str:
        """``RandomActions(seed=..., scale=...)``."""
        return f"RandomActions(seed={self.seed}, scale={self.scale})"


def make_convergence_policy(spec: str, env: Any, seed: int) -> Any:
    """A policy for a convergence run from its spec.

    ``"random"`` or ``"random:scale=0.5"`` as :class:`RandomActions` seeded with ``seed``; anything
    else through :func:`soft_snake_gym.agents.make_policy`.
    """
    if spec.partition(":")[0].strip() != "random":
        return make_policy(spec, env)
    _, params = parse_policy_spec(spec)
    unknown = sorted(set(params) - {"scale"})
    if unknown:
        raise ConfigError(f"unknown key {unknown[0]!r} in random policy; valid keys: scale")
    try:
        return RandomActions(env.action_space, seed=seed, **params)
    except ValueError as err:
        raise ConfigError(str(err)) from None


@dataclass
class ConvergenceResult:
    """The refinement table of one policy on one env.

    Attributes:
        env_id, policy: what ran.
        medium: ``"water"`` or ``"ground"``.
        method: the integrator that ran (``"sdirk2"``, ``"bdf2"``, ``"backward_euler"``, ...).
        substeps: internal steps per integrator step of each run (k * factor), ascending.
        factors: the refinement factors, ascending (the last one is the reference).
        h: integration step of each run [s].
        values: metric -> value at each factor (NaN where not defined).
        failures: the episode's failure reason per factor ("" if none).
        rtol: relative tolerance; atol: metric -> absolute tolerance.
        seed: the episode's seed.
    """

    env_id: str
    policy: str
    medium: str
    method: str
    factors: list[int]
    substeps: list[int]
    h: list[float]
    values: dict[str, list[float]]
    failures: list[str]
    rtol: float
    atol: dict[str, float] = field(default_factory=dict)
    seed: int = 0

    def deviations(self, metric: str) -> list[float]:
        """``|value - finest|`` at each factor."""
        vals = self.values[metric]
        return [abs(v - vals[-1]) for v in vals]

    def tolerance(self, metric: str) -> float:
        """``max(rtol |finest|, atol)`` for ``metric``."""
        return max(self.rtol * abs(self.values[metric][-1]), self.atol[metric])

    def passed(self, metric: str) -> bool | None:
        """Whether ``metric`` agrees with the finest run at every factor (None: not defined)."""
        vals = self.values[metric]
        if all(math.isnan(v) for v in vals):
            return None
        if any(self.failures) or any(not math.isfinite(v) for v in vals):
            return False
        return max(self.deviations(metric)) <= self.tolerance(metric)

    @property
    def ok(self) -> bool:
        """True if no episode failed and every defined metric passed."""
        return not any(self.failures) and all(self.passed(m) is not False for m in self.values)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready mapping (NaN as None)."""

        def clean(v: float) -> float | None:
            return v if math.isfinite(v) else None

        return {
            "env_id": self.env_id,
            "policy": self.policy,
            "medium": self.medium,
            "method": self.method,
            "factors": self.factors,
            "substeps": self.substeps,
            "h": self.h,
            "failures": self.failures,
            "rtol": self.rtol,
            "seed": self.seed,
            "ok": self.ok,
            "metrics": {
                m: {
                    "values": [clean(v) for v in vals],
                    "atol": self.atol[m],
                    "tolerance": clean(self.tolerance(m)),
                    "passed": self.passed(m),
                }
                for m, vals in self.values.items()
            },
        }


def _check_factors(factors: Any) -> list[int]:
    out = list(factors)
    if len(out) < 2 or any(isinstance(f, bool) or not isinstance(f, int) or f < 1 for f in out):
        raise ConfigError(f"factors = {out!r} must be at least two integers >= 1, e.g. 1 4 16")
    if len(set(out)) != len(out):
        raise ConfigError(f"factors = {out!r} must not repeat a value")
    return sorted(out)


def convergence(
    env_id: str,
    policy: str,
    env_kwargs: dict[str, Any] | None = None,
    factors: Any = DEFAULT_FACTORS,
    seed: int = 0,
    transient: float = 2.0,
) -> ConvergenceResult:
    """Run one seeded episode of ``policy`` at each refinement factor of the integration step.

    Args:
        env_id: ``SoftEel-v0`` or ``SoftWorm-v0`` (or another registered soft_snake_gym id).
        policy: a policy spec as ``soft-snake evaluate --policy`` takes (baseline with options,
            ``zoo:ppo``, a run folder or model zip), or ``"random"`` / ``"random:scale=S"``.
        env_kwargs: env keywords (nested dicts for sections, as ``--env-kwarg`` builds them);
            ``integrator.substeps`` is set per run on top of them.
        factors: integers >= 1 dividing the integration step; the largest is the reference.
        seed: seed of the episode (reset noise, randomization) and of ``"random"``.
        transient: start-up time left out of speed and tracking error [s].

    Returns:
        the :class:`ConvergenceResult`.

    Raises:
        ConfigError: bad factors, policy spec or env keyword (before any episode runs).
    """
    factors = _check_factors(factors)
    kwargs = dict(env_kwargs or {})
    env = make_eval_env(env_id, seed=seed, env_kwargs=kwargs)
    inner = env.envs[0].unwrapped
    base_integrator, k = inner.settings.integrator, inner.sim.substeps
    medium, method = inner.medium, inner.sim.config.method
    if medium not in METRICS:
        raise ValueError(f"{env_id} runs in medium {medium!r}; convergence checks water or ground envs")
    make_convergence_policy(policy, env, seed)  # a bad spec fails before any episode runs
    env.close()

    metrics = METRICS[medium]
    values: dict[str, list[float]] = {m: [] for m in metrics}
    failures, substeps, steps = [], [], []
    for f in factors:
        integ = dataclasses.replace(base_integrator, substeps=k * f)
        env = make_eval_env(env_id, seed=seed, env_kwargs={**kwargs, "integrator": integ})
        pol = make_convergence_policy(policy, env, seed)
        (episode,) = evaluate(pol, env, episodes=1, transient=transient)
        env.close()
        for m in metrics:
            values[m].append(float(episode.get(m, math.nan)))
        failures.append(episode["failure"])
        substeps.append(k * f)
        steps.append(base_integrator.h / (k * f))
    return ConvergenceResult(
        env_id=env_id,
        policy=policy,
        medium=medium,
        method=method,
        factors=factors,
        substeps=substeps,
        h=steps,
        values=values,
        failures=failures,
        rtol=RELATIVE_TOLERANCE[medium],
        atol={m: ABSOLUTE_TOLERANCE[m] for m in metrics},
        seed=seed,
    )


def format_convergence(result: ConvergenceResult) -> str:
    """The refinement table.

    Per metric, the value at each factor, the ratio to the finest run, the largest relative
    difference, the tolerance and PASS/FAIL.
    """
    labels = {key: (label, unit) for key, label, unit in metric_columns(list(result.values))}
    r = result
    head = [f"{s} substep{'s' if s > 1 else ''}" for s in r.substeps]
    width = max(len(labels[m][0]) for m in r.values)
    col = max(12, *(len(h) for h in head))
    lines = [
        f"{r.env_id}  policy={r.policy}: one episode (seed {r.seed}) at integration steps "
        f"{', '.join(f'{h:.3g}' for h in r.h)} s ({r.method}); tolerance {100 * r.rtol:g} % ({r.medium}) of the "
        "finest run, or the absolute one near zero",
        f"{'metric':<{width}}  {'unit':<4}  "
        + "  ".join(f"{h:>{col}}" for h in head)
        + f"  {'max rel diff':>12}  {'tolerance':>10}  result",
    ]
    lines.append("-" * len(lines[-1]))
    for m, vals in r.values.items():
        label, unit = labels[m]
        passed = r.passed(m)
        if passed is None:
            lines.append(f"{label:<{width}}  {unit:<4}  " + "  ".join(f"{'n/a':>{col}}" for _ in vals))
            continue
        ref = vals[-1]
        cells = "  ".join(f"{v:>{col}.4g}" for v in vals)
        rel = max(r.deviations(m)) / abs(ref) if ref != 0 else math.inf
        lines.append(
            f"{label:<{width}}  {unit:<4}  {cells}  {100 * rel:>11.2f}%  {r.tolerance(m):>10.3g}  "
            f"{'PASS' if passed else 'FAIL'}"
        )
        ratios = "  ".join(f"{(v / ref if ref != 0 else math.nan):>{col}.3f}" for v in vals)
        lines.append(f"{'  ratio to finest':<{width}}  {'':<4}  {ratios}")
    for s, why in zip(r.substeps, r.failures, strict=True):
        if why:
            lines.append(f"{s} substeps: the episode failed ({why})")
    lines.append("converged: all metrics within tolerance" if r.ok else "NOT converged")
    return "\n".join(lines)
