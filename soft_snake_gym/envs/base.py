"""What the soft-robot environments share: the step/reset loop, info, metrics, rendering.

The environments are a thin task layer over one :class:`~soft_snake_gym.physics.Simulator`
(built once per environment and reused by every ``reset``). A step is one compiled call,
:func:`soft_snake_gym.envs.task.robot_step` (action scaling, physics, observation, reward
terms, metrics), the same kernel the batched vector env runs over many robots; resets are
Python (seeded noise, randomization) and are shared with the vector env too, which keeps one
lightweight env object per robot over views of its stacked arrays.
"""

from __future__ import annotations

import functools
import math
import os
import sys
import warnings
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.render import BodyRenderer, require_interactive_backend
from soft_snake_gym.envs.settings import BaseSettings, resolve_settings
from soft_snake_gym.envs.task import TaskArrays
from soft_snake_gym.params import SimConfig, check_number
from soft_snake_gym.physics import Simulator
from soft_snake_gym.physics.layout import LEDGER_KEYS, O_LEDGER, O_NITER, O_NSTEPS, OK, STATUS_REASONS

__all__ = ["SoftRobotEnv"]


@functools.cache
def _compile_display(params: str, body: str) -> Callable[..., dict[str, Any]]:
    """``lambda params: {body}``, compiled once per source (as ``dataclasses`` makes its methods).

    ``info`` is built this way because a dict display with constant keys takes its values
    straight from the stack: about half the time of ``dict(zip(keys, values))`` and of building
    it in parts (docs/performance_history.md, "The single env's info as one dict display"). The source
    is made by :meth:`SoftRobotEnv._info_displays` from the layout's names and indices only.
    """
    return eval(f"lambda {params}: {{{body}}}", {})


def _entry(key: str, value: str, mask: str | None) -> str:
    """``key: value`` of a dict display; with ``mask``, Gymnasium's vector mask ``_key: mask`` after it."""
    return f"{key!r}: {value}" if mask is None else f"{key!r}: {value}, {'_' + key!r}: {mask}"


def _entries(keys: tuple[str, ...], source: str, start: int, mask: str | None = None) -> str:
    """The body of a dict display of ``keys`` over ``source[start]``, ``source[start + 1]``, ... (:func:`_entry`)."""
    return ", ".join(_entry(key, f"{source}[{start + i}]", mask) for i, key in enumerate(keys))


SLOW_SUBSTEPS = 1000
"""Explicit sub-steps per integrator step above which an env warns that it will be slow."""


def _display_available() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


