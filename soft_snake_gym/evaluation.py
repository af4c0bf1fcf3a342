"""The one metrics module.

Run episodes of any policy through SB3's ``evaluate_policy`` and collect per-episode metrics
(docs/model.md §8), named, labelled and given units once in the registry :data:`METRICS`.

Per episode:

- ``return``: the sum of rewards; ``steps``; ``duration`` [s];
- ``average_speed`` [m/s]: centre-of-mass progress along the goal per time, over the window
  after ``transient`` seconds (the whole episode if it is shorter than twice that); not the
  env's ``info["metrics"]["average_speed"]``, which is over the whole episode (the registry
  :data:`METRICS` names that one ``episode_speed``);
- ``com_speed`` [m/s]: the centre of mass's displacement over the same window, whatever its
  direction, divided by the window's duration (docs/model.md §8's average speed; equal to
  ``average_speed`` for a robot that swims straight along the goal);
- ``distance`` [m]: progress along the goal over the whole episode;
- ``tracking_error``: mean over the same window and over nodes of ``|desired - measured|``,
  curvature [-] on the eel, edge length [m] on the worm; only for the baseline policies
  (NaN for a trained model, which has no reference);
- ``mean_fluid_power`` [W] (over the whole episode) / ``energy_fluid`` [J] in water,
  ``window_fluid_power`` [W] (mean over the same window as the speed), ``energy_friction`` [J]
  on land;
- ``energy_actuator`` [J] and ``cost_of_transport`` [-] (the env's, docs/model.md §8);
- ``failure``: the env's failure reason, or "";
- in ``SoftEelGoal-v0``: ``success`` (1 if the target was reached, else 0; its mean is the
  success rate), ``time_to_goal`` [s] (inf if not reached: means are over the reached ones), ``target_distance`` [m] (left at
  the end); in ``SoftEelPath-v0``: ``cross_track_error`` [m] (mean |error| over the episode),
  ``final_cross_track_error`` [m] (|error| at the end); in both ``distance`` and
  ``average_speed`` are progress toward the target or along the path;
- ``window_start`` [s]: where the speed and error window began: ``transient``, or 0 for an
  episode shorter than twice that (a failure), whose whole length is used.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from soft_snake_gym.envs import register_envs

__all__ = [
    "EpisodeRecorder",
    "evaluate",
    "make_eval_env",
    "summarize",
    "format_table",
    "COLUMNS",
    "METRICS",
    "NAV_METRICS",
    "Metric",
    "TABLE",
    "metric_columns",
    "check_video_path",
    "check_transient",
    "gait_rate_warning",
]

VIDEO_FPS = 25
"""Frames per second of ``--video`` (the env renders only the frames kept)."""


@dataclass(frozen=True)
class Metric:
    """One episode metric of the registry :data:`METRICS`.

    Attributes:
        name: the registry's name, unique.
        label: how tables, charts and reports call it ("average speed").
        unit: SI unit ("m/s"), or "-" for a dimensionless number.
        window: ``"transient"``: averaged after the transient (over the whole episode if the
            episode is shorter than twice the transient, see :class:`EpisodeRecorder`);
            ``"episode"``: over the whole episode.
        source: ``"evaluation"``: a key of :func:`evaluate`'s episode dicts, hence of
            ``soft-snake evaluate --json`` and the sweep CSVs; ``"env"``: a key of the env's
            ``info["metrics"]`` that evaluation does not pass on under that meaning.
        key: the key under which it is written, if not ``name``.
    """

    name: str
    label: str
    unit: str
    window: str
    source: str = "evaluation"
    key: str = ""

    def __post_init__(self) -> None:
        """Default ``key`` to ``name``."""
        if not self.key:
            object.__setattr__(self, "key", self.name)


#: Every episode metric, by name: the one list that tables, charts, sweeps and checks draw on.
#:
#: Two speeds share the key ``average_speed`` and are told apart here by name: ``average_speed``
#: (evaluation, JSON, CSV) is the mean of ``info["forward_speed"]`` after the transient, while
#: ``episode_speed`` is the env's ``info["metrics"]["average_speed"]``, progress along the goal
#: over the whole episode divided by its duration (``distance / duration``). Both keys stay as
#: they are (files and ``info`` keep their meaning); code that means one of them names it here.
METRICS: dict[str, Metric] = {
    m.name: m
    for m in (
        Metric("return", "return", "-", "episode"),
        Metric("average_speed", "average speed", "m/s", "transient"),
        Metric("com_speed", "centre-of-mass speed", "m/s", "transient"),
        Metric("distance", "distance", "m", "episode"),
        Metric("curvature_error", "curvature error", "-", "transient"),
        Metric("length_error", "length error", "m", "transient"),
        Metric("mean_fluid_power", "fluid power", "W", "episode"),
        Metric("window_fluid_power", "fluid power after the transient", "W", "transient"),
        Metric("energy_fluid", "fluid energy", "J", "episode"),
        Metric("energy_friction", "friction energy", "J", "episode"),
        Metric("energy_actuator", "actuator energy", "J", "episode"),
        Metric("cost_of_transport", "cost of transport", "-", "episode"),
        Metric("duration", "duration", "s", "episode"),
        Metric("success", "success rate", "-", "episode"),
        Metric("time_to_goal", "time to goal", "s", "episode"),
        Metric("target_distance", "distance to target", "m", "episode"),
        Metric("cross_track_error", "cross-track error", "m", "episode"),
        Metric("final_cross_track_error", "final cross-track error", "m", "episode"),
        Metric(
            "episode_speed",
            "average speed over the episode",
            "m/s",
            "episode",
            source="env",
            key="average_speed",
        ),
    )
}

#: The metrics of ``soft-snake evaluate``'s table, in order; rows whose key is absent are skipped.
TABLE = (
    "return",
    "average_speed",
    "distance",
    "curvature_error",
    "length_error",
    "mean_fluid_power",
    "energy_fluid",
    "energy_friction",
    "energy_actuator",
    "cost_of_transport",
    "success",
    "time_to_goal",
    "target_distance",
    "cross_track_error",
    "final_cross_track_error",
)

#: The navigation tasks' metrics (written only by ``SoftEelGoal-v0`` and ``SoftEelPath-v0``).
NAV_METRICS = ("success", "time_to_goal", "target_distance", "cross_track_error", "final_cross_track_error")


def metric_columns(names: tuple[str, ...] | list[str]) -> list[tuple[str, str, str]]:
    """(key, label, unit) of the metrics ``names`` of :data:`METRICS`, in that order."""
    return [(METRICS[n].key, METRICS[n].label, METRICS[n].unit) for n in names]


#: (key, label, unit) of the summary table, in order (from :data:`METRICS`).
COLUMNS = metric_columns(TABLE)


def make_eval_env(
    env_id: str,
    n_envs: int = 1,
    seed: int | None = 0,
    env_kwargs: dict[str, Any] | None = None,
    render_mode: str | None = None,
    wrapper: Callable[[gym.Env], gym.Env] | None = None,
):
    """A ``DummyVecEnv`` of ``Monitor``-wrapped envs, as SB3's evaluation expects.

    ``wrapper``, if given, wraps each env inside its ``Monitor`` (a perturbation, say).
    """
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    register_envs()  # what ``import soft_snake_gym`` does; harmless to repeat

    kwargs = dict(env_kwargs or {})
    if render_mode is not None:
        kwargs["render_mode"] = render_mode

    def factory(rank: int):
        def make():
            env = gym.make(env_id, **kwargs)
            env = Monitor(wrapper(env) if wrapper is not None else env)
            env.reset(seed=None if seed is None else seed + rank)
            return env

        return make

    venv = DummyVecEnv([factory(i) for i in range(n_envs)])
    if seed is not None:
        venv.seed(seed)
    return venv


@dataclass
class _Running:
    steps: int = 0
    window_steps: int = 0
    speed_sum: float = 0.0
    error_sum: float = 0.0
    error_n: int = 0
    power_sum: float = 0.0
    all_power_sum: float = 0.0
    last_com: tuple[float, float] | None = None
    window_com: tuple[float, float] | None = None  # centre of mass where the window starts
    ret: float = 0.0
    all_speed_sum: float = 0.0
    all_error_sum: float = 0.0
    all_error_n: int = 0


class EpisodeRecorder:
    """An ``evaluate_policy`` callback that turns each env's steps into episode metrics.

    Args:
        dt: control step [s].
        transient: start-up time left out of speed and tracking error [s].
        error_key: ``"curvature_error"`` or ``"length_error"``.
    """

    def __init__(self, dt: float, transient: float, error_key: str) -> None:
        """Start with no episodes recorded (arguments in the class docstring)."""
        self.dt, self.transient, self.error_key = dt, transient, error_key
        self.episodes: list[dict[str, Any]] = []
        self._run: dict[int, _Running] = {}

    def __call__(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        """Record one env's step from ``evaluate_policy``'s locals; a finished episode adds its metrics."""
        i, info, done = locals_["i"], locals_["info"], bool(locals_["done"])
        policy = locals_["model"]
        run = self._run.setdefault(i, _Running())
        run.steps += 1
        run.ret += float(locals_["reward"])
        err = getattr(policy, "last_error", None)
        e = float(np.mean(err[i])) if err is not None else math.nan
        speed = float(info.get("forward_speed", 0.0))
        power = float(info.get("fluid_power", math.nan))
        run.all_speed_sum += speed
        run.all_power_sum += power
        if err is not None:
            run.all_error_sum += e
            run.all_error_n += 1
        com = (float(info.get("x_position", math.nan)), float(info.get("y_position", math.nan)))
        if run.steps * self.dt > self.transient + 1e-9:
            if run.window_steps == 0:
                run.window_com = run.last_com
            run.window_steps += 1
            run.speed_sum += speed
            run.power_sum += power
            if err is not None:
                run.error_sum += e
                run.error_n += 1
        run.last_com = com
        if done:
            self.episodes.append(self._finish(run, info))
            self._run[i] = _Running()

    def _finish(self, run: _Running, info: dict[str, Any]) -> dict[str, Any]:
        m = dict(info.get("metrics", {}))
        duration = run.steps * self.dt
        use_window = run.window_steps > 0 and duration >= 2 * self.transient
        com_speed = float(m.get("displacement", math.nan)) / duration if duration > 0 else math.nan
        if use_window:
            speed = run.speed_sum / run.window_steps
            if run.window_com is not None:
                com_speed = math.dist(run.last_com, run.window_com) / (run.window_steps * self.dt)
            power = run.power_sum / run.window_steps
            error = run.error_sum / run.error_n if run.error_n else math.nan
        else:
            speed = run.all_speed_sum / run.steps
            power = run.all_power_sum / run.steps
            error = run.all_error_sum / run.all_error_n if run.all_error_n else math.nan
        out: dict[str, Any] = {
            "return": run.ret,
            "steps": run.steps,
            "duration": duration,
            "window_start": self.transient if use_window else 0.0,
            "average_speed": speed,
            "com_speed": com_speed,
            "distance": float(m.get("distance", math.nan)),
            self.error_key: error,
            "energy_actuator": float(m.get("energy_actuator", math.nan)),
            "cost_of_transport": float(m.get("cost_of_transport", math.nan)),
            "failure": info.get("failure") or "",
        }
        if "energy_fluid" in m:
            out["energy_fluid"] = float(m["energy_fluid"])
            out["mean_fluid_power"] = float(m["energy_fluid"]) / duration if duration > 0 else math.nan
            out["window_fluid_power"] = power
        if "energy_friction" in m:
            out["energy_friction"] = float(m["energy_friction"])
        for key in NAV_METRICS:
            if key in m:
                out[key] = float(m[key])
        return out


def evaluate(
    policy: Any,
    env,
    episodes: int = 3,
    transient: float = 2.0,
    deterministic: bool = True,
    video: str | Path | None = None,
) -> list[dict[str, Any]]:
    """Run ``episodes`` episodes of ``policy`` with SB3's ``evaluate_policy``.

    On the VecEnv ``env`` (see :func:`make_eval_env`); returns one metrics dict per episode.

    Args:
        policy: anything with SB3's ``predict`` (a baseline or a trained model).
        env: a ``DummyVecEnv`` of Monitor-wrapped soft_snake_gym envs.
        episodes: number of episodes.
        transient: start-up time excluded from speed and tracking error [s].
        deterministic: passed to ``predict``.
        video: if given, the first episode of env 0 is written there (``.mp4`` or ``.gif``);
            the env must have been made with ``render_mode="rgb_array"``.
    """
    from stable_baselines3.common.evaluation import evaluate_policy

    check_transient(transient, math.inf)  # a transient longer than the episode averages it all
    if video is not None:
        check_video_path(video)
    inner = env.envs[0].unwrapped
    warning = gait_rate_warning(policy, env)
    if warning:
        warnings.warn(warning, stacklevel=2)
    error_key = "curvature_error" if inner.medium == "water" else "length_error"
    rec = EpisodeRecorder(inner.dt, transient, error_key)
    recorder = None
    if video is not None:
        stride = max(1, int(round(1.0 / (VIDEO_FPS * inner.dt))))  # render only the frames kept
        recorder = env.envs[0] = _FirstEpisodeFrames(env.envs[0], stride)
    try:
        evaluate_policy(
            policy,
            env,
            n_eval_episodes=episodes,
            deterministic=deterministic,
            callback=rec,
            return_episode_rewards=True,
            warn=False,
        )
    finally:
        if recorder is not None:
            env.envs[0] = recorder.env
    if recorder is not None:
        write_video(recorder.frames, video, fps=round(1.0 / (recorder.stride * inner.dt)))
    return rec.episodes


class _FirstEpisodeFrames(gym.Wrapper):
    """Env 0 of an evaluation, rendering its first episode: the reset state, then every ``stride``-th step.

    It renders inside the episode's own reset and steps, so a video changes nothing of what is
    evaluated (the seeded reset stays the episode's).
    """

    def __init__(self, env: Any, stride: int) -> None:
        super().__init__(env)
        self.stride = stride
        self.frames: list[np.ndarray] = []
        self._step: int | None = None  # steps of the first episode so far; None before it starts

    def reset(self, **kwargs: Any):
        out = self.env.reset(**kwargs)
        if self._step is None:
            self._step = 0
            self._keep()
        else:
            self._step = -1  # the first episode is over
        return out

    def step(self, action: Any):
        out = self.env.step(action)
        if self._step is not None and self._step >= 0:
            self._step += 1
            if self._step % self.stride == 0:
                self._keep()
        return out

    def _keep(self) -> None:
        frame = self.env.render()
        if frame is not None:
            self.frames.append(frame)


def check_video_path(path: str | Path) -> None:
    """Raise ``ValueError`` unless a video can be written at ``path``.

    A ``.gif`` (Pillow), or an ``.mp4`` with imageio and its ffmpeg plugin installed (the ``video``
    extra). Call it before running episodes, so a missing dependency fails at once.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".mp4", ".gif"):
        raise ValueError(f"video path {str(path)!r} must end in .mp4 or .gif")
    if suffix == ".mp4":
        try:
            import imageio.v2  # noqa: F401
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ValueError(
                f"writing {Path(path).name} needs imageio with ffmpeg (pip install "
                "'soft-snake-gym[video]'); or give a .gif path"
            ) from None


