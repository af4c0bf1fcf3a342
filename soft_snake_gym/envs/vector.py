"""The batched vector environment: many robots stepped by one compiled call.

``gym.make_vec("SoftEel-v0", num_envs=256)`` returns a :class:`SoftVectorEnv` (Gymnasium 1.x
picks a registered ``vector_entry_point`` when ``vectorization_mode`` is not given; pass
``vectorization_mode="sync"`` for a ``SyncVectorEnv`` of single envs instead).

Design: the robots' physics and task arrays are stacked along a leading robot axis (a
:class:`RobotBatch`: :class:`~soft_snake_gym.physics.SimArrays` and
:class:`~soft_snake_gym.envs.task.TaskArrays` with a leading axis, and one
:class:`~soft_snake_gym.physics.Simulator` per robot over views of them); each robot also has
an ordinary :class:`~soft_snake_gym.envs.SwimEnv`/:class:`~soft_snake_gym.envs.InchEnv` object
over views of those arrays. A step runs :func:`~soft_snake_gym.envs.task.batch_step`, a ``prange`` loop of
the very kernel a single env's ``step`` calls; a reset calls that robot's env object's
``reset`` (seeded noise, randomization draws), so robot ``i`` seeded ``s + i`` is bitwise the
robot of ``gym.make(env_id)`` seeded ``s + i`` under the same actions, for any thread count.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from gymnasium.spaces import Box
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numba import njit

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.base import SoftRobotEnv
from soft_snake_gym.envs.inch import InchEnv
from soft_snake_gym.envs.navigate import GoalEnv, PathEnv
from soft_snake_gym.envs.registration import EPISODE_STEPS
from soft_snake_gym.envs.settings import resolve_settings
from soft_snake_gym.envs.swim import SwimEnv
from soft_snake_gym.envs.task import TaskArrays
from soft_snake_gym.params import SimConfig, check_int
from soft_snake_gym.physics import SimArrays, Simulator, allocate_arrays, layout
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

drop_stale_cache(__file__, [layout.__file__])  # the cached step passes embed layout's indices


@njit(cache=True)
def _start_step(actions, act, stepping, out, shape, prev, prev_shape, status):
    """Before a batched step: ``actions`` into ``act``; the first stepping robot with a non-finite one (-1 if none).

    ``actions`` are float32 (a policy's) or float64, converted as they are copied (in the same
    pass as the check, instead of numpy's casting assignment before it). If no action is bad,
    records each robot's step count and Newton iterations (``out``) into ``prev`` (n, 2) and its
    rest ``shape`` into ``prev_shape`` (what a robot whose step fails reports), and sets every
    ``status`` to ``OK``. One compiled pass instead of a dozen array operations, whose calls
    cost more than the work at hundreds of robots.
    """
    n, k = act.shape
    bad = -1
    for i in range(n):
        finite = True
        for j in range(k):  # copy and check in one pass, without a branch per entry
            a = actions[i, j]
            act[i, j] = a
            finite &= math.isfinite(a)
        if not finite and stepping[i] and bad < 0:
            bad = i
    if bad >= 0:
        return bad
    m = shape.shape[1]
    for i in range(n):
        prev[i, 0] = out[i, O_NSTEPS]
        prev[i, 1] = out[i, O_NITER]
        for j in range(m):
            prev_shape[i, j] = shape[i, j]
        status[i] = OK
    return -1


@njit(cache=True)
def _finish_step(status, stepping, reward, success, on_success, elapsed, returns, max_steps):
    """After a batched step: ``(terminated, truncated, failures)`` and the episode counters moved on.

    A robot terminates on a failed step (``status``) or, with ``on_success``, on ``success``;
    each stepping robot's ``elapsed`` steps and ``returns`` grow by its step and ``reward``, and
    it is truncated at ``max_steps`` (0: no limit). ``failures`` counts the failed steps.
    """
    n = status.size
    terminated = np.zeros(n, dtype=np.bool_)
    truncated = np.zeros(n, dtype=np.bool_)
    failures = 0
    for i in range(n):
        if status[i] != OK:
            terminated[i] = True
            failures += 1
        if stepping[i]:
            if on_success and success[i] > 0.0:
                terminated[i] = True
            elapsed[i] += 1
            returns[i] += reward[i]
            truncated[i] = max_steps > 0 and elapsed[i] >= max_steps
    return terminated, truncated, failures


@njit(cache=True)
def _step_outputs(stepping, reward, terminated, truncated):
    """A step's rewards (0 for a robot not stepped), its episode ends, and whether any episode ended."""
    n = stepping.size
    rewards = np.zeros(n)
    dones = np.empty(n, dtype=np.bool_)
    for i in range(n):
        if stepping[i]:
            rewards[i] = reward[i]
        dones[i] = terminated[i] or truncated[i]
    return rewards, dones, dones.any()


@njit(cache=True)
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


@njit(cache=True)
def _info_rows(rs, out, shape, prev, prev_shape, status, stepped, reset, h):
    """The arrays a batched ``info`` is made of, in one compiled pass (see :func:`_start_step`).

    ``rows`` (the task state ``rs`` transposed: row k over robots), ``terms`` (``rows`` with the
    reward terms and metrics, rows ``R_FWD`` on, zero where a robot did not step; ``rows`` itself
    if all stepped), the simulated ``time`` [s], Newton iterations and rest ``shape`` (those of
    the last valid state where a stepped robot ``failed``), ``failed``, the energy ledger
    (N_LEDGER, n), zero where a robot did not step, and whether any robot ``stepped``, all of them
    were ``stepped`` or ``reset``, any was ``reset``, and how many ``failed``.
    """
    n, k = rs.shape
    m = shape.shape[1]
    time_s = np.empty(n)
    niter = np.empty(n, dtype=np.int64)
    shape_out = np.empty_like(shape)
    failed = np.zeros(n, dtype=np.bool_)
    all_stepped = all_present = True
    any_stepped = any_reset = False
    n_failed = 0
    for i in range(n):
        all_stepped &= stepped[i]
        any_stepped |= stepped[i]
        all_present &= stepped[i] or reset[i]
        any_reset |= reset[i]
        failed[i] = stepped[i] and status[i] != OK
        n_failed += failed[i]
        if failed[i]:
            steps, it, src = prev[i, 0], prev[i, 1], prev_shape
        else:
            steps, it, src = out[i, O_NSTEPS], out[i, O_NITER], shape
        time_s[i] = steps * h[i]
        niter[i] = int(it)
        for j in range(m):
            shape_out[i, j] = src[i, j]
    rows = np.empty((k, n))
    for r in range(k):  # row by row: the writes run along a row (2 KB apart robot by robot)
        for i in range(n):
            rows[r, i] = rs[i, r]
    terms = rows
    if not all_stepped:  # written in one pass, not copied and then zeroed robot by robot
        terms = np.empty((k, n))
        for r in range(k):
            for i in range(n):
                terms[r, i] = rows[r, i] if r < T.R_FWD or stepped[i] else 0.0
    ledger = np.empty((N_LEDGER, n))
    for r in range(N_LEDGER):
        for i in range(n):
            ledger[r, i] = out[i, O_LEDGER + r] if stepped[i] else 0.0
    flags = (any_stepped, all_present, any_reset, n_failed)
    return rows, terms, time_s, niter, shape_out, failed, ledger, flags


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
        self._state_of, self._rest_of = proto.batch_info()
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
        return self.obs.copy(), self.infos(np.zeros(self.num_envs, dtype=np.bool_), self._all, randomized)

    def step(self, actions):
        """Step every robot (in ``NEXT_STEP`` mode, reset those whose episode ended last step)."""
        if self._needs_reset:
            raise RuntimeError(f"{self.env_id} vector env: call reset() before step()")
        n = self.num_envs
        none = np.zeros(n, dtype=np.bool_)
        same_step = self.autoreset_mode is AutoresetMode.SAME_STEP
        resetting = none if same_step else self._autoreset
        stepping = ~resetting
        terminated, truncated = self.advance(actions, stepping)
        rewards, dones, any_done = _step_outputs(stepping, self.rewards, terminated, truncated)
        stats = self.episode_stats(dones) if any_done else None
        infos: dict[str, Any] = {}
        if same_step and any_done:
            final_obs = np.full(n, None, dtype=object)
            for i in np.flatnonzero(dones):
                final_obs[i] = self.obs[i].copy()
            infos["final_obs"], infos["_final_obs"] = final_obs, dones.copy()
            infos["final_info"], infos["_final_info"] = self.infos(dones, none, []), dones.copy()
            resetting, stepping = dones, ~dones
        randomized = [self.reset_robot(i) for i in np.flatnonzero(resetting)]
        infos.update(self.infos(stepping, resetting, randomized))
        if stats is not None:
            infos["episode"], infos["_episode"] = stats, dones.copy()
        self._autoreset = none if same_step else dones
        return self.obs.copy(), rewards, terminated, truncated, infos

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
        act = self.batch.task.act
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
        bad = _start_step(
            actions,
            act,
            stepping,
            self.batch.sim.out,
            self._shape,
            self._prev,
            self._prev_shape,
            self._status,
        )
        if bad >= 0:
            bad = np.flatnonzero(stepping & ~np.isfinite(act).all(axis=1)).tolist()
            raise ValueError(
                f"{self.env_id} vector env actions have non-finite entries for robots {bad[:8]}; "
                "every entry must be a finite number in [-1, 1]"
            )
        status = self._status
        start = time.perf_counter()
        if self.num_threads == 1:
            T.batch_step_serial(stepping, tuple(self.batch.sim), tuple(self.batch.task), status)
        else:
            numba.set_num_threads(self.num_threads)
            T.batch_step(stepping, tuple(self.batch.sim), tuple(self.batch.task), status, self.num_threads)
        self.kernel_seconds += time.perf_counter() - start
        rs = self.batch.task.rs
        terminated, truncated, failed = _finish_step(
            status,
            stepping,
            rs[:, T.R_REWARD],
            rs[:, T.R_SUCCESS],
            self._proto.terminate_on_success,
            self._elapsed,
            self._returns,
            self.max_episode_steps or 0,
        )
        if failed:
            for i in np.flatnonzero(status != OK):
                self.envs[i].fail(STATUS_REASONS[status[i]])
        return terminated, truncated

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
        self._autoreset[:] = False
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
        rows, terms, time_s, niter, shape, failed, ledger, flags = _info_rows(
            self.batch.task.rs,
            self.batch.sim.out,
            self._shape,
            self._prev,
            self._prev_shape,
            self._status,
            stepped,
            reset,
            self.batch.sim.prm[:, P_H],
        )  # a robot whose step failed reports its last valid state, as the single env does
        any_stepped, all_present, any_reset, n_failed = flags
        if not (any_stepped or any_reset):
            return {}
        # one mask array per group of keys (read-only by convention)
        mask = self._all.copy() if all_present else stepped | reset
        shape = self._proto._shape_info(self.batch.task.raw, shape)
        if not all_present:
            hidden = ~mask
            rows[:, hidden] = 0
            for value in (time_s, niter, *shape.values()):
                value[hidden] = 0
        failure = np.empty(n, dtype=object)  # None throughout
        if n_failed:
            for i in np.flatnonzero(failed):
                failure[i] = STATUS_REASONS[self._status[i]]
        infos = self._state_of(rows, time_s, shape, niter, failure, mask)
        if any_stepped:
            infos.update(self._rest_of(terms, ledger, stepped.copy()))
        if any_reset:
            drawn: dict[str, Any] = {}
            for i, draws in zip(np.flatnonzero(reset), randomized, strict=True):
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