# --- the environment --------------------------------------------------------------------------
class SoftRobotEnv(gym.Env):
    """Base of :class:`~soft_snake_gym.envs.SwimEnv` and :class:`~soft_snake_gym.envs.InchEnv`.

    Subclasses set ``medium``, ``settings_class``, ``env_id``, ``medium_energy_key``,
    ``medium_power_key``, ``shape_key`` and implement the hooks ``_setup_task``,
    ``_build_spaces``, ``_action_params``, ``_start_body``, ``_shape_views`` and
    ``_check_options``.

    Attributes:
        settings: the validated constructor keywords (``SwimSettings`` or ``InchSettings``).
        sim: the :class:`~soft_snake_gym.physics.Simulator` (one robot), built once and
            reused by every ``reset``; read its state (``sim.x`` (N, 2) [m], ``sim.kbar``,
            ``sim.lbar``, ``sim.time`` [s], energies) between steps, but step through the env.
        task: the task kernels' :class:`~soft_snake_gym.envs.task.TaskArrays` (action, inputs,
            observation, reward terms and metrics of the last step); read-only for users.
        base_config: the :class:`~soft_snake_gym.params.SimConfig` the env was built with
            (``randomize`` draws around it at each reset).
        N: number of nodes.
        dt: control step [s]: ``n_substeps`` integrator steps of ``integrator.h``.
        n_substeps: integrator steps per control step.
        observation_structure: block name -> size of the observation, in order (the
            Observation Space table of the env's docstring).
        goal_direction: the episode's goal direction [rad from +x].
        randomized: the physics values drawn at the last reset (empty without ``randomize``).
        total_mass: mass of the body [kg].
        metric_keys: names of the running episode metrics in ``info["metrics"]``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 100}
    medium: ClassVar[str] = "water"
    settings_class: ClassVar[type] = BaseSettings
    env_id: ClassVar[str] = ""
    medium_energy_key: ClassVar[str] = "energy_fluid"
    medium_power_key: ClassVar[str] = "fluid_power"
    shape_key: ClassVar[str] = "kbar"
    """The rest shape the actions drive (``"kbar"`` or ``"lbar"``), a state entry of ``info``."""
    shape_flags: ClassVar[tuple[str, ...]] = ()
    """Entries of :meth:`_shape_views` held as 0.0 or 1.0 and given in ``info`` as bool arrays."""
    trail_length: ClassVar[int] = 300
    view_lengths: ClassVar[float] = 2.0
    """Width of the rendered view, in body lengths."""
    task_kind: ClassVar[int] = T.TASK_DIRECTION
    """What the robot is asked to do (``task.TASK_DIRECTION``, ``TASK_GOAL`` or ``TASK_PATH``)."""
    terminate_on_success: ClassVar[bool] = False
    """End the episode (``terminated``) when the task succeeds (a target reached)."""

    def __init__(self, render_mode: str | None = None, config: str | Path | None = None, **kwargs: Any):
        """Build the env from a preset, a YAML ``config`` and keywords (see the env's docstring)."""
        settings = resolve_settings(self.settings_class, self.medium, config, kwargs, self.env_id)
        self._setup(settings, render_mode)
        n = self.sim.substeps
        if settings.integrator.method == "symplectic_euler" and n > SLOW_SUBSTEPS:
            warnings.warn(
                f"{self.env_id}: integrator.method = 'symplectic_euler' takes {n:,} sub-steps per "
                f"h = {settings.integrator.h:g} s for this rod (its stiffest elastic mode or its damping), so every "
                "step is slow; use 'auto' (implicit, one or two stages per h) or a softer or "
                "coarser rod",
                stacklevel=2,
            )

    @classmethod
    def over_arrays(cls, settings: BaseSettings, sim: Simulator, task: TaskArrays | None):
        """An env (no rendering) over a given simulator and task arrays, e.g.

        views of a batch's stacked arrays: how the vector env keeps one env object per robot.
        """
        env = cls.__new__(cls)
        env._setup(settings, None, sim=sim, task=task)
        return env

    def _setup(
        self,
        settings: BaseSettings,
        render_mode: str | None,
        sim: Simulator | None = None,
        task: TaskArrays | None = None,
    ) -> None:
        settings.randomize.check(self.medium, settings.ground, self.env_id or type(self).__name__)
        self.settings = s = settings
        self.base_config = SimConfig(
            rod=s.rod, medium=self.medium, fluid=s.fluid, ground=s.ground, integrator=s.integrator
        )
        if sim is None:
            sim = Simulator(self.base_config)
        else:
            sim.set_config(self.base_config)
        self.sim = sim
        self.N = self.sim.N
        h = self._h = s.integrator.h
        self.n_substeps = 1 if s.dt is None else int(round(s.dt / h))
        self.dt = h * self.n_substeps
        self.total_mass = float(self.sim.masses.sum())
        self._mass_fraction = self.sim.masses / self.total_mass  # (N,), for the centre of mass

        modes = ["rgb_array"] + (["human"] if _display_available() else [])
        self.metadata = {"render_modes": modes, "render_fps": int(round(1.0 / self.dt))}
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            if render_mode == "human":
                raise RuntimeError(
                    "render_mode='human' needs a display, and none was found (DISPLAY and "
                    "WAYLAND_DISPLAY are unset); use render_mode='rgb_array' for headless rendering"
                )
            raise ValueError(
                f"render_mode = {render_mode!r} is not supported; use None, 'rgb_array' or 'human'"
            )
        if render_mode == "human":
            require_interactive_backend()  # fail at construction, not at the first frame
        self.render_mode = render_mode
        self._renderer = None

        self.n_path = 2  # vertices of the task's path (a navigation env sets its own)
        self._setup_task()
        self._build_spaces()
        box = self.observation_space
        self._act_shape = self.action_space.shape
        if task is None:
            task = T.allocate_task(self.N, self._act_shape[0], box.shape[0], n_path=self.n_path)
        self.task = task
        self.metric_keys = tuple(k or self.medium_energy_key for k in T.METRIC_KEYS)
        self.term_keys = T.TERM_KEYS
        if self.task_kind != T.TASK_DIRECTION:
            self.metric_keys += T.NAV_METRIC_KEYS[self.task_kind]
            self.term_keys += T.NAV_TERM_KEYS
        self._bind_arrays()
        task.low[:] = box.low
        task.high[:] = box.high
        task.w[:] = self._mass_fraction
        kind, scale, lo, hi, energy = self._action_params()
        tp = task.tp
        tp[T.T_KIND], tp[T.T_SCALE], tp[T.T_LO], tp[T.T_HI], tp[T.T_ESRC] = kind, scale, lo, hi, energy
        tp[T.T_DT] = self.dt
        tp[T.T_NSUB] = self.n_substeps
        tp[T.T_WF], tp[T.T_WE] = s.forward_reward_weight, s.energy_cost_weight
        tp[T.T_WC], tp[T.T_FAIL] = s.ctrl_cost_weight, s.failure_cost
        tp[T.T_MASS] = self.total_mass
        tp[T.T_TASK] = self.task_kind
        self._set_goal(s.goal_direction)
        self._failure: str | None = None
        self._needs_reset = True
        self._trail_com: deque = deque(maxlen=self.trail_length)
        self._trail_head: deque = deque(maxlen=self.trail_length)
        self.randomized: dict[str, float] = {}

    def _bind_arrays(self) -> None:
        """Name what ``step`` passes to the compiled step and reads back, and compile its ``info``.

        Built once, and again on unpickling (neither views nor compiled displays pickle).
        """
        a, task = self.sim.arrays, self.task
        self._kernel_args = (a.f, a.ibuf, task.f, task.obs, task.act.shape[-1], task.path.shape[-2])
        self._out, self._shape = a.out, getattr(a, self.shape_key)
        views = self._shape_views(task.raw, self._shape)
        self._own_views = tuple(views.values())  # this robot's, sliced once: a slice costs 0.1 µs
        self._copy_shape = _compile_display(
            "v",
            ", ".join(
                f"{key!r}: v[{i}].astype(bool)" if key in self.shape_flags else f"{key!r}: v[{i}].copy()"
                for i, key in enumerate(views)
            ),
        )
        self._shape_keys = tuple(views)
        state, rest = self._info_displays()
        self._rest_of = _compile_display("r, out, failure", rest)
        # this robot's: the time and the iterations straight from ``out`` (one call less a step)
        own, _ = self._info_displays(time=f"out[{O_NSTEPS}] * h", niter=f"int(out[{O_NITER}])")
        self._own_state_of = _compile_display("r, out, shape, h", own)
        self._info_of = _compile_display("out, failure, r, shape, h", f"{own}, {rest}")

    # --- hooks ------------------------------------------------------------------------------
    def _setup_task(self) -> None:
        """Read the subclass's own settings (before the spaces are built)."""

    def _build_spaces(self) -> None:
        raise NotImplementedError

    def _action_params(self) -> tuple[int, float, float, float, int]:
        """How the action becomes inputs and what the energy cost charges.

        (``task.SWIM`` or ``task.INCH``, rate of action 1.0, lower and upper bound of the driven
        rest shape, ``task.ENERGY_ACTUATOR`` or ``task.ENERGY_MEDIUM``).
        """
        raise NotImplementedError

    def _start_body(self, rng: np.random.Generator) -> None:
        """Start ``sim`` at the episode's body when ``reset`` is given none, drawn from ``rng``.

        With ``Simulator.start`` or ``Simulator.start_near_rest``, which check nothing: the env
        builds the body right.
        """
        raise NotImplementedError

    def _shape_views(self, raw: np.ndarray, shape: np.ndarray) -> dict[str, np.ndarray]:
        """The body's entries of ``info``, as views in their order (a single env's ``info`` holds copies).

        Of the unclipped observation ``raw`` and the driven rest shape ``shape``; (n_obs,) for one
        robot or (n, n_obs) for a batch. Entries named in ``shape_flags`` are given as bool.
        """
        raise NotImplementedError

    # --- info: the one place it is built (the vector env calls these too) -------------------
    def _info_displays(
        self, time: str = "time", niter: str = "niter", masks: tuple[str, str] | None = None
    ) -> tuple[str, str]:
        """The entries of ``info`` as the bodies of two dict displays, in their order.

        The state entries over ``r`` (the task state ``rs``), ``time``, ``shape`` (the dict of
        the body's entries) and ``niter`` (or the expressions given for the time and the
        iterations); the rest over ``r``, ``out`` (the simulator's ``out``) and ``failure``: the
        reward terms, the running metrics (``task.episode_metrics``) and the energy ledger
        (``layout.energy_ledger``), from the same keys and indices. ``r`` and ``out`` are lists
        for one robot.

        With ``masks`` (the names of the state's and the step's masks), the displays of a batch's
        ``info``, as ``SyncVectorEnv`` gathers them: ``r`` the rows ``rs.T`` and ``out`` the
        ledger's rows (``N_LEDGER``, n), every entry an array over robots followed by its
        ``_key`` mask; ``failure`` closes the state, which the state's mask covers, and the rest
        (the entries of a step) takes the step's.
        """
        m, ms = masks or (None, None)
        shape = "**shape" if m is None else ", ".join(_entry(k, f"shape[{k!r}]", m) for k in self._shape_keys)
        state = ", ".join(
            (
                _entry("x_position", f"r[{T.R_COMX}]", m),
                _entry("y_position", f"r[{T.R_COMY}]", m),
                _entry("heading", f"r[{T.R_HEADING}]", m),
                _entry("time", time, m),
                _entry(self.medium_power_key, f"r[{T.R_P_MED}]", m),
                _entry("actuator_power", f"r[{T.R_P_ACT}]", m),
                shape,
                _entry("newton_iterations", niter, m),
            )
        )
        if self.task_kind != T.TASK_DIRECTION:
            nav = "target_distance" if self.task_kind == T.TASK_GOAL else "cross_track_error"
            state += (
                f", {_entry(nav, f'r[{T.R_NAV}]', m)}, {_entry('is_success', f'r[{T.R_SUCCESS}] > 0.0', m)}"
            )
        failure = _entry("failure", "failure", m)
        ledger = O_LEDGER if m is None else 0  # a batch's ledger rows start at 0
        terms = f"{_entry('forward_speed', f'r[{T.R_FWD}]', ms)}, {_entries(self.term_keys, 'r', T.R_RF, ms)}"
        groups = (
            _entry("metrics", f"{{{_entries(self.metric_keys, 'r', T.M_AVG, ms)}}}", ms),
            _entry("energy", f"{{{_entries(LEDGER_KEYS, 'out', ledger, ms)}}}", ms),
        )
        if m is None:
            return state, ", ".join((terms, failure) + groups)
        return f"{state}, {failure}", ", ".join((terms,) + groups)

    def batch_info(self) -> tuple[Callable[..., dict[str, Any]], ...]:
        """The builders of a batch's ``info`` (:meth:`_info_displays` with masks), for the vector env.

        ``shape(raw, shape)``: the body's entries of a batch's snapshot (its unclipped
        observations and driven rest shapes, arrays new each step), as views of them, the
        ``shape_flags`` as bool arrays; ``state(r, time, shape, niter, failure, m)``: the state
        entries and ``failure`` over robots, masked by ``m``, from the rows ``r = rs.T``, those body
        entries and arrays of the time, the iterations and the failures; ``rest(r, out, ms)``: the
        step's entries masked by ``ms``, from the rows of the reward terms ``r`` and of the ledger
        ``out``.
        """
        views = ", ".join(
            f"{key!r}: v[{i}].astype(bool)" if key in self.shape_flags else f"{key!r}: v[{i}]"
            for i, key in enumerate(self._shape_keys)
        )
        body = _compile_display("v", views)
        state, rest = self._info_displays(masks=("m", "ms"))
        return (
            lambda raw, shape: body(tuple(self._shape_views(raw, shape).values())),
            _compile_display("r, time, shape, niter, failure, m", state),
            _compile_display("r, out, ms", rest),
        )

    def _check_options(self, body: dict[str, np.ndarray]) -> None:
        """Reject an initial body from ``reset(options=...)`` that violates the env's bounds."""

    def _reset_task(self, rng: np.random.Generator) -> None:
        """Draw the episode's task (a target, a path) into ``task`` after the body's reset draws."""

    # --- gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode; returns ``(observation, info)``.

        Args:
            seed: seeds ``np_random`` (reset noise and ``randomize`` draws); None continues
                the current generator.
            options: ``goal_direction`` [rad] for this episode, and/or an exact initial body:
                ``x`` (N, 2) [m], ``v`` (N, 2) [m/s], ``kbar`` (N-2,) [-], ``lbar`` (N-1,) [m]
                (missing parts: at rest, straight rest shape, ``x`` built from ``kbar`` and
                ``lbar``). Unknown options raise ``ValueError``.

        Returns:
            The first observation (see the class docstring's Observation Space) and ``info``
            with the state entries, ``randomized`` (the drawn physics) and ``failure`` (None).
        """
        self.start_episode(seed, options)
        info = self.reset_info()
        if self.render_mode == "human":
            self.render()
        return self.task.obs.copy(), info

    def reset_info(self) -> dict[str, Any]:
        """The info :meth:`reset` returns, of the episode just started.

        Also records the state that ``step`` reports if the next step fails (``rs`` and ``out`` as
        lists, the body's entries).
        """
        self._last_state = state = (
            self.task.rs.tolist(),
            self._out.tolist(),
            self._copy_shape(self._own_views),
        )
        info = self._own_state_of(*state, self._h)
        info["randomized"] = dict(self.randomized)
        info["failure"] = None
        return info

    def start_episode(self, seed: int | None = None, options: dict[str, Any] | None = None) -> None:
        """:meth:`reset` without its observation and info: the body, the task and the draws.

        What the vector env's autoreset calls for a robot (a reset's info is about 3 of its 10 µs):
        it reads the observation from the batch and ``randomized`` (the drawn physics) from
        here, and never steps a robot through this object, which needs :meth:`reset_info`'s state.
        """
        super().reset(seed=seed)
        s = self.settings
        goal = s.goal_direction  # checked with the settings
        if options:
            options = dict(options)
            if "goal_direction" in options:
                goal = options.pop("goal_direction")
                check_number("reset options.goal_direction", goal)
            body_keys = ("x", "v", "kbar", "lbar")
            unknown = sorted(set(options) - set(body_keys))
            if unknown:
                raise ValueError(
                    f"reset options {unknown} are unknown; valid options: {', '.join(body_keys)}, goal_direction"
                )
        self._set_goal(float(goal))
        if s.randomize.enabled:
            config, self.randomized = s.randomize.draw(self.np_random, self.base_config)
        else:
            config, self.randomized = self.base_config, {}
        if config is not self.sim.config:
            self.sim.set_config(config)
        if options:
            body = {k: np.asarray(v, dtype=np.float64) for k, v in options.items()}
            self._check_options(body)
            self.sim.reset(**body)  # checks the body, fills in its missing parts
        else:
            self._start_body(self.np_random)
        self._reset_task(self.np_random)

        self._failure = None
        self._needs_reset = False
        T.robot_reset(*self._kernel_args)
        self._trail_com.clear()
        self._trail_head.clear()
        self._record_trail()

    def step(self, action):
        """Hold ``action`` for one control step of ``dt`` seconds and advance the physics.

        Args:
            action: (n_inputs,) in [-1, 1] (clipped beyond); scaled to the input rates as the
                class docstring's Action Space says. A wrong shape or a NaN raises ``ValueError``.

        Returns:
            ``(observation, reward, terminated, truncated, info)``: ``terminated`` is True on a
            physics failure (``info["failure"]`` names it); ``truncated`` is always False here
            (``TimeLimit`` from ``gym.make`` truncates); ``info`` holds every reward term, the
            state and the running ``metrics``.

        Raises:
            gymnasium.error.ResetNeeded: ``step`` before the first ``reset``.
            RuntimeError: ``step`` after a failure, before ``reset``.
        """
        if self._needs_reset:
            raise gym.error.ResetNeeded(
                f"{self.env_id}: call reset() before step() (the episode has not started)"
            )
        if self._failure is not None:
            raise RuntimeError(
                f"{self.env_id} episode terminated ({self._failure}); call reset() before stepping again"
            )
        task = self.task
        act = task.act
        if type(action) is np.ndarray and action.shape == self._act_shape and action.dtype.kind == "f":
            act[:] = action
        else:
            act[:] = self._check_action(action)
        status = T.robot_step_blocks(*self._kernel_args)
        if status == T.BAD_ACTION:
            a = np.asarray(action, dtype=np.float64)
            bad = np.flatnonzero(~np.isfinite(a)).tolist()
            raise ValueError(
                f"{self.env_id} action has non-finite entries at indices {bad} ({a[bad].tolist()}); "
                "every entry must be a finite number in [-1, 1]"
            )
        ok = status == OK
        r = task.rs.tolist()
        out = self._out.tolist()
        if ok:
            shape = self._copy_shape(self._own_views)
            self._last_state = (r, out, shape)
            info = self._info_of(out, None, r, shape, self._h)
        else:  # the last valid state, in new arrays (returned data must not be shared)
            self.fail(STATUS_REASONS[status])
            r0, out0, shape = self._last_state
            info = self._own_state_of(r0, out0, {k: v.copy() for k, v in shape.items()}, self._h)
            info.update(self._rest_of(r, out, self._failure))
        if self.render_mode is not None and ok:
            self._record_trail()
        if self.render_mode == "human":
            self.render()
        terminated = not ok or (self.terminate_on_success and r[T.R_SUCCESS] > 0.0)
        return task.obs.copy(), r[T.R_REWARD], terminated, False, info

    def render(self):
        """The current frame.

        An (H, W, 3) uint8 RGB array with ``render_mode="rgb_array"``; with ``"human"``, draws into
        a window and returns None. The picture shows the body (head in red), the recent trails of
        the centre of mass and the head, the goal direction, the time, on the ground the nodes
        stuck to the floor, and in a navigation task the target (with its success radius) or the
        path.
        """
        if self.render_mode is None:
            gym.logger.warn(
                f"render() called without a render_mode; create the env with "
                f'gym.make("{self.env_id}", render_mode="rgb_array")'
            )
            return None
        if self._renderer is None:
            self._renderer = BodyRenderer(
                human=self.render_mode == "human",
                ground=self.medium == "ground",
                body_length=self.base_config.rod.length,
                fps=self.metadata["render_fps"],
                view_lengths=self.view_lengths,
            )
        return self._renderer.draw(
            self.sim.x if self._failure is None else self._last_x,
            np.asarray(self._trail_com),
            np.asarray(self._trail_head),
            self.sim.time,
            self.task.tp[T.T_GCOS : T.T_GSIN + 1].copy(),  # the target's bearing, the path's direction
            self.env_id,
            self._failure,
            self.sim.stuck if self._failure is None and self.medium == "ground" else None,
            **self._render_task(),
        )

    def _render_task(self) -> dict[str, Any]:
        """What the renderer draws of the task besides the goal direction (a target, a path)."""
        return {}

    @property
    def failure(self) -> str | None:
        """Why the episode ended (a ``STATUS_REASONS`` entry), or None while it runs."""
        return self._failure

    def fail(self, reason: str) -> None:
        """End the episode with ``reason``.

        What a step that failed does (the vector env calls it for a robot whose batched step
        failed).
        """
        self._failure = self.sim.failure = reason

    def close(self) -> None:
        """Close the renderer, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        """The env's state for pickling, without the renderer (figures do not pickle)."""
        state = self.__dict__.copy()
        state["_renderer"] = None  # figures do not pickle; a new one is made on demand
        for name in (  # made again on unpickling
            "_kernel_args", "_out", "_shape", "_own_views", "_copy_shape",
            "_rest_of", "_own_state_of", "_info_of",
        ):  # fmt: skip
            del state[name]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore a pickled env; its arrays are views of the unpickled blocks again."""
        self.__dict__.update(state)
        self._bind_arrays()

    # --- helpers --------------------------------------------------------------------------
    def _check_action(self, action) -> np.ndarray:
        try:
            a = np.array(action, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{self.env_id} action {action!r} is not an array of numbers: {err}") from None
        if a.shape != self._act_shape:
            raise ValueError(
                f"{self.env_id} action has shape {a.shape}; expected {self._act_shape} "
                f"(one value in [-1, 1] per input)"
            )
        return a

    def _set_goal(self, goal: float) -> None:
        self.goal_direction = goal
        tp = self.task.tp
        tp[T.T_GOAL], tp[T.T_GCOS], tp[T.T_GSIN] = goal, math.cos(goal), math.sin(goal)

    @property
    def _com(self) -> np.ndarray:
        """Centre of mass at the last valid state, (2,) [m]."""
        return self.task.rs[T.R_COMX : T.R_COMY + 1].copy()

    def _record_trail(self) -> None:
        if self.render_mode is None:
            return
        q = self.sim.arrays.q
        self._trail_com.append(self._com)
        self._trail_head.append((q[-2], q[-1]))
        self._last_x = self.sim.x
