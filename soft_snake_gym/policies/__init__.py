"""Baseline controllers of the thesis (docs/model.md §7), as SB3-compatible policies.

``make_baseline("pid:alpha=0.5,omega=2.1", env)`` builds one from a short spec;
:func:`soft_snake_gym.agents.make_policy` also loads trained agents.
"""

from __future__ import annotations

import dataclasses
import difflib
from pathlib import Path
from typing import Any

from soft_snake_gym.config import ConfigError, config_path, from_dict, load_yaml, parse_assignments
from soft_snake_gym.gaits import SerpenoidParams
from soft_snake_gym.policies.base import (
    BaselinePolicy,
    EnvLayout,
    PolicyEnvMismatch,
    env_layout,
)
from soft_snake_gym.policies.decentralized import DecentralizedPhasePID
from soft_snake_gym.policies.inching import InchingPID, InchingWave
from soft_snake_gym.policies.los import HeadingController, LOSGuidance
from soft_snake_gym.policies.open_loop import OpenLoopSerpenoid
from soft_snake_gym.policies.pid import CurvaturePID

__all__ = [
    "BASELINES",
    "BaselinePolicy",
    "CurvaturePID",
    "DecentralizedPhasePID",
    "EnvLayout",
    "HeadingController",
    "LOSGuidance",
    "InchingPID",
    "InchingWave",
    "OpenLoopSerpenoid",
    "PolicyEnvMismatch",
    "env_layout",
    "make_baseline",
    "parse_policy_spec",
    "policy_gait",
]

#: Baseline names accepted by :func:`make_baseline` and ``soft-snake evaluate --policy``.
BASELINES: dict[str, type[BaselinePolicy]] = {
    "open-loop": OpenLoopSerpenoid,
    "pid": CurvaturePID,
    "decentralized": DecentralizedPhasePID,
    "inching": InchingWave,
    "inching-pid": InchingPID,
    "los": LOSGuidance,
}


def parse_policy_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """Split ``"name:key=value,key=value"`` into the name and a dict of parsed values.

    Values follow :func:`soft_snake_gym.config.parse_value`: numbers (``0.5``, ``pi/6``,
    ``2*pi/3``) or strings (``closure=pacemaker``).
    """
    name, _, rest = spec.partition(":")
    usage = f"policy option {{item}} in {spec!r} is not key=value; write e.g. 'pid:alpha=0.5,omega=2.1'"
    return name.strip(), parse_assignments([rest], usage, nested=False, sep=",")


def make_baseline(spec: str, env: Any, config: str | Path | None = None) -> BaselinePolicy:
    """Build a baseline from ``"name[:key=value,...]"``.

    Args:
        spec: a name in :data:`BASELINES`, optionally with options (``"pid:alpha=0.5,omega=2.1"``,
            ``"decentralized:closure=pacemaker"``).
        env: the env to control (gymnasium env, wrapper or DummyVecEnv).
        config: the policy's parameters: a shipped policy config by name (``"pid"``) or a YAML
            file; options in ``spec`` win.

    Raises:
        ConfigError: unknown name or key, malformed option.
        PolicyEnvMismatch: the policy cannot control this env.
    """
    name, params = parse_policy_spec(spec)
    if name not in BASELINES:
        close = difflib.get_close_matches(name, list(BASELINES), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else "."
        raise ConfigError(
            f"unknown policy {name!r}{hint} Choose one of {', '.join(BASELINES)}, "
            "or give the path to a saved SB3 model (.zip)"
        )
    if config is not None:
        params = {**load_yaml(config_path(config, "policy")), **params}
    return BASELINES[name](env, **params)


def policy_gait(spec: str, config: str | Path | None = None) -> dict[str, Any]:
    """The serpenoid gait of a bending baseline, as the env keyword ``start_on_gait`` takes it.

    Args:
        spec: a baseline spec as for :func:`make_baseline` (``"pid:alpha=pi/3"``).
        config: the policy's parameters: a shipped policy config by name or a YAML file;
            options in ``spec`` win.

    Returns:
        ``{"alpha", "omega", "delta", "gamma", "psi0"}`` of that policy (its defaults filled in,
        validated by its own parameter class).

    Raises:
        ConfigError: the spec is not a serpenoid baseline (open-loop, pid, decentralized), or
            its parameters are invalid.
    """
    cls = BASELINES.get(spec.partition(":")[0].strip())
    serpenoid = [n for n, c in BASELINES.items() if issubclass(c.Params, SerpenoidParams)]
    if cls is None or not issubclass(cls.Params, SerpenoidParams):
        raise ConfigError(
            f"policy {spec!r} has no serpenoid gait to start on; starting on the gait takes it from "
            f"one of {', '.join(serpenoid)}. For another policy, give the env the gait itself: "
            "start_on_gait={'alpha': ...} (on the command line --env-kwarg start_on_gait.alpha=pi/6)"
        )
    name, params = parse_policy_spec(spec)
    if config is not None:
        params = {**load_yaml(config_path(config, "policy")), **params}
    p = from_dict(cls.Params, params, where=f"{name} policy")
    return {f.name: getattr(p, f.name) for f in dataclasses.fields(SerpenoidParams)}
