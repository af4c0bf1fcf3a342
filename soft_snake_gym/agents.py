"""Every way to get a policy: a baseline by spec, a saved SB3 model, a run folder, a shipped agent.

``make_policy("pid:alpha=0.5", env)`` builds a baseline of :mod:`soft_snake_gym.policies`;
``make_policy("runs/eel", env)`` or a model zip loads a trained agent with the
``VecNormalize`` statistics saved beside it as a :class:`TrainedPolicy`; ``make_policy("zoo:ppo",
env)`` loads the agent shipped with the package for the env's id (:func:`zoo_path`). Every
result has SB3's ``predict`` on raw observations, so one evaluation runs them all.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np

from soft_snake_gym.config import ConfigError
from soft_snake_gym.multiagent.policies import SharedLocalPolicy, segment_team, team_policy
from soft_snake_gym.policies import BASELINES, make_baseline, parse_policy_spec
from soft_snake_gym.policies.base import PolicyEnvMismatch, _unwrap_one

__all__ = [
    "ZOO",
    "TrainedPolicy",
    "for_env",
    "latest_checkpoint",
    "load_model",
    "load_trained",
    "make_policy",
    "zoo_path",
]

_ALGOS = ("PPO", "SAC", "TD3", "A2C", "DDPG")

#: The agents shipped with the package: ``zoo/<env id>/<algo>/model.zip`` (+ ``vecnormalize.pkl``).
ZOO = Path(__file__).resolve().parent / "zoo"


def make_policy(spec: str, env: Any, config: str | Path | None = None) -> Any:
    """A policy for ``env`` from a spec.

    Args:
        spec: a baseline name in :data:`~soft_snake_gym.policies.BASELINES`, optionally with
            options (``"pid:alpha=0.5,omega=2.1"``, ``"decentralized:closure=pacemaker"``);
            ``"zoo:<algo>"`` for the agent shipped for the env's id; or the path to a run
            folder or a saved SB3 model (``.zip``).
        env: the env to control (gymnasium env, wrapper or DummyVecEnv).
        config: a baseline's parameters: a shipped policy config by name (``"pid"``) or a YAML
            file; options in ``spec`` win.

    Raises:
        ConfigError: unknown name or key, malformed option, missing model file.
        PolicyEnvMismatch: the policy cannot control this env.
    """
    if segment_team(env) is not None:  # the segment team: its baselines and shared local policies
        if spec.startswith("zoo:"):
            spec = str(zoo_path(segment_team(env).env_id, spec[4:]))
        name, _ = parse_policy_spec(spec)
        trained = load_trained if name not in BASELINES and _looks_like_path(spec) else None
        return team_policy(spec, env, config, trained)
    if spec.startswith("zoo:"):  # an agent shipped with the package
        return load_trained(zoo_path(_unwrap_one(env).env_id, spec[4:]), env)
    name, _ = parse_policy_spec(spec)
    if name not in BASELINES and _looks_like_path(spec):  # a run folder or model zip
        return load_trained(spec, env)
    return make_baseline(spec, env, config)


def for_env(policy: Any, env: Any) -> Any:
    """``policy`` as it runs on ``env``: a single-agent policy on a segment team is shared by every agent."""
    return (
        SharedLocalPolicy(policy, getattr(policy, "name", "shared"))
        if segment_team(env) is not None
        else policy
    )


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
            raise ConfigError(
                f"model file {str(path)!r} does not exist; pass the .zip that model.save() wrote"
            )
    import stable_baselines3 as sb3  # here, not at the top: importing SB3 (torch) costs seconds

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


class TrainedPolicy:
    """A trained SB3 model with its ``VecNormalize`` observation statistics, behaving like the baselines.

    ``predict`` takes raw observations, so it runs through the same evaluation as any controller.

    Args:
        model: the SB3 model.
        obs_rms: ``VecNormalize.obs_rms`` (mean, var of the observations), or None.
        clip_obs: bound of the normalized observations.
        epsilon: added to the variance.
        name: shown by ``repr``.
    """

    def __init__(
        self,
        model: Any,
        obs_rms: Any | None,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
        name: str = "trained",
    ) -> None:
        """Wrap ``model`` and its observation statistics (arguments in the class docstring)."""
        self.model = model
        self.obs_rms = obs_rms
        self.clip_obs = clip_obs
        self.epsilon = epsilon
        self.name = name
        self.observation_space = model.observation_space
        self.action_space = model.action_space

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """Observations as ``VecNormalize`` gave them to the model in training."""
        if self.obs_rms is None:
            return obs
        return np.clip(
            (obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon),
            -self.clip_obs,
            self.clip_obs,
        ).astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3's ``predict`` on raw observations."""
        return self.model.predict(
            self.normalize(np.asarray(observation)), state, episode_start, deterministic
        )

    def __repr__(self) -> str:
        """``TrainedPolicy(name)``."""
        return f"TrainedPolicy({self.name})"


