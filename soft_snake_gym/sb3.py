"""Stable-Baselines3 glue: the batched vector env as an SB3 ``VecEnv``.

``SoftVecEnv("SoftEel-v0", n_envs=64)`` runs every robot in one compiled call per step (see
:class:`~soft_snake_gym.envs.vector.SoftVectorEnv`) and speaks SB3's ``VecEnv`` protocol, so
``PPO("MlpPolicy", SoftVecEnv(...))``, ``VecNormalize`` and ``evaluate_policy`` work on it::

    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize
    from soft_snake_gym.sb3 import SoftVecEnv

    env = VecNormalize(SoftVecEnv("SoftEel-v0", n_envs=64, seed=0))
    PPO("MlpPolicy", env).learn(1_000_000)

SB3's conventions, which differ from Gymnasium's vector API: an episode's robot is reset in the
step that ends it (Gymnasium's ``SAME_STEP`` autoreset), its last observation is in
``info["terminal_observation"]`` and ``info["TimeLimit.truncated"]`` says whether the time
limit (not a failure) ended it; ``infos`` is a list of one dict per robot. Episode statistics
``info["episode"] = {"r", "l", "t"}`` (what SB3's ``Monitor`` adds) come with the episode's
``metrics`` and ``failure``, so no ``Monitor``/``VecMonitor`` is needed. By default a robot's
info is empty on other steps (building per-robot dicts of the env's per-step quantities would
cost more than the physics at large ``n_envs``); ``step_info=True`` gives the single env's full
info every step.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.registration import MAX_EPISODE_STEPS
from soft_snake_gym.envs.vector import SoftVectorEnv
from soft_snake_gym.multiagent.segments import SegmentsEnv, local_terms, split_kwargs

__all__ = ["SegmentVecEnv", "SoftVecEnv"]


class SoftVecEnv(VecEnv):
    """``n_envs`` robots of ``env_id`` as an SB3 ``VecEnv`` over one batched simulator.

    Args:
        env_id: an id of the batched env (``"SoftEel-v0"``, ``"SoftWorm-v0"``, ``"SoftEelGoal-v0"``,
            ``"SoftEelPath-v0"``).
        n_envs: number of robots.
        seed: robot ``i`` is seeded ``seed + i`` at the first reset (as ``make_vec_env``);
            ``None``: unseeded. ``VecEnv.seed(s)`` reseeds the next reset the same way.
        max_episode_steps: time limit per episode (default: the id's registered one, as
            ``gym.make``); ``None``: none.
        num_threads: numba threads for the batched step (default: one per 64 robots).
        step_info: also put the single env's per-step info into every robot's info dict.
        **env_kwargs: the env's keywords (``rod``, ``energy_cost_weight``, ``config``...).
    """

    def __init__(
        self,
        env_id: str = "SoftEel-v0",
        n_envs: int = 8,
        *,
        seed: int | None = None,
        max_episode_steps: int | str | None = "registered",
        num_threads: int | None = None,
        step_info: bool = False,
        **env_kwargs: Any,
    ) -> None:
        """Build the batched env of ``n_envs`` robots (arguments in the class docstring)."""
        self.venv = SoftVectorEnv(
            env_id,
            n_envs,
            max_episode_steps=max_episode_steps,
            num_threads=num_threads,
            autoreset_mode=AutoresetMode.SAME_STEP,
            **env_kwargs,
        )
        self.env_id = env_id
        self.step_info = bool(step_info)
        self._actions: np.ndarray | None = None
        self._all = np.ones(n_envs, dtype=np.bool_)
        super().__init__(n_envs, self.venv.single_observation_space, self.venv.single_action_space)
        if seed is not None:
            self.seed(seed)

    # --- VecEnv API ------------------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        """Reset every robot (with the seeds and options set before) and return the observations."""
        venv = self.venv
        self.reset_infos = venv.reset_robots(self._seeds, [options or None for options in self._options])
        self._reset_seeds()
        self._reset_options()
        return venv.obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions for :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self):
        """Step every robot (resetting those that end); returns SB3's (obs, rewards, dones, infos)."""
        venv = self.venv
        if venv.needs_reset:
            raise RuntimeError(f"{self.env_id} SoftVecEnv: call reset() before step()")
        terminated, truncated = venv.advance(self._actions, self._all)
        rewards = venv.rewards.astype(np.float32)
        dones = terminated | truncated
        if self.step_info:
            full = venv.infos(self._all, ~self._all, [])
            infos = [_row(full, i) for i in range(self.num_envs)]
        else:
            infos = [{} for _ in range(self.num_envs)]
        if dones.any():
            stats = venv.episode_stats(dones)
            for i in np.flatnonzero(dones):
                info = infos[i]
                info["terminal_observation"] = venv.obs[i].copy()
                info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                info["episode"] = {
                    "r": float(stats["r"][i]),
                    "l": int(stats["l"][i]),
                    "t": float(stats["t"][i]),
                }
                info["metrics"] = venv.episode_metrics(i)
                info["failure"] = venv.envs[i].failure
                if venv.envs[i].task_kind != T.TASK_DIRECTION:  # SB3 counts it at the episode's end
                    info["is_success"] = bool(venv.batch.task.rs[i, T.R_SUCCESS] > 0.0)
                venv.reset_robot(i)
        return venv.obs.copy(), rewards, dones, infos

    def close(self) -> None:
        """Close the batched env."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Attribute ``attr_name`` of the env objects of the robots in ``indices``."""
        return [getattr(self.venv.envs[i], attr_name) for i in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set attribute ``attr_name`` to ``value`` on the env objects of the robots in ``indices``."""
        for i in self._indices(indices):
            setattr(self.venv.envs[i], attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        """Call ``method_name`` on the env objects of the robots in ``indices``; returns the results."""
        return [
            getattr(self.venv.envs[i], method_name)(*method_args, **method_kwargs)
            for i in self._indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """True for SB3's ``Monitor``.

        The adapter records its episode statistics itself (so ``evaluate_policy`` reads
        ``info["episode"]``); False for any other wrapper.
        """
        from stable_baselines3.common.monitor import Monitor

        return [wrapper_class is Monitor for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """``None`` per robot: the batched env does not render."""
        return [None for _ in range(self.num_envs)]

    def _indices(self, indices: VecEnvIndices) -> Iterable[int]:
        return self._get_indices(indices)


class SegmentVecEnv(VecEnv):
    """Every segment agent of ``n_envs // (N-2)`` eels as one slot of an SB3 ``VecEnv`` (parameter sharing).

    Slot ``r (N-2) + j - 1`` is agent ``node_j`` of robot ``r``; one PPO policy over all slots
    is one shared local policy. The robots are a batched
    :class:`~soft_snake_gym.envs.vector.SoftVectorEnv` of ``SoftEel-v0`` (robot ``r`` seeded
    ``seed + r``, bitwise the robot of ``gym.make("SoftEelSegments-v0")`` with that seed); local
    observations and rewards are those of :mod:`soft_snake_gym.multiagent.segments`, computed from
    the stacked arrays by the same functions. Episodes end for all agents of a robot at once; each
    slot's ``info["episode"]`` has that agent's return.

    Args:
        n_envs: slots, a multiple of the agents per robot (N-2; 8 for the default N = 10).
        seed: robot ``r`` is seeded ``seed + r`` at the first reset; ``None``: unseeded.
        max_episode_steps: time limit per episode (default 1000); ``None``: none.
        num_threads: numba threads for the batched step (default: one per 64 robots).
        **env_kwargs: :class:`~soft_snake_gym.multiagent.SegmentsEnv`'s keywords (``N``,
            ``neighbors``, ``closure``, ``observe_goal`` and ``SoftEel-v0``'s).
    """

    def __init__(
        self,
        n_envs: int = 64,
        *,
        seed: int | None = None,
        max_episode_steps: int | None = MAX_EPISODE_STEPS,
        num_threads: int | None = None,
        **env_kwargs: Any,
    ) -> None:
        """Build the batched robots (arguments in the class docstring)."""
        proto = SegmentsEnv(**env_kwargs)  # checks every keyword, gives the layout
        self.layout = layout = proto.layout
        k = layout.n_agents
        if not isinstance(n_envs, int | np.integer) or n_envs < k or n_envs % k:
            raise ValueError(
                f"n_envs = {n_envs!r} must be a positive multiple of the agents per robot, N - 2 = {k} "
                f"(each robot gives {k} slots), e.g. {8 * k}"
            )
        self.n_robots = int(n_envs) // k
        own, swim_kwargs = split_kwargs(env_kwargs)
        self.venv = SoftVectorEnv(
            "SoftEel-v0",
            self.n_robots,
            max_episode_steps=max_episode_steps,
            num_threads=num_threads,
            autoreset_mode=AutoresetMode.SAME_STEP,
            **swim_kwargs,
        )
        self.env_id = "SoftEelSegments-v0"
        self._actions: np.ndarray | None = None
        self._robots = np.ones(self.n_robots, dtype=np.bool_)
        self._returns = np.zeros((self.n_robots, k))
        super().__init__(int(n_envs), proto.agent_observation_space, proto.agent_action_space)
        if seed is not None:
            self.seed(seed)

    def reset(self) -> np.ndarray:
        """Reset every robot (robot ``r`` with the ``r``-th seed set before) and return the observations."""
        seeds = self._seeds[: self.n_robots] if self._seeds else [None] * self.n_robots
        self.reset_infos = self.venv.reset_robots(seeds, [None] * self.n_robots)
        self._reset_seeds()
        self._reset_options()
        self._returns[:] = 0.0
        return self.layout.observe(self.venv.obs).reshape(self.num_envs, -1)

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions, (n_envs, 1) or (n_envs,), for :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self):
        """Step every robot (resetting those that end); returns SB3's (obs, rewards, dones, infos)."""
        venv, k = self.venv, self.layout.n_agents
        if venv.needs_reset:
            raise RuntimeError("SoftEelSegments-v0 SegmentVecEnv: call reset() before step()")
        actions = np.asarray(self._actions, dtype=np.float64)
        if actions.size != self.num_envs:
            raise ValueError(
                f"SegmentVecEnv actions have shape {actions.shape}; expected ({self.num_envs}, 1), one per slot"
            )
        terminated, truncated = venv.advance(actions.reshape(self.n_robots, k), self._robots)
        batch = venv.batch
        energy, ctrl = local_terms(batch.task, batch.sim, ~terminated)
        rs = batch.task.rs
        rewards = (rs[:, T.R_RF] + rs[:, T.R_RFAIL])[:, None] + energy + ctrl
        self._returns += rewards
        obs = self.layout.observe(venv.obs)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            stats = venv.episode_stats(done)
            for r in np.flatnonzero(done):
                metrics, failure = venv.episode_metrics(r), venv.envs[r].failure
                for j in range(k):
                    infos[r * k + j] = {
                        "terminal_observation": obs[r, j].copy(),
                        "TimeLimit.truncated": bool(truncated[r] and not terminated[r]),
                        "episode": {
                            "r": float(self._returns[r, j]),
                            "l": int(stats["l"][r]),
                            "t": float(stats["t"][r]),
                        },
                        "metrics": metrics,
                        "failure": failure,
                    }
                venv.reset_robot(r)
                self._returns[r] = 0.0
                obs[r] = self.layout.observe(venv.obs[r])
        return (
            obs.reshape(self.num_envs, -1),
            rewards.reshape(-1).astype(np.float32),
            np.repeat(done, k),
            infos,
        )

    def close(self) -> None:
        """Close the batched env."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Attribute ``attr_name`` of the robot env object of each slot in ``indices``."""
        k = self.layout.n_agents
        return [getattr(self.venv.envs[i // k], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set attribute ``attr_name`` on the robot env object of each slot in ``indices``."""
        k = self.layout.n_agents
        for i in self._get_indices(indices):
            setattr(self.venv.envs[i // k], attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        """Call ``method_name`` on the robot env object of each slot in ``indices``."""
        k = self.layout.n_agents
        return [
            getattr(self.venv.envs[i // k], method_name)(*method_args, **method_kwargs)
            for i in self._get_indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """True for SB3's ``Monitor``: the adapter records episode statistics itself."""
        from stable_baselines3.common.monitor import Monitor

        return [wrapper_class is Monitor for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """``None`` per slot: the batched env does not render."""
        return [None for _ in range(self.num_envs)]


def _row(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """Robot ``i``'s entries of a Gymnasium vector info dict, as the single env's info."""
    row: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_") or not infos.get(f"_{key}", np.zeros(i + 1, bool))[i]:
            continue
        if isinstance(value, dict):
            row[key] = _row(value, i)
        else:
            item = value[i]
            row[key] = (
                item.copy()
                if isinstance(item, np.ndarray)
                else item.item()
                if hasattr(item, "item")
                else item
            )
    return row
