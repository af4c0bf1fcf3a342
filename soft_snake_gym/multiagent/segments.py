"""The eel as a team of segment agents: local observations and rewards over ``SoftEel-v0``'s robot.

One agent per interior node ``node_1 ... node_{N-2}`` acts on its own curvature rate. Nothing
here simulates: :class:`SegmentsEnv` owns a :class:`~soft_snake_gym.envs.SwimEnv` (the same
simulator, task kernel, reset noise, seeding, randomization and failure handling) and only
*reads* its arrays to give each agent what the thesis's decentralized controller may measure
and to split the reward into a shared and a local part. The batched SB3 adapter
(:class:`soft_snake_gym.sb3.SegmentVecEnv`) reads the stacked arrays of a
:class:`~soft_snake_gym.envs.vector.RobotBatch` with the same functions, so both give the same
numbers.

The local observation of agent ``node_j`` (``SegmentLayout.structure`` names the blocks):

| block            | size | meaning (unit)                                                         |
|------------------|------|------------------------------------------------------------------------|
| kappa            | 1    | its curvature ``2 tan(phi_j / 2)`` (-)                                 |
| kappa_dot        | 1    | its curvature rate (1/s)                                               |
| kbar             | 1    | its rest curvature (-)                                                 |
| head_kappa, head_kappa_dot | 1 + 1 | the head-ward neighbour's (node j+1), with ``neighbors`` "head" or "both" |
| tail_kappa, tail_kappa_dot | 1 + 1 | the tail-ward neighbour's (node j-1), with ``neighbors`` "tail" or "both" |
| goal_direction_body | 2 | cos, sin of (goal − heading), only with ``observe_goal=True``          |

The values are ``SoftEel-v0``'s observation entries for those nodes (float32, clipped to the
same bounds). The end nodes' missing neighbour is, with ``closure="circulant"`` (default), the
other end of the body (the ring of the thesis's circulant closure: node N-2's head-ward
neighbour is node 1), and with ``closure="open"`` zeros.

Rewards, per agent ``j`` and step, each in ``info``: ``reward_forward`` (shared) =
``forward_reward_weight`` × the centre of mass's speed toward the goal [m/s], as in
``SoftEel-v0``; ``reward_energy`` (local) = ``-energy_cost_weight |P_j|``, ``P_j = -EI/l_v
(kappa_j - kbar_j) u_j`` the power node j's actuator puts into the body at the end of the step
[W] (their sum is the end-of-step term of ``SoftEel-v0``'s actuator power); ``reward_ctrl``
(local) = ``-ctrl_cost_weight a_j^2``; ``reward_failure`` = ``-failure_cost`` for every agent on
a failure. The team reward of :class:`SegmentsEnv` is the shared term plus the sum of the local
ones.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.spaces import Box

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.swim import SwimEnv
from soft_snake_gym.params import Rod, check_int
from soft_snake_gym.physics import layout as L

__all__ = [
    "CLOSURES",
    "NEIGHBORS",
    "SEGMENT_KEYS",
    "SegmentLayout",
    "SegmentsEnv",
    "agent_ids",
    "local_power",
    "node_index",
    "split_kwargs",
]

NEIGHBORS = ("both", "head", "tail", "none")
"""Values of ``neighbors``: which neighbours' curvature and rate a node observes."""
CLOSURES = ("circulant", "open")
"""Values of ``closure``: what the end nodes see in place of their missing neighbour."""
SEGMENT_KEYS = ("N", "neighbors", "closure", "observe_goal")
"""The keywords of the segment envs on top of ``SoftEel-v0``'s."""

_N_NEIGHBORS = {"both": 2, "head": 1, "tail": 1, "none": 0}
_AGENT = re.compile(r"node_(\d+)")


def agent_ids(n_nodes: int) -> list[str]:
    """``["node_1", ..., "node_{N-2}"]``: one agent per interior node."""
    return [f"node_{j}" for j in range(1, n_nodes - 1)]


