"""PettingZoo parallel env: the eel with one agent per interior node (``node_1 ... node_{N-2}``).

PettingZoo's module convention::

    from soft_snake_gym.multiagent import eel_segments_v0

    env = eel_segments_v0.parallel_env(N=10, neighbors="both")
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

``env()`` is the same env in PettingZoo's AEC (turn-by-turn) API, through
``pettingzoo.utils.parallel_to_aec``. Each agent acts on its own node's curvature rate
(``Box(-1, 1, (1,))``, scaled as in ``SoftEel-v0``) and observes only its own and its
neighbours' curvature and rate and its rest curvature; the keywords, the observation blocks and
the reward terms are those of :class:`soft_snake_gym.multiagent.SegmentsEnv` (module
:mod:`soft_snake_gym.multiagent.segments`), over which this env is built: the same robot, physics,
reset noise, seeding, randomization and failure handling as ``SoftEel-v0``. Every agent's
``info`` has its reward terms (``reward_forward`` shared, ``reward_energy`` and ``reward_ctrl``
local, ``reward_failure``), ``forward_speed``, ``failure`` and the episode's running
``metrics``. Episodes end for every agent at once: on a physics failure (terminated) or after
``max_cycles`` steps (truncated; default 1000 = 10 s, ``SoftEel-v0``'s limit).

Needs PettingZoo: ``pip install 'soft_snake_gym[multiagent]'``.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from soft_snake_gym.envs.registration import MAX_EPISODE_STEPS
from soft_snake_gym.multiagent.segments import SegmentsEnv, node_index
from soft_snake_gym.params import check_int

try:
    from pettingzoo import ParallelEnv
    from pettingzoo.utils import parallel_to_aec
except ImportError:  # the error comes when an env is made, with the command to fix it
    ParallelEnv, parallel_to_aec = object, None

__all__ = ["env", "parallel_env", "raw_env", "SegmentsParallelEnv"]

RESET_OPTIONS = ("x", "v", "kbar", "lbar", "goal_direction")
_MISSING = "the PettingZoo env needs pettingzoo: pip install 'soft_snake_gym[multiagent]'"


class SegmentsParallelEnv(ParallelEnv):
    """The eel's interior nodes as agents of a PettingZoo ``ParallelEnv``.

    Args:
        max_cycles: steps per episode (truncation), default 1000.
        render_mode: ``None`` or ``"rgb_array"``.
        **kwargs: :class:`~soft_snake_gym.multiagent.SegmentsEnv`'s keywords: ``N``,
            ``neighbors``, ``closure``, ``observe_goal`` and every ``SoftEel-v0`` keyword.
    """

    metadata = {"name": "eel_segments_v0", "render_modes": ["rgb_array"], "is_parallelizable": True}

    def __init__(self, max_cycles: int = MAX_EPISODE_STEPS, render_mode: str | None = None, **kwargs: Any):
        """Build the team (arguments in the class docstring)."""
        if parallel_to_aec is None:
            raise ImportError(_MISSING)
        self.max_cycles = check_int("max_cycles", max_cycles, 1, hint="steps per episode")
        self.team = SegmentsEnv(render_mode=render_mode, **kwargs)
        self.render_mode = render_mode
        self.possible_agents = list(self.team.possible_agents)
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self._obs_space = self.team.agent_observation_space
        self._act_space = self.team.agent_action_space
        self._action = np.zeros(len(self.possible_agents), dtype=np.float32)
        self._steps = 0

    def observation_space(self, agent: str):
        """The local observation space of ``agent`` (the same for every agent)."""
        self._check_agent(agent)
        return self._obs_space

    def action_space(self, agent: str):
        """``Box(-1, 1, (1,), float32)``: ``agent``'s normalized curvature rate."""
        self._check_agent(agent)
        return self._act_space

    def _check_agent(self, agent: Any) -> None:
        if agent not in self._index:
            node_index(agent, self.team.N)  # raises, naming the valid ids
            raise ValueError(f"agent {agent!r} does not exist; the agents are {self.possible_agents}")

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the robot (as ``SoftEel-v0`` with the same seed); returns (observations, infos).

        ``options`` are ``SoftEel-v0``'s (``x``, ``v``, ``kbar``, ``lbar``, ``goal_direction``);
        others are dropped with a warning (PettingZoo's API test passes one of its own).
        """
        options = dict(options or {})
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            warnings.warn(
                f"eel_segments_v0 reset options {unknown} are unknown and ignored; valid: {', '.join(RESET_OPTIONS)}",
                stacklevel=2,
            )
            options = {k: v for k, v in options.items() if k in RESET_OPTIONS}
        obs, info = self.team.reset(seed=seed, options=options or None)
        self.agents = list(self.possible_agents)
        self._steps = 0
        infos = {a: {"randomized": dict(info["randomized"]), "failure": None} for a in self.agents}
        return self._split(obs), infos

    def step(self, actions: dict[str, Any]):
        """Step with one action per live agent.

        Args:
            actions: ``{agent: action}`` with exactly the live agents (``env.agents``), each action
                a number or an array of shape (1,) in [-1, 1].

        Returns:
            ``(observations, rewards, terminations, truncations, infos)``, dicts keyed by agent.

        Raises:
            ValueError: a missing or unknown agent, or an action of the wrong shape or not finite.
            RuntimeError: ``step`` before ``reset`` or after the episode ended.
        """
        if not self.agents:
            raise RuntimeError("eel_segments_v0: no live agents; call reset() before step()")
        if not isinstance(actions, dict):
            raise ValueError(f"actions must be a dict {{agent: action}}, not {type(actions).__name__}")
        missing = [a for a in self.agents if a not in actions]
        extra = [a for a in actions if a not in self._index]
        if missing or extra:
            parts = ([f"missing {missing}"] if missing else []) + ([f"unknown {extra}"] if extra else [])
            raise ValueError(
                f"eel_segments_v0 actions: {'; '.join(parts)}; give one action for each of {self.agents}"
            )
        act = self._action
        for agent, a in actions.items():
            try:
                value = np.asarray(a, dtype=np.float64)
            except (TypeError, ValueError):
                value = None
            if value is None or value.size != 1 or value.ndim > 1:
                raise ValueError(
                    f"action of {agent} is {a!r}; expected one number or an array of shape (1,) in [-1, 1]"
                )
            if not np.isfinite(value).all():
                raise ValueError(f"action of {agent} is {a!r}; it must be a finite number in [-1, 1]")
            act[self._index[agent]] = value.reshape(())
        obs, _, terminated, _, info = self.team.step(act.copy())
        self._steps += 1
        truncated = not terminated and self._steps >= self.max_cycles
        shared = {
            "forward_speed": info["forward_speed"],
            "reward_forward": info["reward_forward"],
            "reward_failure": info["reward_failure"],
            "failure": info["failure"],
            "metrics": info["metrics"],
        }
        energy, ctrl, rewards = info["agent_reward_energy"], info["agent_reward_ctrl"], info["agent_rewards"]
        agents = self.agents
        infos = {
            a: {**shared, "reward_energy": float(energy[i]), "reward_ctrl": float(ctrl[i])}
            for a, i in ((a, self._index[a]) for a in agents)
        }
        out = (
            self._split(obs),
            {a: float(rewards[self._index[a]]) for a in agents},
            {a: bool(terminated) for a in agents},
            {a: bool(truncated) for a in agents},
            infos,
        )
        if terminated or truncated:
            self.agents = []
        return out

    def _split(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        return {a: obs[self._index[a]] for a in self.agents}

    def state(self) -> np.ndarray:
        """The robot's ``SoftEel-v0`` observation (the global state, for centralized critics)."""
        return self.team.swim.task.obs.copy()

    def render(self):
        """The robot's frame (``render_mode="rgb_array"``)."""
        return self.team.render()

    def close(self) -> None:
        """Close the renderer."""
        self.team.close()


def parallel_env(**kwargs: Any) -> SegmentsParallelEnv:
    """The PettingZoo parallel env (keywords of :class:`SegmentsParallelEnv`)."""
    return SegmentsParallelEnv(**kwargs)


def raw_env(**kwargs: Any):
    """The AEC version of :func:`parallel_env` (PettingZoo's ``parallel_to_aec``)."""
    if parallel_to_aec is None:
        raise ImportError(_MISSING)
    return parallel_to_aec(parallel_env(**kwargs))


def env(**kwargs: Any):
    """The AEC env (PettingZoo's ``env()`` convention), the same as :func:`raw_env`."""
    return raw_env(**kwargs)
