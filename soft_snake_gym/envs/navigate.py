"""``SoftEelGoal-v0`` and ``SoftEelPath-v0``: the eel of ``SoftEel-v0`` asked to steer.

A task layer over the same physics, action, observation and reward terms as
:class:`~soft_snake_gym.envs.swim.SwimEnv`: the goal direction of the observation becomes the
bearing of a target point or the direction of a path, one more observation entry says how far
the target is or how far off the path the eel swims, and the forward reward pays progress
toward the target or along the path. The task's geometry is computed in the same compiled step
(:func:`soft_snake_gym.envs.task.robot_step`), so the batched vector env runs these tasks too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from gymnasium.spaces import Box

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.swim import SwimEnv, SwimSettings
from soft_snake_gym.params import check_number, plain_number

__all__ = ["GoalEnv", "GoalSettings", "PathEnv", "PathSettings", "path_polyline"]


def _show(value: Any) -> str:
    """``value`` as the user wrote it: a list for a tuple or list, else its repr."""
    return repr(list(value)) if isinstance(value, (tuple, list)) else repr(value)


def _check_range(where: str, value: Any, lo: float | None = None, hi: float | None = None) -> tuple:
    """``value`` as a pair ``(low, high)`` of finite numbers with ``lo <= low <= high <= hi``."""
    try:
        pair = tuple(plain_number(v) for v in value)
    except TypeError:
        pair = (None,)
    bounds = f" within [{lo:g}, {hi:g}]" if lo is not None and hi is not None else ""
    if len(pair) != 2 or not all(v is not None and math.isfinite(v) for v in pair) or pair[0] > pair[1]:
        raise ValueError(
            f"{where} = {_show(value)} must be a range [low, high] of finite numbers, low <= high{bounds}"
        )
    if (lo is not None and pair[0] < lo) or (hi is not None and pair[1] > hi):
        raise ValueError(f"{where} = {list(pair)!r} must lie{bounds}")
    return tuple(float(v) for v in pair)


@dataclass(frozen=True)
class _NavSettings(SwimSettings):
    """What both navigation envs add to :class:`SwimSettings`."""

    success_radius: float = 0.3

    def __post_init__(self) -> None:
        """Check the shared settings and that ``goal_direction`` is not set (the task sets it)."""
        super().__post_init__()
        cls = type(self).__name__
        check_number(f"{cls}.success_radius", self.success_radius, 0.0, lo_open=True)
        if self.goal_direction != 0.0:
            raise ValueError(
                f"{cls}.goal_direction = {self.goal_direction!r}: in a navigation task the goal "
                "direction is the bearing of the target or the direction of the path; leave it unset"
            )


@dataclass(frozen=True)
class GoalSettings(_NavSettings):
    """Constructor keywords of :class:`GoalEnv` (the table in its docstring)."""

    target_distance: tuple[float, float] = (1.0, 2.0)
    target_bearing: tuple[float, float] = (-math.pi / 2, math.pi / 2)
    target: tuple[float, float] | None = None
    success_bonus: float = 10.0
    max_target_distance: float = 10.0

    def __post_init__(self) -> None:
        """Check the target's ranges, the fixed target, the bonus and the observation bound."""
        super().__post_init__()
        object.__setattr__(
            self,
            "target_distance",
            _check_range("GoalSettings.target_distance", self.target_distance, 0.0, math.inf),
        )
        object.__setattr__(
            self,
            "target_bearing",
            _check_range("GoalSettings.target_bearing", self.target_bearing, -math.pi, math.pi),
        )
        if self.target is not None:
            object.__setattr__(self, "target", _check_point("GoalSettings.target", self.target))
        check_number("GoalSettings.success_bonus", self.success_bonus, 0.0)
        check_number("GoalSettings.max_target_distance", self.max_target_distance, 0.0, lo_open=True)


def _check_point(where: str, value: Any) -> tuple[float, float]:
    """``value`` as a point ``(x, y)`` of finite numbers [m]."""
    try:
        point = tuple(plain_number(v) for v in value)
    except TypeError:
        point = (None,)
    if len(point) != 2 or not all(v is not None and math.isfinite(v) for v in point):
        raise ValueError(f"{where} = {_show(value)} must be a point [x, y] of two finite numbers (m)")
    return (float(point[0]), float(point[1]))