def check_transient(transient: float, duration: float) -> None:
    """Raise ``ValueError`` unless ``transient`` [s] leaves an averaging window in the episode.

    The episode lasts ``duration`` [s]. Speed and error are averaged after the transient only when
    the episode lasts at least twice as long (otherwise over the whole episode).
    """
    if not (isinstance(transient, (int, float)) and math.isfinite(transient) and transient >= 0):
        raise ValueError(f"transient = {transient!r} s must be a finite number >= 0")
    if 2 * transient > duration + 1e-9:
        raise ValueError(
            f"transient = {transient:g} s is longer than half the {duration:g} s episode, so no "
            f"metrics would be taken after it; give at most {duration / 2:g} s or a longer episode"
        )


def gait_rate_warning(policy: Any, env: Any) -> str | None:
    """A warning if a baseline's gait asks for input rates beyond the env's action scale.

    The scale is ``max_curvature_rate`` or ``max_length_rate``: the actions saturate and the gait is
    not the one named. None when the gait fits or the policy has no gait (a trained agent).
    """
    params = getattr(policy, "params", None)
    inner = env.envs[0].unwrapped if hasattr(env, "envs") else getattr(env, "unwrapped", env)
    omega = getattr(params, "omega", None)
    if omega is None:
        return None
    if hasattr(params, "alpha") and hasattr(inner, "max_curvature_rate"):
        alpha = params.alpha
        peak = alpha * omega / math.cos(alpha / 2) ** 2  # max of d/dt 2 tan(alpha sin(psi) / 2)
        limit, name, unit = inner.max_curvature_rate, "max_curvature_rate", "1/s"
        gait = f"alpha = {alpha:g} rad, omega = {omega:g} rad/s"
    elif hasattr(params, "eps") and hasattr(inner, "max_length_rate"):
        # the policy's own edge length and duty: a pulse's peak rate grows as 1/duty
        peak = 0.5 * policy.l0 * params.eps * omega / policy.duty
        limit, name, unit = inner.max_length_rate, "max_length_rate", "m/s"
        gait = f"eps = {params.eps:g}, omega = {omega:g} rad/s"
    else:
        return None
    if peak <= limit * (1 + 1e-9):
        return None
    return (
        f"the {gait} gait needs input rates up to {peak:.3g} {unit}, beyond the env's {name} = "
        f"{limit:.3g} {unit}: the actions saturate and the robot does not follow the gait; "
        f"raise {name} (--env-kwarg {name}={peak * 1.05:.3g}) or slow the gait"
    )