def node_index(agent: Any, n_nodes: int) -> int:
    """The interior node number ``j`` (1 … N-2) of agent id ``"node_j"``.

    Raises:
        ValueError: ``agent`` is not the id of an agent of a body of ``n_nodes`` nodes.
    """
    m = _AGENT.fullmatch(agent) if isinstance(agent, str) else None
    if m is None or not 1 <= int(m.group(1)) <= n_nodes - 2:
        raise ValueError(
            f"agent {agent!r} does not exist: a body of N = {n_nodes} nodes has the agents "
            f"node_1 ... node_{n_nodes - 2} (one per interior node)"
        )
    return int(m.group(1))


def split_kwargs(kwargs: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Split keywords into the segment env's own (:data:`SEGMENT_KEYS`) and ``SoftEel-v0``'s.

    ``N`` goes into ``rod`` (``rod={"N": N}``); ``N`` and a different ``rod.N`` together raise.
    """
    own = {k: kwargs[k] for k in SEGMENT_KEYS if k in kwargs}
    swim = {k: v for k, v in kwargs.items() if k not in SEGMENT_KEYS}
    if "N" in own:
        n = check_int("N", own.pop("N"), 3, hint="the number of nodes of the body (agents: N - 2)")
        rod = swim.get("rod")
        given = rod.get("N") if isinstance(rod, dict) else getattr(rod, "N", None)
        if given is not None and given != n:
            raise ValueError(f"N = {n} and rod.N = {given} disagree; give the body length once")
        if isinstance(rod, Rod):
            swim["rod"] = dataclasses.replace(rod, N=n)
        else:
            swim["rod"] = {**(rod or {}), "N": n}
    return own, swim


@dataclass(frozen=True)
class SegmentLayout:
    """Where each agent's local observation comes from in ``SoftEel-v0``'s observation.

    Attributes:
        n_nodes: N.
        neighbors: one of :data:`NEIGHBORS`.
        closure: one of :data:`CLOSURES`.
        observe_goal: whether each agent sees the goal direction.
        structure: block name -> size of the local observation.
        index: (N-2, obs_dim) indices into ``SoftEel-v0``'s observation vector.
        present: (N-2, obs_dim) False where the entry is a missing neighbour (``closure="open"``),
            which reads as 0.
        low, high: bounds of the local observation, (obs_dim,) float32.
    """

    n_nodes: int
    neighbors: str
    closure: str
    observe_goal: bool
    structure: dict[str, int]
    index: np.ndarray
    present: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def build(
        cls,
        n_nodes: int,
        swim_space: Box,
        neighbors: str = "both",
        closure: str = "circulant",
        observe_goal: bool = False,
    ) -> SegmentLayout:
        """The layout for a body of ``n_nodes`` nodes over ``SoftEel-v0``'s observation space."""
        if neighbors not in NEIGHBORS:
            raise ValueError(f"neighbors = {neighbors!r} is unknown; use one of {', '.join(NEIGHBORS)}")
        if closure not in CLOSURES:
            raise ValueError(f"closure = {closure!r} is unknown; use one of {', '.join(CLOSURES)}")
        if not isinstance(observe_goal, bool | np.bool_):
            raise ValueError(f"observe_goal = {observe_goal!r} must be True or False")
        n = n_nodes - 2
        cols: list[tuple[str, int, str]] = [
            ("kappa", 0, "kappa"),
            ("kappa_dot", 0, "kappa_dot"),
            ("kbar", 0, "kbar"),
        ]
        if neighbors in ("both", "head"):
            cols += [("head_kappa", 1, "kappa"), ("head_kappa_dot", 1, "kappa_dot")]
        if neighbors in ("both", "tail"):
            cols += [("tail_kappa", -1, "kappa"), ("tail_kappa_dot", -1, "kappa_dot")]
        block_start = {"kappa": 0, "kappa_dot": n, "kbar": 2 * n}
        index = np.zeros((n, len(cols) + 2 * observe_goal), dtype=np.int64)
        present = np.ones(index.shape, dtype=np.bool_)
        for c, (_, offset, block) in enumerate(cols):
            for a in range(n):
                k = a + offset
                if not 0 <= k < n:
                    present[a, c] = closure == "circulant"
                    k %= n
                index[a, c] = block_start[block] + k
        structure = {name: 1 for name, _, _ in cols}
        if observe_goal:
            index[:, -2:] = [3 * n + 2, 3 * n + 3]
            structure["goal_direction_body"] = 2
        return cls(
            n_nodes=n_nodes,
            neighbors=neighbors,
            closure=closure,
            observe_goal=bool(observe_goal),
            structure=structure,
            index=index,
            present=present,
            low=swim_space.low[index[0]].astype(np.float32),
            high=swim_space.high[index[0]].astype(np.float32),
        )

    @property
    def n_agents(self) -> int:
        """Agents, one per interior node: N-2."""
        return self.n_nodes - 2

    @property
    def obs_dim(self) -> int:
        """Size of one agent's observation."""
        return self.index.shape[1]

    def observe(self, swim_obs: np.ndarray, lost: np.ndarray | None = None) -> np.ndarray:
        """Local observations from ``SoftEel-v0`` observations.

        Args:
            swim_obs: (..., 3(N-2)+4) float32, one robot or a batch.
            lost: optional (N-2,) bool, nodes whose messages to their neighbours are lost this step
                (their curvature and rate read as 0 in the neighbours' observations, not in their
                own).

        Returns:
            (..., N-2, obs_dim) float32.
        """
        out = swim_obs[..., self.index]
        mask = self.present
        if lost is not None and lost.any():
            source = self.index % self.n_agents  # the node each entry comes from
            from_neighbor = np.zeros(mask.shape, dtype=np.bool_)
            from_neighbor[:, 3 : 3 + 2 * _N_NEIGHBORS[self.neighbors]] = True
            mask = mask & ~(from_neighbor & lost[source])
        if not mask.all():
            out = np.where(mask, out, np.float32(0.0))
        return out


def local_power(kappa: np.ndarray, kbar: np.ndarray, uk: np.ndarray, lbar: np.ndarray, EI: Any) -> np.ndarray:
    """Power each node's actuator puts into the body, ``P_j = -EI/l_v (kappa_j - kbar_j) u_j`` [W].

    The term of docs/model.md §3's actuator power at node j (rest lengths held), evaluated at the
    end of the step. Arrays (..., N-2) except ``lbar`` (..., N-1); ``EI`` [N m^2] a scalar or (..., 1).
    """
    lv = 0.5 * (lbar[..., :-1] + lbar[..., 1:])
    return -EI / lv * (kappa - kbar) * uk


def local_terms(task: T.TaskArrays, sim: Any, ok: Any) -> tuple[np.ndarray, np.ndarray]:
    """The local reward terms, ``(reward_energy, reward_ctrl)``, (..., N-2) each.

    From a robot's (or a batch's) task and simulator arrays after a step; ``ok`` (bool or (n,)) is
    False where the step failed (no energy term then, as in ``SoftEel-v0``).
    """
    n = sim.kbar.shape[-1]
    tp = task.tp
    power = local_power(task.raw[..., :n], sim.kbar, task.uk, sim.lbar, sim.prm[..., L.P_EI, None])
    energy = -tp[..., T.T_WE, None] * np.abs(power)
    energy = np.where(np.asarray(ok)[..., None], energy, 0.0)
    ctrl = -tp[..., T.T_WC, None] * task.act * task.act
    return energy, ctrl


class SegmentsEnv(gym.Env):
    r"""``SoftEelSegments-v0``: the segment team seen as one Gymnasium env (for evaluation).

    The same robot as ``SoftEel-v0``, whose keywords it takes, plus ``N`` (nodes, default 10),
    ``neighbors`` (``"both"``, ``"head"``, ``"tail"``, ``"none"``; default ``"both"``),
    ``closure`` (``"circulant"`` or ``"open"``; default ``"circulant"``) and ``observe_goal``
    (default False); see the module docstring.

    Observation: every agent's local observation, ``Box((N-2, obs_dim), float32)``, row ``j-1``
    for ``node_j``. Action: ``Box(-1, 1, (N-2,), float32)``, entry ``j-1`` the action of
    ``node_j`` (the ``SoftEel-v0`` action). Reward: the team reward (the shared forward term
    plus the sum of the agents' local terms). ``info``: ``SoftEel-v0``'s, with the local terms per
    agent as arrays ``agent_reward_energy``, ``agent_reward_ctrl`` (N-2,) and ``agent_rewards``.
    A policy for it is any SB3-style ``predict`` on these arrays: a shared local policy applied
    row by row, or a baseline through :mod:`soft_snake_gym.multiagent.policies`. The PettingZoo
    env :mod:`soft_snake_gym.multiagent.eel_segments_v0` is this env with one entry per agent.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 100}
    medium = "water"
    env_id = "SoftEelSegments-v0"

    def __init__(self, render_mode: str | None = None, config: Any = None, **kwargs: Any) -> None:
        """Build the team over a ``SoftEel-v0`` robot (keywords in the class docstring)."""
        own, swim_kwargs = split_kwargs(kwargs)
        self.swim = SwimEnv(render_mode=render_mode, config=config, **swim_kwargs)
        self.layout = SegmentLayout.build(self.swim.N, self.swim.observation_space, **own)
        self.N = self.swim.N
        self.dt = self.swim.dt
        self.sim = self.swim.sim
        self.max_curvature_rate = self.swim.max_curvature_rate
        self.metric_keys = self.swim.metric_keys
        self.render_mode = render_mode
        self.metadata = self.swim.metadata
        self.possible_agents = agent_ids(self.N)
        n, d = self.layout.n_agents, self.layout.obs_dim
        self.observation_space = Box(
            np.broadcast_to(self.layout.low, (n, d)).copy(),
            np.broadcast_to(self.layout.high, (n, d)).copy(),
            dtype=np.float32,
        )
        self.action_space = Box(-1.0, 1.0, (n,), dtype=np.float32)
        self.agent_observation_space = Box(self.layout.low, self.layout.high, dtype=np.float32)
        self.agent_action_space = Box(-1.0, 1.0, (1,), dtype=np.float32)
        self.lost_messages: np.ndarray | None = None
        """(N-2,) bool, or None: nodes whose messages the next observations lose (robustness studies)."""

    @property
    def failure(self) -> str | None:
        """Why the episode ended, or None while it runs."""
        return self.swim.failure

    def observe(self) -> np.ndarray:
        """The agents' current local observations, (N-2, obs_dim) float32 (a new array)."""
        return self.layout.observe(self.swim.task.obs, self.lost_messages)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the robot as ``SoftEel-v0`` does (same seed, same body); returns local observations."""
        super().reset(seed=seed)
        _, info = self.swim.reset(seed=seed, options=options)
        return self.observe(), info

    def step(self, action):
        """Step the robot with every agent's action; returns the team's (obs, reward, term, trunc, info)."""
        _, _, terminated, truncated, info = self.swim.step(action)
        task, sim = self.swim.task, self.swim.sim.arrays
        energy, ctrl = local_terms(task, sim, not terminated)
        rs = task.rs
        shared = rs[T.R_RF] + rs[T.R_RFAIL]
        info["agent_reward_energy"] = energy
        info["agent_reward_ctrl"] = ctrl
        info["agent_rewards"] = shared + energy + ctrl
        reward = float(shared + energy.sum() + ctrl.sum())
        return self.observe(), reward, terminated, truncated, info

    def render(self):
        """The robot's frame, as ``SoftEel-v0`` draws it."""
        return self.swim.render()

    def close(self) -> None:
        """Close the robot's renderer."""
        self.swim.close()
