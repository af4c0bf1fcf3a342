"""Policies of the segment team (``SoftEelSegments-v0``): shared local policies and the baselines.

Every policy here has SB3's ``predict(observation, state, episode_start, deterministic)`` on the
team's observations, (n_envs, N-2, obs_dim), and returns actions (n_envs, N-2), so
``evaluate``, ``compare`` and the robustness study run learned and classical control through
the same evaluation:

- :class:`SharedLocalPolicy`: one policy of a single agent's observation (a trained PPO agent)
  applied to every agent, row by row (parameter sharing).
- :class:`DecentralizedTeam`: the thesis's :class:`~soft_snake_gym.policies.DecentralizedPhasePID`
  (either closure) with each node reading its head-ward neighbour's curvature and rate from its
  *own* local observation, so a lost neighbour message reaches only that node's controller.
- :class:`CentralizedTeam`: any ``SoftEel-v0`` curvature baseline (``pid``, ``open-loop``) fed by
  every node's own measurements, as a central computer with a bus to every node would be: the
  nodes' own ``kappa``, ``kappa_dot``, ``kbar`` rebuilt into ``SoftEel-v0``'s observation layout
  (its ``com_velocity_body`` and ``goal_direction_body`` blocks are zero; no curvature baseline
  reads them). Bitwise the baseline on ``SoftEel-v0``.

The baseline classes are used unchanged (built on the team's ``SoftEel-v0`` robot, so their
gait mapping, gains and parameter checks are theirs); :func:`team_policy` builds any of these
from a spec as :func:`soft_snake_gym.agents.make_policy` takes it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from soft_snake_gym.multiagent.segments import SegmentsEnv
from soft_snake_gym.policies import BASELINES, make_baseline, parse_policy_spec
from soft_snake_gym.policies.base import PolicyEnvMismatch, _unwrap_one
from soft_snake_gym.policies.decentralized import DecentralizedPhasePID, estimate_phase
from soft_snake_gym.policies.pid import pid_law

__all__ = ["CentralizedTeam", "DecentralizedTeam", "SharedLocalPolicy", "segment_team", "team_policy"]


def segment_team(env: Any) -> SegmentsEnv | None:
    """The :class:`SegmentsEnv` inside ``env`` (a gym env, wrapper or DummyVecEnv), or None."""
    try:
        inner = _unwrap_one(env)
    except PolicyEnvMismatch:
        return None
    return inner if isinstance(inner, SegmentsEnv) else None


def _batched(observation: Any) -> tuple[np.ndarray, bool]:
    obs = np.asarray(observation)
    single = obs.ndim == 2
    return (obs[None] if single else obs), single


class SharedLocalPolicy:
    """One local policy applied to every agent of the team (parameter sharing).

    Args:
        local: a policy with SB3's ``predict`` on single-agent observations (n, obs_dim) that
            returns actions (n, 1), e.g. a :class:`~soft_snake_gym.agents.TrainedPolicy`.
        name: shown by ``repr``.
    """

    last_error = None  # a learned policy has no reference to track

    def __init__(self, local: Any, name: str = "shared") -> None:
        """Wrap ``local`` (arguments in the class docstring)."""
        self.local = local
        self.name = name

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """Actions (n_envs, N-2) for team observations (n_envs, N-2, obs_dim); ``state`` passes through."""
        obs, single = _batched(observation)
        n, k, d = obs.shape
        actions, _ = self.local.predict(obs.reshape(n * k, d), None, None, deterministic)
        actions = np.asarray(actions, dtype=np.float32).reshape(n, k)
        return (actions[0] if single else actions), state

    def __repr__(self) -> str:
        """``SharedLocalPolicy(name)``."""
        return f"SharedLocalPolicy({self.name})"


class _TeamBaseline:
    """A ``SoftEel-v0`` baseline built on the team's robot; subclasses say how its input is read."""

    def __init__(self, base: Any, team: SegmentsEnv) -> None:
        self.base = base
        self.team = team
        self.params = base.params  # for evaluation's gait-rate check
        self.layout = team.layout
        self._col = {name: i for i, name in enumerate(team.layout.structure)}

    @property
    def last_error(self) -> np.ndarray | None:
        """Tracking error |desired - measured| per env and node of the last call."""
        return self.base.last_error

    def _state(self, state, episode_start, n: int) -> np.ndarray:
        size = self.base.state_size
        if state is None or np.shape(state) != (n, size):
            return self.base.initial_state(n)
        state = np.array(state, dtype=np.float64, copy=True)
        if episode_start is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1)
            if starts.size == n:
                state[starts] = 0.0
        return state

    def column(self, obs: np.ndarray, name: str) -> np.ndarray:
        """Block ``name`` of every agent's observation, (n_envs, N-2) float64."""
        return obs[:, :, self._col[name]].astype(np.float64)

    def __repr__(self) -> str:
        """The class name around the baseline's."""
        return f"{type(self).__name__}({self.base!r})"