def latest_checkpoint(run_dir: Path) -> tuple[Path, Path | None] | None:
    """The newest checkpoint of a run folder (model zip, VecNormalize pickle or None)."""
    ckpts = sorted(
        (run_dir / "checkpoints").glob("model_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1])
    )
    if not ckpts:
        return None
    model = ckpts[-1]
    stats = model.with_name(f"vecnormalize_{model.stem.split('_')[1]}_steps.pkl")
    return model, (stats if stats.is_file() else None)


def _find_model(path: Path) -> tuple[Path, Path | None]:
    """The model zip and its VecNormalize statistics for a run folder or a zip."""
    if path.is_dir():
        for name, stats in (
            ("best_model.zip", "best_vecnormalize.pkl"),
            ("final_model.zip", "vecnormalize.pkl"),
            ("model.zip", "vecnormalize.pkl"),
        ):
            if (path / name).is_file():
                return path / name, (path / stats if (path / stats).is_file() else None)
        ckpt = latest_checkpoint(path)
        if ckpt is not None:
            return ckpt
        raise ConfigError(
            f"run folder {str(path)!r} holds no model (best_model.zip, final_model.zip or a checkpoint)"
        )
    if not path.is_file():
        raise ConfigError(
            f"model {str(path)!r} does not exist; give a run folder or a .zip written by training"
        )
    for stats in (
        path.with_name(path.stem.replace("model", "vecnormalize") + ".pkl"),
        path.parent / "vecnormalize.pkl",
    ):
        if stats.is_file() and stats != path:
            return path, stats
    return path, None


def load_trained(path: str | Path, env: Any) -> TrainedPolicy:
    """Load a trained agent as a :class:`TrainedPolicy`.

    From a run folder or a model zip (with the VecNormalize statistics saved beside it).

    Raises:
        ConfigError: nothing loadable at ``path``.
        PolicyEnvMismatch: the model does not fit ``env``.
    """
    model_path, stats_path = _find_model(Path(path))
    model = load_model(model_path, env)
    obs_rms, clip = None, 10.0
    if stats_path is not None:
        with open(stats_path, "rb") as fh:
            vn = pickle.load(fh)
        if getattr(vn, "norm_obs", True):
            obs_rms, clip = vn.obs_rms, vn.clip_obs
    return TrainedPolicy(model, obs_rms, clip, name=str(path))


def zoo_path(env_id: str, algo: str) -> Path:
    """The folder of the agent shipped with the package for ``env_id`` and ``algo``."""
    path = ZOO / env_id / algo.lower()
    if not (path / "model.zip").is_file():
        shipped = sorted(
            f"zoo:{p.name} on {p.parent.name}" for p in ZOO.glob("*/*") if (p / "model.zip").is_file()
        )
        raise ConfigError(
            f"no shipped {algo.lower()} agent for {env_id}; shipped agents: {', '.join(shipped) or 'none'}"
        )
    return path