def write_video(frames: list[np.ndarray], path: str | Path, fps: int = 50, stride: int = 1) -> Path:
    """Write RGB frames (H, W, 3) to ``.mp4`` (imageio-ffmpeg) or ``.gif`` (Pillow)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    frames = [f for f in frames[::stride] if f is not None]
    if not frames:
        raise ValueError("no frames were rendered; the env must be made with render_mode='rgb_array'")
    if path.suffix.lower() == ".gif":
        from PIL import Image

        images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
        images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
        return path
    try:
        import imageio.v2 as imageio
    except ImportError as err:
        raise RuntimeError(
            f"writing {path.name} needs imageio with ffmpeg (pip install 'soft-snake-gym[video]'); "
            "or give a .gif path"
        ) from err
    # H.264 wants sides divisible by 16: pad with the edge pixels (imageio would resize, and warn)
    frames = [np.asarray(f, dtype=np.uint8) for f in frames]
    frames = [np.pad(f, ((0, -f.shape[0] % 16), (0, -f.shape[1] % 16), (0, 0)), mode="edge") for f in frames]
    imageio.mimsave(path, frames, fps=fps)
    return path


def summarize(episodes: list[dict[str, Any]]) -> dict[str, tuple[float, float]]:
    """Mean and standard deviation of every numeric metric over episodes."""
    keys = [k for k in episodes[0] if isinstance(episodes[0][k], (int, float))]
    out = {}
    for k in keys:
        vals = np.array([float(e[k]) for e in episodes])
        finite = vals[np.isfinite(vals)]
        out[k] = (float(finite.mean()), float(finite.std())) if finite.size else (math.nan, math.nan)
    return out


def format_table(summary: dict[str, tuple[float, float]], title: str = "") -> str:
    """A plain-text table: metric, unit, mean ± std."""
    rows = [(label, unit, summary[key]) for key, label, unit in metric_columns(TABLE) if key in summary]
    width = max(len(r[0]) for r in rows)
    lines = [title] if title else []
    lines.append(f"{'metric':<{width}}  {'unit':<4}  {'mean':>11} ± {'std':<10}")
    lines.append("-" * (width + 32))
    for label, unit, (mean, std) in rows:
        if math.isnan(mean):
            lines.append(f"{label:<{width}}  {unit:<4}  {'n/a':>11}")
        else:
            lines.append(f"{label:<{width}}  {unit:<4}  {mean:>11.4g} ± {std:<10.3g}")
    return "\n".join(lines)
