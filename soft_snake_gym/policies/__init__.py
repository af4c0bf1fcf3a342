"""Baseline controllers of the thesis (docs/model.md §7), as SB3-compatible policies.

``make_policy("pid:alpha=0.5,omega=2.1", env)`` builds one from a short spec; a spec that is a
path to a saved Stable-Baselines3 model loads that model instead.
"""

from __future__ import annotations

import dataclasses
import difflib
from pathlib import Path
from typing import Any

from soft_snake_gym.config import ConfigError, from_dict, load_yaml
from soft_snake_gym.gaits import SerpenoidParams
from soft_snake_gym.policies.base import (
    BaselinePolicy,
    EnvLayout,
    PolicyEnvMismatch,
    _unwrap_one,
    env_layout,
    parse_value,
)
from soft_snake_gym.policies.decentralized import DecentralizedPhasePID
from soft_snake_gym.policies.inching import InchingPID, InchingWave
from soft_snake_gym.policies.open_loop import OpenLoopSerpenoid
from soft_snake_gym.policies.pid import CurvaturePID

__all__ = [
    "BASELINES",
    "BaselinePolicy",
    "CurvaturePID",
    "DecentralizedPhasePID",
    "EnvLayout",
    "InchingPID",
    "InchingWave",
    "OpenLoopSerpenoid",
    "PolicyEnvMismatch",
    "env_layout",
    "load_model",
    "make_policy",
    "parse_policy_spec",
    "policy_gait",
]

#: Baseline names accepted by :func:`make_policy` and ``soft-snake evaluate --policy``.
BASELINES: dict[str, type[BaselinePolicy]] = {
    "open-loop": OpenLoopSerpenoid,
    "pid": CurvaturePID,
    "decentralized": DecentralizedPhasePID,
    "inching": InchingWave,
    "inching-pid": InchingPID,
}

_ALGOS = ("PPO", "SAC", "TD3", "A2C", "DDPG")


def parse_policy_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """Split ``"name:key=value,key=value"`` into the name and a dict of parsed values.

    Values are numbers (``0.5``, ``pi/6``, ``2*pi/3``) or strings (``closure=pacemaker``).
    """
    name, _, rest = spec.partition(":")
    params: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ConfigError(
                f"policy option {item!r} in {spec!r} is not key=value; write e.g. 'pid:alpha=0.5,omega=2.1'"
            )
        params[key.strip()] = parse_value(value)
    return name.strip(), params


def _looks_like_path(spec: str) -> bool:
    return spec.endswith(".zip") or "/" in spec or "\\" in spec or Path(spec).exists()


def load_model(path: str | Path, env: Any) -> Any:
    """Load a saved SB3 model (any of PPO, SAC, TD3, A2C, DDPG) and check it fits ``env``."""
    path = Path(path)
    if not path.is_file():
        alt = path.with_suffix(".zip")
        if path.suffix != ".zip" and alt.is_file():
            path = alt
        else:
            raise ConfigError(f"model file {str(path)!r} does not exist; pass the .zip that model.save() wrote")
    import stable_baselines3 as sb3

    errors = []
    for algo in _ALGOS:
        try:
            model = getattr(sb3, algo).load(path, device="cpu")
            break
        except Exception as err:  # noqa: BLE001 - try the next algorithm
            errors.append(f"{algo}: {type(err).__name__}")
    else:
        raise ConfigError(f"{str(path)!r} is not a loadable Stable-Baselines3 model ({'; '.join(errors)})")
    obs_space = getattr(env, "observation_space", None)
    if obs_space is not None and model.observation_space.shape != obs_space.shape:
        raise PolicyEnvMismatch(
            f"model {str(path)!r} was trained on observations of shape "
            f"{model.observation_space.shape}, but this env observes {obs_space.shape}; "
            "evaluate it on the env id it was trained on"
        )
    act_space = getattr(env, "action_space", None)
    if act_space is not None and model.action_space.shape != act_space.shape:
        raise PolicyEnvMismatch(
            f"model {str(path)!r} produces actions of shape {model.action_space.shape}, "
            f"but this env expects {act_space.shape}"
        )
    return model


def make_policy(spec: str, env: Any, config: str | Path | None = None) -> Any:
    """Build a baseline from ``"name[:key=value,...]"`` or load a model from a path.

    Args:
        spec: a name in :data:`BASELINES`, optionally with options
            (``"pid:alpha=0.5,omega=2.1"``, ``"decentralized:closure=pacemaker"``), or a path
            to a saved SB3 model (``.zip``).
        env: the env to control (gymnasium env, wrapper or DummyVecEnv).
        config: optional YAML file of the policy's parameters; options in ``spec`` win.

    Raises:
        ConfigError: unknown name or key, malformed option, missing model file.
        PolicyEnvMismatch: the policy cannot control this env.
    """
    if spec.startswith("zoo:"):  # an agent shipped with the package
        from soft_snake_gym.training import load_trained, zoo_path

        return load_trained(zoo_path(_unwrap_one(env).env_id, spec[4:]), env)
    name, params = parse_policy_spec(spec)
    if name not in BASELINES:
        if _looks_like_path(spec):  # a run folder or model zip, with its VecNormalize statistics
            from soft_snake_gym.training import load_trained

            return load_trained(spec, env)
        close = difflib.get_close_matches(name, list(BASELINES), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else "."
        raise ConfigError(
            f"unknown policy {name!r}{hint} Choose one of {', '.join(BASELINES)}, "
            "or give the path to a saved SB3 model (.zip)"
        )
    cls = BASELINES[name]
    if config is not None:
        params = {**load_yaml(config), **params}
    return cls(env, **params)


def policy_gait(spec: str, config: str | Path | None = None) -> dict[str, Any]:
    """The serpenoid gait of a bending baseline, as the env keyword ``start_on_gait`` takes it.

    Args:
        spec: a baseline spec as for :func:`make_policy` (``"pid:alpha=pi/3"``).
        config: optional YAML file of the policy's parameters; options in ``spec`` win.

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
        params = {**load_yaml(config), **params}
    p = from_dict(cls.Params, params, where=f"{name} policy")
    return {f.name: getattr(p, f.name) for f in dataclasses.fields(SerpenoidParams)}