class CentralizedTeam(_TeamBaseline):
    """A curvature baseline of ``SoftEel-v0`` (``pid``, ``open-loop``) fed every node's own measurements."""

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """Actions (n_envs, N-2): the baseline's on the rebuilt ``SoftEel-v0`` observation."""
        obs, single = _batched(observation)
        n, k, _ = obs.shape
        swim = np.zeros((n, 3 * k + 4), dtype=obs.dtype)
        for b, name in enumerate(("kappa", "kappa_dot", "kbar")):
            swim[:, b * k : (b + 1) * k] = obs[:, :, self._col[name]]
        actions, state = self.base.predict(swim, state, episode_start, deterministic)
        return (actions[0] if single else actions), state


class DecentralizedTeam(_TeamBaseline):
    """:class:`~soft_snake_gym.policies.DecentralizedPhasePID`, each node on its own observation.

    Node j's reference phase comes from its head-ward neighbour's curvature and rate as node j
    observes them (``head_kappa``, ``head_kappa_dot``); the pacemaker closure's head-most node
    runs the clock, and every node does during the start-up. Bitwise the baseline on
    ``SoftEel-v0`` when no message is lost.
    """

    def __init__(self, base: DecentralizedPhasePID, team: SegmentsEnv) -> None:
        """Check that the team's nodes see what the closure needs."""
        super().__init__(base, team)
        lay = team.layout
        if "head_kappa" not in self._col:
            raise PolicyEnvMismatch(
                f"policy 'decentralized' needs each node to observe its head-ward neighbour, but the env "
                f"has neighbors = {lay.neighbors!r}; use neighbors='both' or 'head'"
            )
        if base.params.closure == "circulant" and lay.closure != "circulant":
            raise PolicyEnvMismatch(
                "policy 'decentralized:closure=circulant' needs the head-most node to observe node 1, but "
                f"the env has closure = {lay.closure!r}; use closure='circulant' or "
                "'decentralized:closure=pacemaker'"
            )

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """Actions (n_envs, N-2) from each node's own and head-ward neighbour's measurements."""
        obs, single = _batched(observation)
        n = obs.shape[0]
        base, p = self.base, self.base.params
        state = self._state(state, episode_start, n)
        t = state[:, 0].copy()
        kappa, kappa_dot = self.column(obs, "kappa"), self.column(obs, "kappa_dot")
        head_kappa, head_kappa_dot = self.column(obs, "head_kappa"), self.column(obs, "head_kappa_dot")
        if p.omega > 0:
            psi = estimate_phase(head_kappa, head_kappa_dot, p.omega) - base.delta
        else:
            psi = np.zeros_like(kappa) - base.delta
        if p.closure == "pacemaker":
            psi[:, -1] = base.clock_phase(t)[:, -1]
        kappa_des, kappa_dot_des = base.desired(base.start_up(psi, t))
        u = pid_law(base.gait, base.layout.dt, kappa, kappa_dot, kappa_des, kappa_dot_des, state[:, 1:])
        state[:, 0] = t + base.layout.dt
        base.last_rates, base.last_error = u, np.abs(kappa_des - kappa)
        actions = np.clip(u / base.layout.action_scale, -1.0, 1.0).astype(np.float32)
        return (actions[0] if single else actions), state


def team_policy(spec: str, env: Any, config: str | Path | None = None, load_trained: Any = None) -> Any:
    """A policy of the segment team in ``env`` from a spec.

    Args:
        spec: ``"decentralized[:...]"`` (:class:`DecentralizedTeam`), another curvature baseline
            (``"pid[:...]"``, ``"open-loop"``: :class:`CentralizedTeam`), or a trained single-agent
            model (a run folder or zip, loaded by ``load_trained``): :class:`SharedLocalPolicy`.
        env: an env holding a :class:`SegmentsEnv` (gym env, wrapper or DummyVecEnv).
        config: a baseline's parameters (a shipped policy config by name or a YAML file).
        load_trained: ``f(path, local_env)`` that loads a trained agent for one agent's spaces.

    Raises:
        ConfigError, PolicyEnvMismatch: as :func:`soft_snake_gym.agents.make_policy`.
    """
    team = segment_team(env)
    if team is None:
        raise PolicyEnvMismatch(f"{type(env).__name__} is not a SoftEelSegments-v0 env")
    name, _ = parse_policy_spec(spec)
    if name in BASELINES or load_trained is None:  # an unknown name raises, listing the baselines
        base = make_baseline(spec, team.swim, config)
        if isinstance(base, DecentralizedPhasePID):
            return DecentralizedTeam(base, team)
        return CentralizedTeam(base, team)
    return SharedLocalPolicy(load_trained(spec, _LocalSpaces(team)), name=spec)


class _LocalSpaces:
    """One agent's spaces, which a trained shared policy is checked against."""

    def __init__(self, team: SegmentsEnv) -> None:
        self.observation_space = team.agent_observation_space
        self.action_space = team.agent_action_space
