"""What every baseline controller shares: reading the env, batched SB3 ``predict``, state.

A baseline is a controller of docs/model.md §7 wrapped in Stable-Baselines3's ``PolicyPredictor``
protocol: ``predict(observation, state, episode_start, deterministic) -> (action, state)`` on
batched observations. Its memory (clock, PID integral) lives in ``state``, an array
(n_envs, state_size) that is zeroed on ``episode_start``, so the same object runs through
``evaluate_policy`` over a ``VecEnv`` exactly as a trained agent does.

Controllers compute physical rates (curvature rates [1/s] or length rates [m/s]); the env
scales its actions in [-1, 1] by ``max_curvature_rate`` / ``max_length_rate``, so ``predict``
divides by that scale and clips.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from soft_snake_gym.config import config_path, from_dict, load_yaml

__all__ = ["BaselinePolicy", "EnvLayout", "PolicyEnvMismatch", "env_layout"]


class PolicyEnvMismatch(ValueError):
    """A policy was given an environment it cannot control (wrong observation or action)."""


@dataclass(frozen=True)
class EnvLayout:
    """What a baseline needs to know about an environment.

    Attributes:
        env_id: registered id if known (for messages).
        blocks: observation block name -> slice into the flat observation.
        n_actions: size of the action vector.
        dt: control step [s].
        action_scale: physical rate of action 1.0 ([1/s] or [m/s]).
        n_nodes: number of nodes N.
        edge_length: rest edge length at t = 0 [m].
        design_nodes: node count of the robot as designed (``Rod.design_nodes``): N, or the
            ``refined_from`` of a refined rod, on whose nodes the gait parameters are given.
    """

    env_id: str
    blocks: dict[str, slice]
    n_actions: int
    dt: float
    action_scale: float
    n_nodes: int
    edge_length: float
    design_nodes: int


def _unwrap_one(env: Any) -> Any:
    """The innermost gymnasium env of a gym.Env, a wrapper, or an SB3 VecEnv (its first env)."""
    if hasattr(env, "envs"):  # DummyVecEnv and wrappers of it
        return env.envs[0].unwrapped
    venv = getattr(env, "venv", None)
    if venv is not None:
        return _unwrap_one(venv)
    if hasattr(env, "get_attr") and not hasattr(env, "unwrapped"):
        raise PolicyEnvMismatch(
            "baseline policies need a gymnasium env or a DummyVecEnv to read the observation "
            "layout from; got a " + type(env).__name__
        )
    return env.unwrapped


def env_layout(env: Any) -> EnvLayout:
    """Read the observation layout, control step and action scale of a SoftEel/SoftWorm env."""
    inner = _unwrap_one(env)
    structure = getattr(inner, "observation_structure", None)
    if structure is None:
        raise PolicyEnvMismatch(
            f"{type(inner).__name__} has no observation_structure: baseline policies run on "
            "the soft_snake_gym envs (SoftEel-v0, SoftWorm-v0)"
        )
    blocks, start = {}, 0
    for name, size in structure.items():
        size = int(np.prod(size))
        blocks[name] = slice(start, start + size)
        start += size
    spec = getattr(inner, "spec", None)
    env_id = spec.id if spec is not None else type(inner).__name__
    sim = inner.sim
    if "kappa" in blocks:
        scale = float(inner.max_curvature_rate)
    elif "edge_lengths" in blocks:
        scale = float(inner.max_length_rate)
    else:
        scale = 1.0
    return EnvLayout(
        env_id=env_id,
        blocks=blocks,
        n_actions=int(np.prod(inner.action_space.shape)),
        dt=float(inner.dt),
        action_scale=scale,
        n_nodes=int(sim.N),
        edge_length=float(sim.config.rod.edge_length),
        design_nodes=int(sim.config.rod.design_nodes),
    )


class BaselinePolicy:
    """Base class.

    Subclasses set ``Params`` (a frozen dataclass), ``needs`` (observation blocks), ``kind`` and
    implement :meth:`_control`.

    Args:
        env: the environment (gymnasium env, wrapper or DummyVecEnv) to control.
        **params: fields of ``Params``; unknown names raise :class:`ConfigError`.
    """

    Params: ClassVar[type]
    name: ClassVar[str]
    needs: ClassVar[tuple[str, ...]]
    controls: ClassVar[str]  # "curvature" or "length"
    suggestion: ClassVar[str]

    def __init__(self, env: Any, **params: Any) -> None:
        """Check that ``env`` fits the policy and read the parameters (arguments in the class docstring)."""
        self.layout = layout = env_layout(env)
        missing = [b for b in self.needs if b not in layout.blocks]
        if missing:
            raise PolicyEnvMismatch(
                f"policy {self.name!r} controls {self.controls} and needs the observation "
                f"blocks {list(self.needs)}, but {layout.env_id} observes "
                f"{list(layout.blocks)}; {self.suggestion}"
            )
        self.params = from_dict(self.Params, params, where=f"{self.name} policy")
        self._setup()
        if self.n_outputs != layout.n_actions:
            raise PolicyEnvMismatch(
                f"policy {self.name!r} produces {self.n_outputs} actions but {layout.env_id} "
                f"expects {layout.n_actions}"
            )
        #: tracking error |desired - measured| per env and node of the last predict call.
        self.last_error: np.ndarray | None = None
        self.last_rates: np.ndarray | None = None

    @classmethod
    def from_yaml(cls, env: Any, path: str | Path, **overrides: Any) -> BaselinePolicy:
        """Build from a YAML mapping of ``Params`` fields (``overrides`` win).

        A shipped policy config by name (``"pid"``) or a file.
        """
        data = load_yaml(config_path(path, "policy"))
        return cls(env, **{**data, **overrides})

    # subclasses ------------------------------------------------------------------------
    n_outputs: int
    state_size: int

    def _setup(self) -> None:
        raise NotImplementedError

    def _control(self, obs: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (rates (n, n_outputs) in physical units, error (n, m)); update ``state``."""
        raise NotImplementedError

    # SB3 PolicyPredictor ------------------------------------------------------------------
    def block(self, obs: np.ndarray, name: str) -> np.ndarray:
        """Observation block ``name`` of batched observations, float64 (n_envs, size)."""
        return obs[:, self.layout.blocks[name]].astype(np.float64)

    def initial_state(self, n_envs: int) -> np.ndarray:
        """Zero memory for ``n_envs`` environments, (n_envs, state_size)."""
        return np.zeros((n_envs, self.state_size))

    def predict(
        self,
        observation: np.ndarray,
        state: np.ndarray | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, np.ndarray]:
        """SB3's ``predict``: actions in [-1, 1] for a batch (or one) observation.

        Args:
            observation: (n_envs, obs_dim) or (obs_dim,).
            state: the memory returned by the previous call, (n_envs, state_size), or None.
            episode_start: (n_envs,) bools; True zeroes that env's memory (clock, integral).
            deterministic: ignored; baselines are deterministic.

        Returns:
            (actions float32 (n_envs, n_actions) or (n_actions,), new state).
        """
        obs = np.asarray(observation)
        single = obs.ndim == 1
        if single:
            obs = obs[None, :]
        n = obs.shape[0]
        if state is None or np.shape(state) != (n, self.state_size):
            state = self.initial_state(n)
        else:
            state = np.array(state, dtype=np.float64, copy=True)
        if episode_start is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1)
            if starts.size == n:
                state[starts] = 0.0
        rates, error = self._control(obs, state)
        self.last_rates = rates
        self.last_error = error
        action = np.clip(rates / self.layout.action_scale, -1.0, 1.0).astype(np.float32)
        return (action[0] if single else action), state

    def __repr__(self) -> str:
        """The class name and the parameters, as ``Name(key=value, ...)``."""
        args = ", ".join(
            f"{f.name}={getattr(self.params, f.name)!r}" for f in dataclasses.fields(self.params)
        )
        return f"{type(self).__name__}({args})"
