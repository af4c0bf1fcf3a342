"""What the soft-robot environments share: settings, randomization, the step/reset loop, metrics.

The environments are a thin task layer over one :class:`~soft_snake_gym.physics.Simulator`
(built once per environment and reused by every ``reset``). The physics-to-observation and
physics-to-reward code lives in plain functions of simulator arrays and quantities
(``soft_snake_gym.envs.observe`` for observations and inputs, ``reward_terms`` and
``episode_metrics`` here) so that a batched environment can reuse them.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from soft_snake_gym.config import ConfigError, from_dict, load_yaml
from soft_snake_gym.params import Fluid, Ground, Integrator, Rod, SimConfig
from soft_snake_gym.physics import Simulator, body_from_curvature

__all__ = [
    "G",
    "Randomization",
    "BaseSettings",
    "SoftRobotEnv",
    "reward_terms",
    "episode_metrics",
    "resolve_settings",
]

G = 9.81
"""Gravity used by the cost of transport (MODEL.md §8) [m/s^2]."""


# --- plain functions of simulator quantities (batchable) ----------------------------------------
def reward_terms(
    forward_speed: float,
    energy_power: float,
    action_sq: float,
    failed: bool,
    forward_reward_weight: float,
    energy_cost_weight: float,
    ctrl_cost_weight: float,
    failure_cost: float,
) -> dict[str, float]:
    """The named reward terms; the reward is their sum.

    Args:
        forward_speed: centre-of-mass progress along the goal over the step / dt [m/s].
        energy_power: the energy cost's power over the step (>= 0) [W].
        action_sq: squared 2-norm of the normalized action [-].
        failed: the step ended in a physics failure.
    """
    return {
        "reward_forward": forward_reward_weight * forward_speed,
        "reward_energy": -energy_cost_weight * energy_power,
        "reward_ctrl": -ctrl_cost_weight * action_sq,
        "reward_failure": -failure_cost if failed else 0.0,
    }


def episode_metrics(
    distance: float,
    displacement: float,
    duration: float,
    energy_actuator: float,
    actuator_work: float,
    energy_medium: float,
    medium_key: str,
    total_mass: float,
) -> dict[str, float]:
    """Episode averages of MODEL.md §8 from accumulated quantities.

    Args:
        distance: centre-of-mass displacement along the goal direction [m] (signed).
        displacement: length of the centre-of-mass displacement [m].
        duration: simulated time [s].
        energy_actuator: sum of |actuator work| per step [J].
        actuator_work: signed actuator work [J].
        energy_medium: energy lost to the fluid or to friction [J].
        medium_key: ``"energy_fluid"`` or ``"energy_friction"``.
        total_mass: mass of the body [kg].

    Returns:
        average_speed [m/s], distance [m], displacement [m], duration [s],
        cost_of_transport [-] (``inf`` unless the robot made forward progress), the energies [J].
    """
    return {
        "average_speed": distance / duration if duration > 0 else 0.0,
        "distance": distance,
        "displacement": displacement,
        "duration": duration,
        "cost_of_transport": energy_actuator / (total_mass * G * distance) if distance > 0 else math.inf,
        medium_key: energy_medium,
        "energy_actuator": energy_actuator,
        "actuator_work": actuator_work,
    }


# --- settings ---------------------------------------------------------------------------------
def _check_number(cls: str, name: str, value: Any, lo: float | None = None, lo_open: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{cls}.{name} = {value!r} must be a finite number")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise ValueError(f"{cls}.{name} = {value!r} must be {'>' if lo_open else '>='} {lo}")


@dataclass(frozen=True)
class Randomization:
    """Per-episode physics randomization: each field is ``None`` (not randomized) or a range
    ``[low, high]`` from which the value is drawn uniformly at every ``reset``.

    Fields map onto :class:`~soft_snake_gym.params.Rod` (``E``, ``E_bend``, ``damping``),
    :class:`~soft_snake_gym.params.Fluid` (``rho``, ``C_f``, ``C_D``, ``C_A``) and
    :class:`~soft_snake_gym.params.Ground` (``mu_s``, ``mu_d``; a drawn ``mu_d`` above the drawn
    ``mu_s`` is lowered to it). The draws happen in field order from ``env.np_random``.
    """

    E: tuple[float, float] | None = None
    E_bend: tuple[float, float] | None = None
    damping: tuple[float, float] | None = None
    rho: tuple[float, float] | None = None
    C_f: tuple[float, float] | None = None
    C_D: tuple[float, float] | None = None
    C_A: tuple[float, float] | None = None
    mu_s: tuple[float, float] | None = None
    mu_d: tuple[float, float] | None = None

    _SECTIONS: ClassVar[dict[str, str]] = {
        "E": "rod", "E_bend": "rod", "damping": "rod", "rho": "fluid", "C_f": "fluid",
        "C_D": "fluid", "C_A": "fluid", "mu_s": "ground", "mu_d": "ground",
    }

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            rng = getattr(self, f.name)
            if rng is None:
                continue
            rng = tuple(rng)
            object.__setattr__(self, f.name, rng)
            if len(rng) != 2 or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in rng
            ):
                raise ValueError(f"Randomization.{f.name} = {rng!r} must be a pair [low, high] of finite numbers")
            lo, hi = rng
            positive = f.name in ("E", "E_bend")
            if lo > hi or lo < 0 or (positive and lo <= 0):
                allowed = "0 < low <= high" if positive else "0 <= low <= high"
                raise ValueError(f"Randomization.{f.name} = {list(rng)!r} is not a valid range: need {allowed}")

    @property
    def enabled(self) -> bool:
        """True if any parameter is randomized."""
        return any(getattr(self, f.name) is not None for f in dataclasses.fields(self))

    def draw(self, rng: np.random.Generator, base: SimConfig) -> tuple[SimConfig, dict[str, float]]:
        """Draw one configuration around ``base``; returns it and the drawn values."""
        drawn: dict[str, float] = {}
        sections: dict[str, dict[str, float]] = {"rod": {}, "fluid": {}, "ground": {}}
        for f in dataclasses.fields(self):
            bounds = getattr(self, f.name)
            if bounds is None:
                continue
            value = float(rng.uniform(bounds[0], bounds[1]))
            drawn[f.name] = value
            sections[self._SECTIONS[f.name]][f.name] = value
        gr = sections["ground"]
        mu_s = gr.get("mu_s", base.ground.mu_s)
        if gr.get("mu_d", base.ground.mu_d) > mu_s:  # kinetic friction may not exceed static
            gr["mu_d"] = drawn["mu_d"] = mu_s
        config = dataclasses.replace(
            base,
            rod=dataclasses.replace(base.rod, **sections["rod"]),
            fluid=dataclasses.replace(base.fluid, **sections["fluid"]),
            ground=dataclasses.replace(base.ground, **gr),
        )
        return config, drawn


@dataclass(frozen=True)
class BaseSettings:
    """Constructor keywords shared by both environments (see the env docstrings)."""

    rod: Rod = Rod()
    fluid: Fluid = Fluid()
    ground: Ground = Ground()
    integrator: Integrator = Integrator()
    dt: float | None = None
    forward_reward_weight: float = 1.0
    energy_cost_weight: float = 1e-3
    ctrl_cost_weight: float = 1e-2
    failure_cost: float = 10.0
    reset_noise_scale: float = 0.01
    goal_direction: float = 0.0
    max_observed_speed: float = 2.0
    randomize: Randomization = field(default_factory=Randomization)

    def __post_init__(self) -> None:
        cls = type(self).__name__
        if self.dt is not None:
            _check_number(cls, "dt", self.dt, 0.0, lo_open=True)
            ratio = self.dt / self.integrator.h
            if ratio < 0.999 or abs(ratio - round(ratio)) > 1e-6 * ratio:
                raise ValueError(
                    f"{cls}.dt = {self.dt!r} must be a positive integer multiple of the integrator "
                    f"step integrator.h = {self.integrator.h!r}"
                )
        for name in ("forward_reward_weight", "goal_direction"):
            _check_number(cls, name, getattr(self, name))
        for name in ("energy_cost_weight", "ctrl_cost_weight", "failure_cost", "reset_noise_scale"):
            _check_number(cls, name, getattr(self, name), 0.0)
        _check_number(cls, "max_observed_speed", self.max_observed_speed, 0.0, lo_open=True)


def resolve_settings(settings_cls: type, medium: str, config: str | Path | None, kwargs: dict,
                     label: str | None = None) -> Any:
    """Settings from a YAML file of constructor keywords overridden by explicit keywords.

    A ``medium`` key in the file (as in ``configs/eel.yaml``) is accepted if it names this
    environment's medium. Unknown keys are rejected with the closest valid name.
    """
    data: dict[str, Any] = {}
    where = f"the keywords of {label}" if label else settings_cls.__name__
    if config is not None:
        data = dict(load_yaml(config))
        where = Path(config).name
        file_medium = data.pop("medium", medium)
        if file_medium != medium:
            raise ConfigError(
                f"{where} sets medium = {file_medium!r}, but this environment runs in {medium!r}; "
                f"remove the key or set it to {medium!r}"
            )
    data.update(kwargs)
    if config is not None and kwargs:
        where = f"{where} with keyword overrides"
    return from_dict(settings_cls, data, where=where)


def _display_available() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


# --- the environment --------------------------------------------------------------------------
class SoftRobotEnv(gym.Env):
    """Base of :class:`~soft_snake_gym.envs.SwimEnv` and :class:`~soft_snake_gym.envs.InchEnv`.

    Subclasses set ``medium``, ``settings_class``, ``env_id`` and implement the hooks
    ``_build_spaces``, ``_set_inputs``, ``_observe``, ``_energy_power``, ``_initial_body``,
    ``_state_info`` and ``_check_options``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 100}
    medium: ClassVar[str] = "water"
    settings_class: ClassVar[type] = BaseSettings
    env_id: ClassVar[str] = ""
    medium_energy_key: ClassVar[str] = "energy_fluid"
    trail_length: ClassVar[int] = 300

    def __init__(self, render_mode: str | None = None, config: str | Path | None = None, **kwargs: Any):
        self.settings = s = resolve_settings(self.settings_class, self.medium, config, kwargs, self.env_id)
        self.base_config = SimConfig(
            rod=s.rod, medium=self.medium, fluid=s.fluid, ground=s.ground, integrator=s.integrator
        )
        self.sim = Simulator(self.base_config)
        self.N = self.sim.N
        h = s.integrator.h
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
            from soft_snake_gym.envs.render import require_interactive_backend

            require_interactive_backend()  # fail at construction, not at the first frame
        self.render_mode = render_mode
        self._renderer = None

        self._uk = np.zeros(self.N - 2)
        self._ul = np.zeros(self.N - 1)
        self._build_spaces()
        box = self.observation_space
        self._obs_low = box.low.astype(np.float64)
        self._obs_high = box.high.astype(np.float64)
        self._obs_raw = np.zeros(box.shape, dtype=np.float64)  # unclipped, for info
        self._act_shape = self.action_space.shape

        self.goal_direction = s.goal_direction
        self._goal = np.array([math.cos(s.goal_direction), math.sin(s.goal_direction)])
        self._failure: str | None = None
        self._last_obs: np.ndarray | None = None
        self._com = np.zeros(2)
        self._com_start = np.zeros(2)
        self._metrics: dict[str, float] = {}
        self._trail_com: deque = deque(maxlen=self.trail_length)
        self._trail_head: deque = deque(maxlen=self.trail_length)
        self.randomized: dict[str, float] = {}
        self._power_actuator = self._power_medium = 0.0

    # --- hooks ------------------------------------------------------------------------------
    def _build_spaces(self) -> None:
        raise NotImplementedError

    def _set_inputs(self, action: np.ndarray) -> float:
        """Clip ``action`` to [-1, 1] in place and write the physical rates into ``self._uk`` /
        ``self._ul``; return the squared norm of the clipped action (NaN if not finite)."""
        raise NotImplementedError

    def _observe(self, raw: np.ndarray, out: np.ndarray) -> None:
        """Write the observation, unclipped into ``raw`` (float64) and clipped to the
        observation space into ``out`` (float32); set ``self._heading``."""
        raise NotImplementedError

    def _energy_power(self, d_actuator_energy: float, d_medium_energy: float) -> float:
        """The power charged by the energy cost, from the step's energy increments [W]."""
        return d_actuator_energy / self.dt

    def _initial_body(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _state_info(self) -> dict[str, Any]:
        raise NotImplementedError

    def _check_options(self, body: dict[str, np.ndarray]) -> None:
        """Reject an initial body from ``reset(options=...)`` that violates the env's bounds."""

    # --- gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        s = self.settings
        options = dict(options or {})
        goal = options.pop("goal_direction", s.goal_direction)
        _check_number("reset options", "goal_direction", goal)
        body_keys = ("x", "v", "kbar", "lbar")
        unknown = sorted(set(options) - set(body_keys))
        if unknown:
            raise ValueError(
                f"reset options {unknown} are unknown; valid options: {', '.join(body_keys)}, goal_direction"
            )
        self.goal_direction = float(goal)
        self._goal = np.array([math.cos(goal), math.sin(goal)])
        if s.randomize.enabled:
            config, self.randomized = s.randomize.draw(self.np_random, self.base_config)
        else:
            config, self.randomized = self.base_config, {}
        if config is not self.sim.config:
            self.sim.set_config(config)
        if options:
            body = {k: np.asarray(v, dtype=np.float64) for k, v in options.items()}
            self._check_options(body)
        else:
            body = self._initial_body(self.np_random)
        self.sim.reset(**body)

        self._failure = None
        self._power_actuator = self._power_medium = 0.0
        self._com = self._com_of(self.sim._q)
        self._com_start = self._com.copy()
        self._metrics = self._compute_metrics()
        self._trail_com.clear()
        self._trail_head.clear()
        self._record_trail()
        obs = self._get_obs()
        info = self._state_info()
        self._last_state_info = info.copy()
        info["randomized"] = dict(self.randomized)
        info["failure"] = None
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action):
        if self._failure is not None:
            raise RuntimeError(
                f"{self.env_id} episode terminated ({self._failure}); call reset() before stepping again"
            )
        a = self._check_action(action)
        action_sq = self._set_inputs(a)
        if action_sq != action_sq:  # NaN: a non-finite entry
            bad = np.flatnonzero(~np.isfinite(a)).tolist()
            raise ValueError(
                f"{self.env_id} action has non-finite entries at indices {bad} ({a[bad].tolist()}); "
                "every entry must be a finite number in [-1, 1]"
            )
        sim = self.sim
        e_act0, w_act0, e_med0 = sim.actuator_energy, sim.actuator_work, self._medium_energy()
        ok = sim.advance(self.n_substeps, self._uk, self._ul)
        if ok:
            com = self._com_of(sim._q)
            forward_speed = float((com - self._com) @ self._goal) / self.dt
            d_medium = self._medium_energy() - e_med0
            energy_power = self._energy_power(sim.actuator_energy - e_act0, d_medium)
            if self.n_substeps == 1:  # the simulator's own figures for its one step
                self._power_actuator = sim.actuator_power
                self._power_medium = sim.friction_power if self.medium == "ground" else sim.fluid_power
            else:  # averages over the control step
                self._power_actuator = (sim.actuator_work - w_act0) / self.dt
                self._power_medium = d_medium / self.dt
            self._com = com
            obs = self._get_obs()
            self._metrics = self._compute_metrics()
            self._record_trail()
        else:  # keep the last valid observation and metrics; the state may be non-finite
            self._failure = sim.failure
            forward_speed = energy_power = 0.0
            obs = self._last_obs.copy()
        s = self.settings
        terms = reward_terms(
            forward_speed, energy_power, action_sq, not ok, s.forward_reward_weight,
            s.energy_cost_weight, s.ctrl_cost_weight, s.failure_cost,
        )
        reward = sum(terms.values())
        if ok:
            info = self._state_info()
            self._last_state_info = info.copy()
        else:  # the last valid state, in new arrays (returned data must not be shared)
            info = {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in self._last_state_info.items()}
        info["forward_speed"] = forward_speed
        info.update(terms)
        info["failure"] = self._failure
        info["metrics"] = dict(self._metrics)
        if self.render_mode == "human":
            self.render()
        return obs, reward, not ok, False, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                f"render() called without a render_mode; create the env with "
                f'gym.make("{self.env_id}", render_mode="rgb_array")'
            )
            return None
        if self._renderer is None:
            from soft_snake_gym.envs.render import BodyRenderer

            self._renderer = BodyRenderer(
                human=self.render_mode == "human", ground=self.medium == "ground",
                body_length=self.base_config.rod.length, fps=self.metadata["render_fps"],
            )
        return self._renderer.draw(
            self.sim.x if self._failure is None else self._last_x,
            np.asarray(self._trail_com), np.asarray(self._trail_head),
            self.sim.time, self._goal, self.env_id, self._failure,
            self.sim.stuck if self._failure is None and self.medium == "ground" else None,
        )

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None  # figures do not pickle; a new one is made on demand
        return state

    # --- helpers --------------------------------------------------------------------------
    def _check_action(self, action) -> np.ndarray:
        try:
            a = np.array(action, dtype=np.float64)  # a copy: _set_inputs clips it in place
        except (TypeError, ValueError) as err:
            raise ValueError(
                f"{self.env_id} action {action!r} is not an array of numbers: {err}"
            ) from None
        if a.shape != self._act_shape:
            raise ValueError(
                f"{self.env_id} action has shape {a.shape}; expected {self._act_shape} "
                f"(one value in [-1, 1] per input)"
            )
        return a

    def _com_of(self, flat: np.ndarray) -> np.ndarray:
        """Mass-weighted mean of a flat interleaved (2N,) array of positions or velocities."""
        return self._mass_fraction @ flat.reshape(self.N, 2)

    def _medium_energy(self) -> float:
        return self.sim.friction_work if self.medium == "ground" else self.sim.fluid_energy

    def _get_obs(self) -> np.ndarray:
        obs = np.empty(self._obs_raw.shape, dtype=np.float32)
        self._observe(self._obs_raw, obs)
        self._last_obs = obs.copy()  # returned again if the next step fails
        return obs

    def _compute_metrics(self) -> dict[str, float]:
        sim = self.sim
        delta = self._com - self._com_start
        return episode_metrics(
            float(delta @ self._goal), math.hypot(delta[0], delta[1]), sim.time,
            sim.actuator_energy, sim.actuator_work, self._medium_energy(),
            self.medium_energy_key, self.total_mass,
        )

    def _record_trail(self) -> None:
        if self.render_mode is None:
            return
        q = self.sim._q
        self._trail_com.append(self._com.copy())
        self._trail_head.append((q[-2], q[-1]))
        self._last_x = self.sim.x

    def _noisy_straight_body(self, rng, kbar0: np.ndarray, lbar: np.ndarray, length_noise: bool):
        """A body near rest: curvatures ``kbar0 + U(-s, s)``, chord heading ``U(-s, s)`` (about
        +x, whatever the goal), rest lengths ``lbar (1 + U(-s, s))`` if ``length_noise``; at rest."""
        s = self.settings.reset_noise_scale
        kappa0 = kbar0 + rng.uniform(-s, s, kbar0.shape)
        if length_noise:
            lbar = lbar * (1.0 + rng.uniform(-s, s, lbar.shape))
        heading = rng.uniform(-s, s)
        x = body_from_curvature(kappa0, lbar, heading=heading)
        return {"x": x, "v": np.zeros_like(x), "kbar": kbar0.copy(), "lbar": lbar}
