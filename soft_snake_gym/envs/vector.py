"""The batched vector environment: many robots stepped by one compiled call.

``gym.make_vec("SoftEel-v0", num_envs=256)`` returns a :class:`SoftVectorEnv` (Gymnasium 1.x
picks a registered ``vector_entry_point`` when ``vectorization_mode`` is not given; pass
``vectorization_mode="sync"`` for a ``SyncVectorEnv`` of single envs instead).

Design: the robots' physics and task arrays are stacked along a leading robot axis (a
:class:`RobotBatch`: :class:`~soft_snake_gym.physics.SimArrays` and
:class:`~soft_snake_gym.envs.task.TaskArrays` with a leading axis, and one
:class:`~soft_snake_gym.physics.Simulator` per robot over views of them); each robot also has
an ordinary :class:`~soft_snake_gym.envs.SwimEnv`/:class:`~soft_snake_gym.envs.InchEnv` object
over views of those arrays. A step is one compiled call, a ``prange`` loop over numba's threads
(:func:`_step`): each thread takes its robots' actions, steps them with the very kernel a single
env's ``step`` calls (``task.step_units``), moves their episodes on and writes what the step
returns of them into a :class:`Snapshot`, so that the calling thread reads none of the robots'
rows (a row it reads is one the stepping thread must fetch back). A reset calls that robot's env
object's ``reset`` (seeded noise, randomization draws), so robot ``i`` seeded ``s + i`` is
bitwise the robot of ``gym.make(env_id)`` seeded ``s + i`` under the same actions, for any
thread count.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numba
import numpy as np
from gymnasium.spaces import Box
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numba import njit, prange

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.base import SoftRobotEnv
from soft_snake_gym.envs.inch import InchEnv
from soft_snake_gym.envs.navigate import GoalEnv, PathEnv
from soft_snake_gym.envs.registration import EPISODE_STEPS
from soft_snake_gym.envs.settings import resolve_settings
from soft_snake_gym.envs.swim import SwimEnv
from soft_snake_gym.envs.task import TaskArrays
from soft_snake_gym.params import SimConfig, check_int
from soft_snake_gym.physics import SimArrays, Simulator, allocate_arrays
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.layout import (
    N_LEDGER,
    O_LEDGER,
    O_NITER,
    O_NSTEPS,
    OK,
    P_H,
    STATUS_REASONS,
)

__all__ = [
    "RobotBatch",
    "SoftVectorEnv",
    "SwimVectorEnv",
    "InchVectorEnv",
    "GoalVectorEnv",
    "PathVectorEnv",
    "ENV_CLASSES",
]

ENV_CLASSES: dict[str, type[SoftRobotEnv]] = {
    "SoftEel-v0": SwimEnv,
    "SoftWorm-v0": InchEnv,
    "SoftEelGoal-v0": GoalEnv,
    "SoftEelPath-v0": PathEnv,
}

_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))
"""The action dtypes the step copies as they are (others are converted to float64 first)."""

ROBOTS_PER_THREAD = 64
"""Default threads: one per this many robots, at most ``NUMBA_NUM_THREADS``."""

drop_stale_cache(__file__, [T.__file__, *T.KERNEL_SOURCES])  # the cached step embeds the task's kernels


@njit(cache=True, error_model="numpy", _nrt=False)
def _bad_action(actions, stepping):
    """The first stepping robot with a non-finite action, -1 if none (``actions`` alone is read)."""
    n, k = actions.shape
    for i in range(n):
        finite = True
        for j in range(k):  # without a branch per entry
            finite &= math.isfinite(actions[i, j])
        if not finite and stepping[i]:
            return i
    return -1


class Snapshot(NamedTuple):
    """What a batched step's ``info`` and observation are made of, robot by robot, in arrays of their own.

    The threads that step the robots write them, each for its own robots, while the robots'
    rows are in its caches: a row the calling thread reads is one the stepping thread must
    fetch back before its next write (256 robots on two threads step 1.06 times faster so:
    docs/performance_history.md, "The robots' rows stay with their thread"). The robots that
    start again in a step are reset before it and taken with the others; :meth:`SoftVectorEnv.reset`
    and ``SAME_STEP``'s resets, which come after a step, take theirs again.

    Attributes:
        rows: the task state ``rs`` transposed, (N_RS, n).
        time: simulated time [s], (n,).
        niter: Newton iterations of the last step, (n,).
        shape: the driven rest shape, (n, N-2) or (n, N-1).
        failed: the robot stepped and its step failed (it reports its last valid state), (n,).
        ledger: the energy ledger, (N_LEDGER, n).
        obs: the observation, (n, n_obs) float32.
        raw: the leading columns of the observation unclipped that the info reads, (n, n_raw).
    """

    rows: np.ndarray
    time: np.ndarray
    niter: np.ndarray
    shape: np.ndarray
    failed: np.ndarray
    ledger: np.ndarray
    obs: np.ndarray
    raw: np.ndarray


@njit(cache=True, error_model="numpy", _nrt=False)
def _snapshot(rs, out, shape, prev, prev_shape, status, stepped, h, obs, raw, lo, hi, snap):
    """Robots ``lo`` .. ``hi - 1`` into ``snap`` (a :class:`Snapshot`'s arrays).

    A robot that ``stepped`` and whose ``status`` is not ``OK`` reports its last valid state,
    as the single env does: the step count and iterations ``prev`` (n, 2) and the rest shape
    ``prev_shape`` recorded before its step. ``h``: each robot's step [s]. A robot that did not
    step has +0 in the step's rows (``R_FWD`` on: the reward terms and metrics) and in the ledger,
    as its ``info`` gives them (:func:`_info_rows`).
    """
    rows, time_s, niter, shape_out, failed, ledger, obs_out, raw_out = snap
    for i in range(lo, hi):
        failed[i] = stepped[i] and status[i] != OK
        if failed[i]:
            steps, it, src = prev[i, 0], prev[i, 1], prev_shape
        else:
            steps, it, src = out[i, O_NSTEPS], out[i, O_NITER], shape
        time_s[i] = steps * h[i]
        niter[i] = int(it)
        for j in range(shape.shape[1]):
            shape_out[i, j] = src[i, j]
        for j in range(obs.shape[1]):
            obs_out[i, j] = obs[i, j]
        for j in range(raw_out.shape[1]):
            raw_out[i, j] = raw[i, j]
    for r in range(rs.shape[1]):  # row by row: the writes run along a row (2 KB apart robot by robot)
        for i in range(lo, hi):
            rows[r, i] = rs[i, r] if r < T.R_FWD or stepped[i] else 0.0
    for r in range(N_LEDGER):
        for i in range(lo, hi):
            ledger[r, i] = out[i, O_LEDGER + r] if stepped[i] else 0.0


@njit(cache=True, error_model="numpy")
def _step_part(actions, stepping, max_steps, s, t, status, shape, book, ends, rewards, snap, first, end):
    """Units ``first`` .. ``end - 1`` of a batched step (``task.units``), on the thread that owns their robots.

    Before the physics (``task.step_units``), each robot's action is copied into ``act``
    (float32 converted as it is copied) and its step count, iterations and rest shape recorded
    in ``prev`` and ``prev_shape``, its ``status`` set to ``OK``. After it, each robot's episode
    moves on (``book``'s counters; :func:`_finish`) and its :class:`Snapshot` is taken.
    """
    prev, prev_shape, elapsed, returns, on_success = book
    sa, ta = SimArrays(*s), TaskArrays(*t)
    act, out = ta.act, sa.out
    n = status.size
    lo, hi = T.first_robot(first, n), T.first_robot(end, n)
    for i in range(lo, hi):
        for j in range(act.shape[1]):
            act[i, j] = actions[i, j]
        prev[i, 0] = out[i, O_NSTEPS]
        prev[i, 1] = out[i, O_NITER]
        for j in range(shape.shape[1]):
            prev_shape[i, j] = shape[i, j]
        status[i] = OK
    T.step_units(stepping, s, t, status, first, end)
    _finish(status, stepping, ta.rs, on_success, elapsed, returns, max_steps, ends, rewards, lo, hi)
    h = sa.prm[:, P_H]
    _snapshot(ta.rs, out, shape, prev, prev_shape, status, stepping, h, ta.obs, ta.raw, lo, hi, snap)


@njit(cache=True, error_model="numpy", _nrt=False)
def _finish(status, stepping, rs, on_success, elapsed, returns, max_steps, ends, rewards, lo, hi):
    """Robots ``lo`` .. ``hi - 1`` after their step: ``ends`` (3, n) terminated, truncated, done; ``rewards``.

    A robot terminates on a failed step or, with ``on_success``, on success; each stepping
    robot's ``elapsed`` steps and ``returns`` grow by its step and reward (0 for a robot not
    stepped), and it is truncated at ``max_steps`` (0: no limit).
    """
    for i in range(lo, hi):
        terminated = status[i] != OK
        truncated = False
        reward = 0.0
        if stepping[i]:
            reward = rs[i, T.R_REWARD]
            if on_success and rs[i, T.R_SUCCESS] > 0.0:
                terminated = True
            elapsed[i] += 1
            returns[i] += reward
            truncated = max_steps > 0 and elapsed[i] >= max_steps
        ends[0, i], ends[1, i], ends[2, i] = terminated, truncated, terminated or truncated
        rewards[i] = reward


@njit(cache=True, error_model="numpy")
def _new_snapshot(t, shape, n_raw):
    """New arrays for a :class:`Snapshot` of the robots of task arrays ``t`` (the infos hold them: new each step)."""
    ta = TaskArrays(*t)
    n, k = ta.rs.shape
    snap = (np.empty((k, n)), np.empty(n), np.empty(n, dtype=np.int64), np.empty_like(shape),
            np.empty(n, dtype=np.bool_), np.empty((N_LEDGER, n)), np.empty_like(ta.obs), np.empty((n, n_raw)))  # fmt: skip
    return snap, np.empty((3, n), dtype=np.bool_), np.empty(n)


@njit(cache=True, parallel=True, error_model="numpy")
def _step(actions, stepping, max_steps, s, t, status, shape, book, n_raw, threads):
    """A batched step over ``threads`` of numba's threads, each taking one run of units (:func:`_step_part`).

    Returns the step's :class:`Snapshot` arrays, its ends (3, n) (terminated, truncated, done),
    its rewards and whether any episode ended.
    """
    snap, ends, rewards = _new_snapshot(t, shape, n_raw)
    count = T.units(status.size)
    parts = max(1, min(threads, count))
    for c in prange(parts):
        _step_part(
            actions, stepping, max_steps, s, t, status, shape, book, ends, rewards, snap, c * count // parts,
            (c + 1) * count // parts,
        )  # fmt: skip
    return snap, ends, rewards, ends[2].any()


@njit(cache=True, error_model="numpy")
def _step_serial(actions, stepping, max_steps, s, t, status, shape, book, n_raw):
    """:func:`_step` on the calling thread alone (no thread-pool launch: for one thread)."""
    snap, ends, rewards = _new_snapshot(t, shape, n_raw)
    _step_part(
        actions, stepping, max_steps, s, t, status, shape, book, ends, rewards, snap, 0, T.units(status.size)
    )
    return snap, ends, rewards, ends[2].any()


@njit(cache=True, error_model="numpy")
def _episode_stats(dones, returns, elapsed, starts, now):
    """Return, length and wall-clock seconds (to the microsecond) of the episodes that end, 0 elsewhere."""
    n = dones.size
    r = np.zeros(n)
    l = np.zeros(n, dtype=np.int64)
    t = np.zeros(n)
    for i in range(n):
        if dones[i]:
            r[i], l[i], t[i] = returns[i], elapsed[i], np.round(now - starts[i], 6)
    return r, l, t


@njit(cache=True, error_model="numpy")
def _info_rows(rows, failed, ledger, stepped, reset):
    """What a batched ``info`` makes of a :class:`Snapshot` for robots that ``stepped`` and were ``reset``.

    ``terms`` (``rows`` with the reward terms and metrics, rows ``R_FWD`` on, +0 where a robot
    did not step), the ledger +0 where a robot did not step, and whether any robot ``stepped``,
    all of them were ``stepped`` or ``reset``, any was ``reset``, and how many ``failed``.
    ``terms`` and the ledger are the snapshot's own arrays where they hold +0 there already: as
    :func:`_snapshot` leaves them for the robots it did not step, all but ``SAME_STEP``'s
    ``final_info``.
    """
    k, n = rows.shape
    all_stepped = all_present = True
    any_stepped = any_reset = False
    n_failed = 0
    for i in range(n):
        all_stepped &= stepped[i]
        any_stepped |= stepped[i]
        all_present &= stepped[i] or reset[i]
        any_reset |= reset[i]
        n_failed += failed[i]
    terms, step_ledger = rows, ledger
    if not all_stepped and not _zero_where_not(rows, ledger, stepped):  # in one pass, not copied then zeroed
        terms = np.empty((k, n))
        for r in range(k):
            for i in range(n):
                terms[r, i] = rows[r, i] if r < T.R_FWD or stepped[i] else 0.0
        step_ledger = np.empty_like(ledger)
        for r in range(N_LEDGER):
            for i in range(n):
                step_ledger[r, i] = ledger[r, i] if stepped[i] else 0.0
    return terms, step_ledger, (any_stepped, all_present, any_reset, n_failed)


@njit(cache=True, inline="always", error_model="numpy")
def _zero_where_not(rows, ledger, stepped):
    """True if the step's rows (``R_FWD`` on) and the ledger hold +0 (not -0) for every robot not ``stepped``."""
    for i in range(stepped.size):
        if stepped[i]:
            continue
        for r in range(T.R_FWD, rows.shape[0]):
            if rows[r, i] != 0.0 or math.copysign(1.0, rows[r, i]) < 0.0:
                return False
        for r in range(N_LEDGER):
            if ledger[r, i] != 0.0 or math.copysign(1.0, ledger[r, i]) < 0.0:
                return False
    return True


@dataclass(frozen=True)
class RobotBatch:
    """The arrays of ``n`` robots stacked on a leading axis, as the batched step takes them.

    Attributes:
        sim: the simulators' arrays, :class:`~soft_snake_gym.physics.SimArrays` of shapes
            (n, 2N), (n, 2N), (n, N-2), (n, N-1), ... .
        task: the task's arrays, :class:`~soft_snake_gym.envs.task.TaskArrays` of shapes (n, ...).
        sims: robot ``i`` as a :class:`~soft_snake_gym.physics.Simulator` over ``sim.row(i)``.
    """

    sim: SimArrays
    task: TaskArrays
    sims: tuple[Simulator, ...]

    @property
    def time(self) -> np.ndarray:
        """Simulated time of each robot, as :attr:`Simulator.time`, (n,) [s]."""
        return self.sim.out[:, O_NSTEPS] * self.sim.prm[:, P_H]


class SoftVectorEnv(VectorEnv):
    r"""``num_envs`` soft robots of one id, stepped together by one compiled call.

    A Gymnasium 1.x ``VectorEnv``: batched ``Box`` spaces, ``reset(seed=...)``, ``step`` with
    autoreset, and infos as a dict of arrays with ``_key`` masks, as ``SyncVectorEnv`` over
    ``gym.make(env_id)`` would give them (the single env's info keys, its ``metrics``, and
    ``episode`` = {r, l, t} on the step an episode ends, as ``RecordEpisodeStatistics``).

    Autoreset: ``NEXT_STEP`` (Gymnasium's default) returns the last observation of an episode
    on the step that ends it and resets the robot on the following ``step``, ignoring that
    step's action for it (reward 0, the reset's info). ``SAME_STEP`` resets at once and puts
    the last observation in ``info["final_obs"]`` and its info in ``info["final_info"]``
    (what SB3's ``VecEnv`` convention needs; :class:`soft_snake_gym.sb3.SoftVecEnv` uses it).

    Seeding: ``reset(seed=s)`` seeds robot ``i`` with ``s + i`` (a list gives one seed per
    robot), as ``SyncVectorEnv`` does; later autoresets continue each robot's own generator.

    Args:
        env_id: a key of :data:`ENV_CLASSES` (``"SoftEel-v0"``, ``"SoftWorm-v0"``,
            ``"SoftEelGoal-v0"``, ``"SoftEelPath-v0"``).
        num_envs: number of robots (>= 1).
        max_episode_steps: truncate an episode after this many steps, as ``TimeLimit`` does
            for ``gym.make`` (default ``"registered"``: the id's registered limit, 1000 steps, 3000
            for the navigation tasks); ``None``: never. An episode that succeeds at its task
            (a target reached) is terminated, as the single env's is.
        num_threads: numba threads for the batched step (default: one per 64 robots, at most
            ``NUMBA_NUM_THREADS``; 1 runs on the calling thread). Robots are independent, so
            results do not depend on it. Threads help only on otherwise idle cores: on busy cores
            (or next to torch's own threads) one thread is often faster.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``AutoresetMode.SAME_STEP``.
        render_mode: only ``None``; render a single env to watch a robot.
        config: a YAML file of env keywords, as for the single env.
        **kwargs: the single env's keywords (``preset``, ``rod``, ``fluid``, ``randomize``,
            ``start_on_gait``...), the same for every robot (physics randomization draws differ
            per robot).
    """

    env_id = ""

    def __init__(
        self,
        env_id: str | None = None,
        num_envs: int = 1,
        *,
        max_episode_steps: int | str | None = "registered",
        num_threads: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        config: Any = None,
        **kwargs: Any,
    ) -> None:
        """Build ``num_envs`` robots of ``env_id`` (arguments in the class docstring)."""
        env_id = env_id or self.env_id
        if env_id not in ENV_CLASSES:
            raise ValueError(f"env_id = {env_id!r} has no batched version; use one of {list(ENV_CLASSES)}")
        self.env_id = env_id
        env_cls = ENV_CLASSES[env_id]
        n = check_int("num_envs", num_envs, 1, hint="the number of robots")
        if max_episode_steps == "registered":
            max_episode_steps = EPISODE_STEPS[env_id]
        if max_episode_steps is not None:
            max_episode_steps = check_int(
                "max_episode_steps", max_episode_steps, 1, hint="or None for no time limit"
            )
        max_threads = numba.config.NUMBA_NUM_THREADS
        if num_threads is not None:
            num_threads = check_int(
                "num_threads",
                num_threads,
                1,
                max_threads,
                hint=f"NUMBA_NUM_THREADS = {max_threads}; or None for the default",
            )
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(
                f"autoreset_mode = {autoreset_mode!r} is not supported; use AutoresetMode.NEXT_STEP "
                "or AutoresetMode.SAME_STEP"
            )
        if render_mode is not None:
            raise ValueError(
                f"render_mode = {render_mode!r}: the batched env does not render; render a single "
                f'env, gym.make("{env_id}", render_mode="rgb_array")'
            )
        settings = resolve_settings(env_cls.settings_class, env_cls.medium, config, kwargs, env_id)

        self.num_envs = n
        self.max_episode_steps = max_episode_steps
        self.autoreset_mode = mode
        self.render_mode = None
        base_config = SimConfig(
            rod=settings.rod,
            medium=env_cls.medium,
            fluid=settings.fluid,
            ground=settings.ground,
            integrator=settings.integrator,
        )
        if num_threads is None:  # a thread pays for its wake-up only with enough robots to share
            num_threads = min(max_threads, max(1, n // ROBOTS_PER_THREAD))
        self.num_threads = int(num_threads)
        sim_arrays = allocate_arrays(base_config.rod.N, (n,))
        sims = tuple(Simulator(base_config, arrays=sim_arrays.row(i)) for i in range(n))
        proto = env_cls.over_arrays(settings, sims[0], None)
        n_act, n_obs = proto.action_space.shape[0], proto.observation_space.shape[0]
        task = T.allocate_task(proto.N, n_act, n_obs, (n,), n_path=proto.n_path)
        self.batch = RobotBatch(sim=sim_arrays, task=task, sims=sims)
        """The robots' stacked arrays (:class:`RobotBatch`); read-only for users."""
        self.envs: list[SoftRobotEnv] = [
            env_cls.over_arrays(settings, sim, self.batch.task.row(i)) for i, sim in enumerate(sims)
        ]
        self.settings = settings
        self.N = proto.N
        self.dt = proto.dt
        self.observation_structure = proto.observation_structure
        self.single_observation_space: Box = proto.observation_space
        self.single_action_space: Box = proto.action_space
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)
        self.metadata = {
            "autoreset_mode": mode,
            "render_modes": [],
            "render_fps": proto.metadata["render_fps"],
        }
        self.metric_keys = proto.metric_keys
        """Names of the running episode metrics in ``info["metrics"]``."""
        self._proto = proto  # builds the infos, as each robot's env does
        self._shape_of, self._state_of, self._rest_of = proto.batch_info()
        self._act_shape = (n, n_act)
        self._shape = getattr(self.batch.sim, proto.shape_key)  # the driven rest shape, (n, N-2) or (n, N-1)
        self._status = np.zeros(n, dtype=np.int64)
        # each robot's step count and Newton iterations, and its rest shape, before the last step:
        # the state a robot whose step failed reports (as the single env does)
        self._prev = np.zeros((n, 2))
        self._prev_shape = np.zeros_like(self._shape)
        self._autoreset = np.zeros(n, dtype=np.bool_)
        self._all = np.ones(n, dtype=np.bool_)
        self._elapsed = np.zeros(n, dtype=np.int64)
        self._returns = np.zeros(n)
        self._starts = np.zeros(n)
        self._none = np.zeros(n, dtype=np.bool_)
        # the leading columns of the unclipped observation that the info's body entries read
        probe = np.arange(n_obs, dtype=np.float64)[None, :]
        views = proto._shape_views(probe, self._shape[:1])
        self._n_raw = max((int(v.max()) + 1 for v in views.values() if np.shares_memory(v, probe)), default=0)
        self._snap: Snapshot | None = None  # the last step's, or the last reset's
        book = (self._prev, self._prev_shape, self._elapsed, self._returns, proto.terminate_on_success)
        self._step_args = (
            tuple(self.batch.sim),
            tuple(self.batch.task),
            self._status,
            self._shape,
            book,
            self._n_raw,
        )
        self._rewards = np.zeros(n)  # the last step's rewards (0 for a robot not stepped)
        self._dones = np.zeros(n, dtype=np.bool_)
        self._any_done = False  # whether any episode ended in the last step
        self._needs_reset = True
        self.kernel_seconds = 0.0
        """Wall-clock seconds spent in the compiled batched step so far (for profiling)."""

    # --- Gymnasium VectorEnv API ----------------------------------------------------------------
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset every robot; ``seed`` an int (robot ``i`` gets ``seed + i``) or one per robot."""
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(
                    f"seed has {len(seeds)} entries for {self.num_envs} robots; give one per robot or one int"
                )
        infos = self.reset_robots(seeds, [options] * self.num_envs)
        randomized = [info["randomized"] for info in infos]
        return self._snap.obs, self.infos(self._none, self._all, randomized)

    def step(self, actions):
        """Step every robot (in ``NEXT_STEP`` mode, reset those whose episode ended last step)."""
        if self._needs_reset:
            raise RuntimeError(f"{self.env_id} vector env: call reset() before step()")
        n = self.num_envs
        none = self._none
        same_step = self.autoreset_mode is AutoresetMode.SAME_STEP
        resetting = none if same_step else self._autoreset
        stepping = ~resetting
        actions = self._checked_actions(actions, stepping)
        # the robots whose episode ended last step (if any did) start again before the others
        # step, so that the step's snapshot holds their infos and observations too
        randomized = [self.reset_robot(i) for i in resetting.nonzero()[0].tolist()] if self._any_done else []
        terminated, truncated = self._run(actions, stepping)
        rewards, dones, any_done = self._rewards, self._dones, self._any_done
        stats = self.episode_stats(dones) if any_done else None
        infos: dict[str, Any] = {}
        if same_step and any_done:
            kept = Snapshot(*(a.copy() for a in self._snap))  # the resets' snapshots go into it
            final_obs = np.full(n, None, dtype=object)
            for i in np.flatnonzero(dones):
                final_obs[i] = kept.obs[i].copy()
            infos["final_obs"], infos["_final_obs"] = final_obs, dones.copy()
            infos["final_info"], infos["_final_info"] = self.infos(dones, none, []), dones.copy()
            self._snap = kept
            resetting, stepping = dones, ~dones
            resets = np.flatnonzero(resetting)
            randomized = [self.reset_robot(i) for i in resets]
            for i in resets:  # the reset robots' infos and observations: after their reset
                self._take_snapshot(i, i + 1)
        infos.update(self.infos(stepping, resetting, randomized))
        if stats is not None:
            infos["episode"], infos["_episode"] = stats, dones.copy()
        self._autoreset = none if same_step else dones
        return self._snap.obs, rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        """Close every robot's env object."""
        for env in self.envs:
            env.close()

    # --- the engine, shared with the SB3 adapter (soft_snake_gym.sb3) ---------------------------
    @property
    def obs(self) -> np.ndarray:
        """The robots' current observations, (n, n_obs) float32.

        The batch's buffer, which the next step overwrites (copy to keep).
        """
        return self.batch.task.obs

    @property
    def rewards(self) -> np.ndarray:
        """The robots' rewards of the last step, (n,): a view of the batch's buffer."""
        return self.batch.task.rs[:, T.R_REWARD]

    @property
    def needs_reset(self) -> bool:
        """True until the first reset: stepping before it raises."""
        return self._needs_reset

    def advance(self, actions, stepping: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Step the robots in ``stepping`` in one compiled call and update their episode counters.

        ``stepping`` is (n,) bool and ``actions`` (n, n_act). A robot whose step fails ends its
        episode (its env's ``failure``). Resets nobody: see :meth:`reset_robot`.

        Returns:
            (terminated, truncated), (n,) bool each, False for robots not stepped.
        """
        return self._run(self._checked_actions(actions, stepping), stepping)

    def _checked_actions(self, actions, stepping: np.ndarray) -> np.ndarray:
        """``actions`` as :meth:`_run` takes them; a ``ValueError`` that names the fault if they are not a step's."""
        if not (
            type(actions) is np.ndarray and actions.shape == self._act_shape and actions.dtype in _FLOATS
        ):
            try:
                actions = np.asarray(actions, dtype=np.float64)
            except (TypeError, ValueError) as err:
                raise ValueError(
                    f"{self.env_id} vector env actions are not an array of numbers: {err}"
                ) from None
            if actions.shape != self._act_shape:
                raise ValueError(
                    f"{self.env_id} vector env actions have shape {actions.shape}; expected "
                    f"{self._act_shape} (one row of values in [-1, 1] per robot)"
                )
        if _bad_action(actions, stepping) >= 0:
            bad = np.flatnonzero(stepping & ~np.isfinite(actions).all(axis=1)).tolist()
            raise ValueError(
                f"{self.env_id} vector env actions have non-finite entries for robots {bad[:8]}; "
                "every entry must be a finite number in [-1, 1]"
            )
        return actions

    def _run(self, actions: np.ndarray, stepping: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`advance` with ``actions`` checked: the compiled step, then the failed robots' envs told."""
        status, args = self._status, self._step_args
        max_steps = self.max_episode_steps or 0  # read each step: the attribute is public
        start = time.perf_counter()
        if self.num_threads == 1:
            snap, ends, self._rewards, self._any_done = _step_serial(actions, stepping, max_steps, *args)
        else:
            numba.set_num_threads(self.num_threads)
            snap, ends, self._rewards, self._any_done = _step(
                actions, stepping, max_steps, *args, self.num_threads
            )
        self.kernel_seconds += time.perf_counter() - start
        self._snap = Snapshot(*snap)
        if self._any_done:  # a failed step (status not OK, 0) ends its episode
            for i in status.nonzero()[0].tolist():
                self.envs[i].fail(STATUS_REASONS[status[i]])
        terminated, truncated, self._dones = ends
        return terminated, truncated

    def _take_snapshot(self, lo: int, hi: int) -> None:
        """Robots ``lo`` .. ``hi - 1``, not stepped, into the current :class:`Snapshot` (after their reset, outside a step)."""
        sim, task = self.batch.sim, self.batch.task
        _snapshot(
            task.rs,
            sim.out,
            self._shape,
            self._prev,
            self._prev_shape,
            self._status,
            self._none,
            sim.prm[:, P_H],
            task.obs,
            task.raw,
            lo,
            hi,
            tuple(self._snap),
        )

    def reset_robot(self, i: int, seed: int | None = None, options: dict[str, Any] | None = None) -> dict:
        """Start robot ``i``'s episode through its env object and its episode counters.

        The env object's ``start_episode``: its ``reset`` without the info, which the batch's
        :meth:`infos` builds. Returns the episode's ``randomized`` draws (empty without
        ``randomize``).
        """
        env = self.envs[i]
        env.start_episode(seed, options)
        self._elapsed[i] = 0
        self._returns[i] = 0.0
        self._starts[i] = time.perf_counter()
        return env.randomized

    def reset_robots(self, seeds: list[int | None], options: list[dict[str, Any] | None]) -> list[dict]:
        """Reset every robot, robot ``i`` with ``seeds[i]`` and ``options[i]``; clears pending autoresets.

        Returns the robots' reset infos, each as its single env's ``reset`` returns it.
        """
        for i in range(self.num_envs):
            self.reset_robot(i, seeds[i], options[i])
        self._snap = Snapshot(*_new_snapshot(tuple(self.batch.task), self._shape, self._n_raw)[0])
        self._take_snapshot(0, self.num_envs)
        self._autoreset[:] = False
        self._any_done = False
        self._needs_reset = False
        return [env.reset_info() for env in self.envs]

    def episode_metrics(self, i: int) -> dict[str, float]:
        """Robot ``i``'s running episode metrics, as its env's ``info["metrics"]``."""
        return T.episode_metrics(self.batch.task.rs[i].tolist(), self.metric_keys)

    def episode_stats(self, dones: np.ndarray) -> dict[str, np.ndarray]:
        """``{"r", "l", "t"}`` (return, length, wall-clock seconds) of the episodes that end.

        (n,) each, zero where ``dones`` is False (as ``RecordEpisodeStatistics``).
        """
        r, l, t = _episode_stats(dones, self._returns, self._elapsed, self._starts, time.perf_counter())
        return {"r": r, "l": l, "t": t}

    def infos(self, stepped: np.ndarray, reset: np.ndarray, randomized: list[dict]) -> dict[str, Any]:
        """Infos of robots that ``stepped`` and were ``reset``, with Gymnasium's ``_key`` masks.

        ``randomized`` holds the reset robots' draws (:meth:`reset_robot`), in robot order. As
        ``SyncVectorEnv`` would gather the single envs' (the entries are built by the same env
        methods).
        """
        n = self.num_envs
        snap = self._snap
        rows, time_s, niter, failed = snap.rows, snap.time, snap.niter, snap.failed
        terms, ledger, flags = _info_rows(rows, failed, snap.ledger, stepped, reset)
        any_stepped, all_present, any_reset, n_failed = flags
        if not (any_stepped or any_reset):
            return {}
        # one mask array per group of keys (read-only by convention)
        mask = self._all.copy() if all_present else stepped | reset
        shape = self._shape_of(snap.raw, snap.shape)  # views of the step's new arrays
        if not all_present:
            hidden = ~mask
            rows[:, hidden] = 0
            for value in (time_s, niter, *shape.values()):
                value[hidden] = 0
        failure = np.empty(n, dtype=object)  # None throughout
        if n_failed:
            for i in failed.nonzero()[0].tolist():
                failure[i] = STATUS_REASONS[self._status[i]]
        infos = self._state_of(rows, time_s, shape, niter, failure, mask)
        if any_stepped:
            infos.update(self._rest_of(terms, ledger, stepped.copy()))
        if any_reset:
            drawn: dict[str, Any] = {}
            if any(randomized):  # without randomize, every robot's draws are empty
                for i, draws in zip(reset.nonzero()[0].tolist(), randomized, strict=True):
                    for key, value in draws.items():
                        if key not in drawn:
                            drawn[key] = np.zeros(n)
                            drawn[f"_{key}"] = np.zeros(n, dtype=np.bool_)
                        drawn[key][i] = value
                        drawn[f"_{key}"][i] = True
            infos["randomized"], infos["_randomized"] = drawn, reset.copy()
        return infos


class _OneIdVectorEnv(SoftVectorEnv):
    """A :class:`SoftVectorEnv` of the class's ``env_id``, called as ``gym.make_vec`` calls an entry point."""

    def __init__(self, num_envs: int = 1, **kwargs: Any) -> None:
        """Build ``num_envs`` robots of ``env_id`` (keywords as for :class:`SoftVectorEnv`)."""
        super().__init__(self.env_id, num_envs, **kwargs)


class SwimVectorEnv(_OneIdVectorEnv):
    """:class:`SoftVectorEnv` of ``SoftEel-v0`` (its ``vector_entry_point``)."""

    env_id = "SoftEel-v0"


class InchVectorEnv(_OneIdVectorEnv):
    """:class:`SoftVectorEnv` of ``SoftWorm-v0`` (its ``vector_entry_point``)."""

    env_id = "SoftWorm-v0"


class GoalVectorEnv(_OneIdVectorEnv):
    """:class:`SoftVectorEnv` of ``SoftEelGoal-v0`` (its ``vector_entry_point``)."""

    env_id = "SoftEelGoal-v0"


class PathVectorEnv(_OneIdVectorEnv):
    """:class:`SoftVectorEnv` of ``SoftEelPath-v0`` (its ``vector_entry_point``)."""

    env_id = "SoftEelPath-v0"