@dataclass(frozen=True)
class PathSettings(_NavSettings):
    """Constructor keywords of :class:`PathEnv` (the table in its docstring)."""

    success_radius: float = 0.1
    path: Literal["line", "sine", "waypoints"] = "line"
    path_offset: tuple[float, float] = (-1.0, 1.0)
    path_angle: tuple[float, float] = (-math.pi / 6, math.pi / 6)
    path_length: float = 40.0
    sine_amplitude: float = 0.5
    sine_wavelength: float = 6.0
    waypoints: tuple[tuple[float, float], ...] | None = None
    cross_track_weight: float = 0.5
    max_cross_track: float = 5.0

    def __post_init__(self) -> None:
        """Check the path's kind, ranges and shape, the weight and the observation bound."""
        super().__post_init__()
        if self.path not in ("line", "sine", "waypoints"):
            raise ValueError(f"PathSettings.path = {self.path!r} must be 'line', 'sine' or 'waypoints'")
        object.__setattr__(self, "path_offset", _check_range("PathSettings.path_offset", self.path_offset))
        object.__setattr__(
            self, "path_angle", _check_range("PathSettings.path_angle", self.path_angle, -math.pi, math.pi)
        )
        check_number("PathSettings.path_length", self.path_length, 0.0, lo_open=True)
        check_number("PathSettings.sine_amplitude", self.sine_amplitude, 0.0)
        check_number("PathSettings.sine_wavelength", self.sine_wavelength, 0.0, lo_open=True)
        check_number("PathSettings.cross_track_weight", self.cross_track_weight, 0.0)
        check_number("PathSettings.max_cross_track", self.max_cross_track, 0.0, lo_open=True)
        if self.path == "waypoints":
            if self.waypoints is None or len(self.waypoints) < 2:
                raise ValueError(
                    f"PathSettings.waypoints = {_show(self.waypoints)}: path = 'waypoints' needs a list of at "
                    "least two points [[x, y], ...] (m, in the path's frame)"
                )
            points = tuple(
                _check_point(f"PathSettings.waypoints[{i}]", p) for i, p in enumerate(self.waypoints)
            )
            for i in range(1, len(points)):
                if points[i] == points[i - 1]:
                    raise ValueError(
                        f"PathSettings.waypoints[{i}] = {list(points[i])!r} repeats the point before it; "
                        "consecutive waypoints must differ"
                    )
            object.__setattr__(self, "waypoints", points)
        elif self.waypoints is not None:
            raise ValueError(
                f"PathSettings.waypoints is set but path = {self.path!r}; set path = 'waypoints' to follow them"
            )


def path_polyline(settings: PathSettings) -> np.ndarray:
    """The path of ``settings`` in its own frame (start of the path at the origin, along +x), (M, 2) [m].

    ``line``: from ``-0.1 path_length`` to ``path_length`` along x. ``sine``: ``y = sine_amplitude
    sin(2 pi x / sine_wavelength)`` over the same span, a vertex every 5 cm. ``waypoints``: as given.
    """
    s = settings
    if s.path == "waypoints":
        return np.array(s.waypoints, dtype=np.float64)
    if s.path == "line":
        return np.array([[-0.1 * s.path_length, 0.0], [s.path_length, 0.0]])
    x = np.linspace(-0.1 * s.path_length, s.path_length, int(round(1.1 * s.path_length / 0.05)) + 1)
    return np.column_stack([x, s.sine_amplitude * np.sin(2 * np.pi * x / s.sine_wavelength)])


class _NavEnv(SwimEnv):
    """What both navigation envs share: one more observation entry, the task's reset and drawing."""

    nav_block: ClassVar[str] = ""
    trail_length = 3000

    def _build_spaces(self) -> None:
        super()._build_spaces()
        self.observation_structure[self.nav_block] = 1
        bound = self._nav_bound()
        low = np.append(self.observation_space.low, -bound).astype(np.float32)
        high = np.append(self.observation_space.high, bound).astype(np.float32)
        self.observation_space = Box(low, high, dtype=np.float32)

    def _nav_bound(self) -> float:
        raise NotImplementedError

    def _setup(self, settings, render_mode, sim=None, task=None) -> None:
        super()._setup(settings, render_mode, sim=sim, task=task)
        tp = self.task.tp
        tp[T.T_RADIUS] = settings.success_radius
        tp[T.T_BONUS] = getattr(settings, "success_bonus", 0.0)
        tp[T.T_WXTE] = getattr(settings, "cross_track_weight", 0.0)
        tp[T.T_NPATH] = self.n_path
        self._options: dict[str, Any] = {}

    def start_episode(self, seed: int | None = None, options: dict[str, Any] | None = None) -> None:
        """Start an episode, as :meth:`SwimEnv.start_episode`, with this task's own options (class docstring)."""
        options = dict(options or {})
        self._options = {k: options.pop(k) for k in self.task_options if k in options}
        if "goal_direction" in options:
            raise ValueError(
                f"{self.env_id}: reset option goal_direction is not used: the task sets the goal "
                f"direction; options of this task: {', '.join(self.task_options)}"
            )
        super().start_episode(seed, options)


