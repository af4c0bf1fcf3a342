"""TRANSITIONAL (issue 10): saved agents as plain ``predict()`` objects. These move to
``soft_snake_gym.agents`` (branch ``cli``); the lead deletes this module at merge."""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np

from soft_snake_gym.config import ConfigError
from soft_snake_gym.training.run import latest_checkpoint

__all__ = ["TrainedPolicy", "load_trained", "zoo_path", "ZOO"]


class TrainedPolicy:
    """A trained SB3 model with its ``VecNormalize`` observation statistics, behaving like
    the baselines: ``predict`` takes raw observations, so it runs through the same
    evaluation as any controller."""

    def __init__(self, model: Any, obs_rms: Any | None, clip_obs: float = 10.0, epsilon: float = 1e-8,
                 name: str = "trained") -> None:
        self.model = model
        self.obs_rms = obs_rms
        self.clip_obs = clip_obs
        self.epsilon = epsilon
        self.name = name
        self.observation_space = model.observation_space
        self.action_space = model.action_space

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_rms is None:
            return obs
        return np.clip((obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon),
                       -self.clip_obs, self.clip_obs).astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        return self.model.predict(self.normalize(np.asarray(observation)), state, episode_start,
                                  deterministic)

    def __repr__(self) -> str:
        return f"TrainedPolicy({self.name})"


def _find_model(path: Path) -> tuple[Path, Path | None]:
    """The model zip and its VecNormalize statistics for a run folder or a zip."""
    if path.is_dir():
        for name, stats in (("best_model.zip", "best_vecnormalize.pkl"),
                            ("final_model.zip", "vecnormalize.pkl"),
                            ("model.zip", "vecnormalize.pkl")):
            if (path / name).is_file():
                return path / name, (path / stats if (path / stats).is_file() else None)
        ckpt = latest_checkpoint(path)
        if ckpt is not None:
            return ckpt
        raise ConfigError(
            f"run folder {str(path)!r} holds no model (best_model.zip, final_model.zip or a checkpoint)"
        )
    if not path.is_file():
        raise ConfigError(f"model {str(path)!r} does not exist; give a run folder or a .zip written by training")
    for stats in (path.with_name(path.stem.replace("model", "vecnormalize") + ".pkl"),
                  path.parent / "vecnormalize.pkl"):
        if stats.is_file() and stats != path:
            return path, stats
    return path, None


def load_trained(path: str | Path, env: Any) -> TrainedPolicy:
    """Load a trained agent from a run folder or a model zip (with the VecNormalize
    statistics saved beside it) as a :class:`TrainedPolicy`.

    Raises:
        ConfigError: nothing loadable at ``path``.
        PolicyEnvMismatch: the model does not fit ``env``.
    """
    from soft_snake_gym.policies import load_model  # policies imports this module: a cycle until merge

    model_path, stats_path = _find_model(Path(path))
    model = load_model(model_path, env)
    obs_rms, clip = None, 10.0
    if stats_path is not None:
        with open(stats_path, "rb") as fh:
            vn = pickle.load(fh)
        if getattr(vn, "norm_obs", True):
            obs_rms, clip = vn.obs_rms, vn.clip_obs
    return TrainedPolicy(model, obs_rms, clip, name=str(path))


ZOO = Path(__file__).resolve().parents[1] / "zoo"


def zoo_path(env_id: str, algo: str) -> Path:
    """The folder of the agent shipped with the package for ``env_id`` and ``algo``."""
    path = ZOO / env_id / algo.lower()
    if not (path / "model.zip").is_file():
        shipped = sorted(f"zoo:{p.name} on {p.parent.name}" for p in ZOO.glob("*/*") if (p / "model.zip").is_file())
        raise ConfigError(
            f"no shipped {algo.lower()} agent for {env_id}; shipped agents: {', '.join(shipped) or 'none'}"
        )
    return path