class GoalEnv(_NavEnv):
    r"""The eel swims to a target point: ``SoftEelGoal-v0``.

    ## Description
    The robot, physics and action of ``SoftEel-v0`` (:class:`SwimEnv`). At each reset a target is
    drawn at a distance in ``target_distance`` [m] and a bearing in ``target_bearing`` [rad, from
    +x] of the starting centre of mass (the body starts along +x); the episode ends with success
    (``terminated``, ``info["is_success"]``) when the centre of mass comes within
    ``success_radius`` of it.

    ## Observation Space
    ``SoftEel-v0``'s 3(N-2)+4 entries, where ``goal_direction_body`` is the cos and sin of the
    target's bearing relative to the heading (the target in the body frame, its direction), then
    ``target_distance`` (1): the distance from the centre of mass to the target [m], bounded by
    ``max_target_distance``. A `Box((3(N-2)+5,), float32)`, 29 entries for N = 10.

    ## Rewards
    ``reward_forward`` = ``forward_reward_weight`` × progress speed (the decrease of the distance
    to the target per second, m/s); ``reward_success`` = ``success_bonus`` on the step that
    reaches the target; ``reward_energy``, ``reward_ctrl``, ``reward_failure`` as in
    ``SoftEel-v0``; ``reward_cross_track`` is 0 here.

    ## Episode End
    Terminated on success or on a physics failure; truncated after 3000 steps (30 s).

    ## Info
    That of ``SoftEel-v0``, plus ``target_distance`` [m], ``is_success`` (the target reached),
    ``forward_speed`` the progress speed [m/s], and in ``metrics``: ``distance`` (progress: the
    initial distance minus the current one, m), ``success`` (0/1), ``time_to_goal`` [s] (inf
    until reached), ``target_distance`` [m]. ``env.unwrapped.target`` is the episode's target.

    ## Arguments
    Those of ``SoftEel-v0`` (``goal_direction`` excepted: the target sets it) and:

    | Parameter             | Type       | Default          | Description                                                   |
    |-----------------------|------------|------------------|---------------------------------------------------------------|
    | `target_distance`     | [low, high]| `[1.0, 2.0]`     | range of the target's distance from the start (m), uniform    |
    | `target_bearing`      | [low, high]| `[-pi/2, pi/2]`  | range of its bearing from +x (rad), uniform, within [-pi, pi] |
    | `target`              | [x, y] or None | `None`       | a fixed target (m) instead of the draw                       |
    | `success_radius`      | float      | `0.3`            | reached within this distance of the centre of mass (m)        |
    | `success_bonus`       | float      | `10.0`           | reward on reaching it                                         |
    | `max_target_distance` | float      | `10.0`           | bound of the observed distance (m)                            |

    ``reset(options={"target": [x, y]})`` sets the episode's target.
    """

    settings_class = GoalSettings
    env_id = "SoftEelGoal-v0"
    task_kind = T.TASK_GOAL
    terminate_on_success = True
    nav_block = "target_distance"
    task_options = ("target",)

    def _nav_bound(self) -> float:
        return self.settings.max_target_distance

    def _reset_task(self, rng: np.random.Generator) -> None:
        s = self.settings
        if "target" in self._options:
            target = _check_point("reset options.target", self._options["target"])
        elif s.target is not None:
            target = s.target
        else:
            d = rng.uniform(*s.target_distance)
            b = rng.uniform(*s.target_bearing)
            com = self.sim.com
            target = (com[0] + d * math.cos(b), com[1] + d * math.sin(b))
        self.target = np.array(target, dtype=np.float64)
        self.task.tp[T.T_TX], self.task.tp[T.T_TY] = self.target

    def _render_task(self) -> dict[str, Any]:
        return {"target": self.target, "target_radius": self.settings.success_radius}


class PathEnv(_NavEnv):
    r"""The eel follows a path: ``SoftEelPath-v0``.

    ## Description
    The robot, physics and action of ``SoftEel-v0`` (:class:`SwimEnv`). At each reset the path
    (``path``: a straight ``line``, a ``sine`` wave, or a polyline of ``waypoints``, given in
    its own frame, starting at its origin along +x) is turned by an angle drawn from
    ``path_angle`` [rad] and shifted to its left by an offset drawn from ``path_offset`` [m],
    about the starting centre of mass (the body starts along +x). The robot should swim along
    it: the closest point of the path moves forward, the cross-track error (the distance to
    that point) stays small. A polyline's first segment extends backwards and its last
    forwards without end.

    ## Observation Space
    ``SoftEel-v0``'s 3(N-2)+4 entries, where ``goal_direction_body`` is the cos and sin of the
    path's direction at the closest point relative to the heading, then ``cross_track_error``
    (1): the signed distance to the path [m], positive with the path on the robot's right
    (looking along the path), bounded by ``max_cross_track``. A `Box((3(N-2)+5,), float32)`.

    ## Rewards
    ``reward_forward`` = ``forward_reward_weight`` × progress speed along the path (the rate of
    the closest point's arc length, m/s); ``reward_cross_track`` = ``-cross_track_weight`` ×
    \|cross-track error\| (per m); ``reward_energy``, ``reward_ctrl``, ``reward_failure`` as in
    ``SoftEel-v0``; ``reward_success`` is 0 here.

    ## Episode End
    Terminated on a physics failure; truncated after 3000 steps (30 s).

    ## Info
    That of ``SoftEel-v0``, plus ``cross_track_error`` (signed, m), ``is_success`` (\|cross-track
    error\| <= ``success_radius`` now: on the path), ``forward_speed`` the progress speed along the
    path [m/s], and in ``metrics``: ``distance`` (progress along the path, m), ``average_speed``
    (that progress per second), ``cross_track_error`` (mean \|error\| over the episode, m),
    ``final_cross_track_error`` (\|error\| now, m). ``env.unwrapped.path`` is the episode's
    polyline, (M, 2) [m].

    ## Arguments
    Those of ``SoftEel-v0`` (``goal_direction`` excepted: the path sets it) and:

    | Parameter             | Type       | Default          | Description                                                   |
    |-----------------------|------------|------------------|---------------------------------------------------------------|
    | `path`                | str        | `"line"`         | `"line"`, `"sine"` or `"waypoints"`                           |
    | `path_offset`         | [low, high]| `[-1.0, 1.0]`    | range of the path's offset to the left of the start (m)       |
    | `path_angle`          | [low, high]| `[-pi/6, pi/6]`  | range of its direction from +x (rad), within [-pi, pi]        |
    | `path_length`         | float      | `40.0`           | extent of the line or sine ahead of the start (m)             |
    | `sine_amplitude`      | float      | `0.5`            | amplitude of the sine path (m)                                |
    | `sine_wavelength`     | float      | `6.0`            | its wavelength (m)                                            |
    | `waypoints`           | [[x, y], ...] | `None`        | the polyline of `path="waypoints"` (m, path frame), >= 2 points |
    | `success_radius`      | float      | `0.1`            | `is_success` within this distance of the path (m)             |
    | `cross_track_weight`  | float      | `0.5`            | weight of *reward_cross_track* (per m)                        |
    | `max_cross_track`     | float      | `5.0`            | bound of the observed cross-track error (m)                   |

    ``reset(options={"path_offset": d, "path_angle": a})`` fixes the episode's offset and angle.
    """

    settings_class = PathSettings
    env_id = "SoftEelPath-v0"
    task_kind = T.TASK_PATH
    nav_block = "cross_track_error"
    task_options = ("path_offset", "path_angle")

    def _setup_task(self) -> None:
        super()._setup_task()
        self._local_path = path_polyline(self.settings)
        self.n_path = len(self._local_path)
        seg = np.linalg.norm(np.diff(self._local_path, axis=0), axis=1)
        self._arc = np.concatenate([[0.0], np.cumsum(seg)])

    def _nav_bound(self) -> float:
        return self.settings.max_cross_track

    def _reset_task(self, rng: np.random.Generator) -> None:
        s = self.settings
        offset = rng.uniform(*s.path_offset)
        angle = rng.uniform(*s.path_angle)
        for key in ("path_offset", "path_angle"):
            if key in self._options:
                check_number(f"reset options.{key}", self._options[key])
        offset = float(self._options.get("path_offset", offset))
        angle = float(self._options.get("path_angle", angle))
        c, sn = math.cos(angle), math.sin(angle)
        origin = self.sim.com + offset * np.array([-sn, c])
        self.path = origin + self._local_path @ np.array([[c, sn], [-sn, c]])
        self.task.path[:, :2] = self.path
        self.task.path[:, 2] = self._arc

    def _render_task(self) -> dict[str, Any]:
        return {"path": self.path}
