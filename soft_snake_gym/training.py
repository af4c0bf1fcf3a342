"""Stable-Baselines3 training: YAML hyperparameters keyed by env id, run folders, resume,
and an evaluation callback that scores the agent against a baseline controller.

A run folder holds everything needed to reproduce or continue a run::

    runs/SoftEel-v0_PPO_s0/
      config.yaml          the resolved configuration (run settings and hyperparameters)
      command.txt          the exact command line
      meta.json            package version, git commit, library versions, start time
      tb/                  TensorBoard logs
      progress.csv         SB3's training log
      learning_curve.csv   agent and baseline evaluations on the same seeds
      checkpoints/         periodic model and VecNormalize statistics (resume from the last)
      best_model.zip       the best model by evaluation return (+ best_vecnormalize.pkl)
      final_model.zip      the model at the end (+ vecnormalize.pkl)

Hyperparameters follow rl-baselines3-zoo's files (``configs/ppo.yml``): a mapping from env
id to plain YAML (``n_envs``, ``n_timesteps``, ``normalize``, ``policy_kwargs`` and the
algorithm's own keyword arguments); nothing is ``eval``'d, and unknown keys are rejected.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import difflib
import inspect
import json
import math
import os
import platform
import shlex
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from soft_snake_gym.agents import ZOO, TrainedPolicy, _find_model, latest_checkpoint, load_trained, zoo_path  # noqa: F401 - moved to agents (issue 10)
from soft_snake_gym.config import CONFIG_DIR, ConfigError, _Loader, load_yaml
from soft_snake_gym.params import plain_number

__all__ = [
    "zoo_path",
    "TrainConfig",
    "TrainedPolicy",
    "load_train_config",
    "train",
    "load_trained",
    "ALGOS",
    "ACTIVATIONS",
]

ALGOS = ("PPO", "SAC")
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")
DEFAULT_BASELINES = {"SoftEel-v0": "pid", "SoftWorm-v0": "inching-pid"}
CONFIGS = CONFIG_DIR / "algorithm"


@dataclass(frozen=True)
class TrainConfig:
    """One training run.

    Attributes:
        env_id: the environment (``SoftEel-v0``, ``SoftWorm-v0``).
        algo: ``PPO`` or ``SAC``.
        n_envs: parallel environments.
        n_timesteps: total environment steps.
        normalize: wrap the envs in ``VecNormalize`` (observations and rewards).
        vec_env: ``dummy`` (one process), ``subproc`` (one process per env) or ``batched``
            (every env in one compiled call, :class:`soft_snake_gym.sb3.SoftVecEnv`).
        policy: the SB3 policy class name.
        policy_kwargs: plain YAML; ``activation_fn`` is a name in :data:`ACTIVATIONS`.
        env_kwargs: keywords for ``gym.make`` (the env's own arguments).
        hyperparams: the algorithm's keyword arguments (``learning_rate``, ``gamma``...).
        seed: seeds the algorithm and the training envs.
        eval_freq: evaluate every this many environment steps (0: never).
        eval_episodes: episodes per evaluation, on seeds ``eval_seed, eval_seed + 1, ...``.
        eval_seed: first evaluation seed.
        checkpoint_freq: save a checkpoint every this many environment steps.
        baseline: the baseline policy spec evaluated once per run on the same seeds
            (``none`` to skip).
    """

    env_id: str
    algo: str = "PPO"
    n_envs: int = 8
    n_timesteps: int = 1_000_000
    normalize: bool = True
    vec_env: str = "dummy"
    policy: str = "MlpPolicy"
    policy_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    hyperparams: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    eval_freq: int = 50_000
    eval_episodes: int = 5
    eval_seed: int = 1000
    checkpoint_freq: int = 50_000
    baseline: str = "default"

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ConfigError(f"algo = {self.algo!r} is not supported; use one of {', '.join(ALGOS)}")
        for name, lo in (("n_envs", 1), ("n_timesteps", 1), ("eval_episodes", 1), ("eval_freq", 0),
                         ("checkpoint_freq", 0), ("seed", 0), ("eval_seed", 0)):
            value = plain_number(getattr(self, name), integer=True)
            if value is None or value < lo:
                raise ConfigError(f"{name} = {getattr(self, name)!r} must be an integer >= {lo}")
            object.__setattr__(self, name, value)
        if self.vec_env not in ("dummy", "subproc", "batched"):
            raise ConfigError(f"vec_env = {self.vec_env!r} must be 'dummy', 'subproc' or 'batched'")
        if not isinstance(self.normalize, bool):
            raise ConfigError(f"normalize = {self.normalize!r} must be true or false")
        act = self.policy_kwargs.get("activation_fn")
        if act is not None and act not in ACTIVATIONS:
            raise ConfigError(f"policy_kwargs.activation_fn = {act!r} must be one of {', '.join(ACTIVATIONS)}")
        _check_hyperparams(self.algo, self.hyperparams)

    @property
    def baseline_spec(self) -> str | None:
        """The baseline to score against, or None."""
        if self.baseline == "none":
            return None
        if self.baseline == "default":
            return DEFAULT_BASELINES.get(self.env_id)
        return self.baseline

    def to_yaml_dict(self) -> dict[str, Any]:
        """The zoo-style mapping ``{env_id: {...}}`` of this config."""
        data = dataclasses.asdict(self)
        env_id = data.pop("env_id")
        hyper = data.pop("hyperparams")
        return {env_id: {**data, **hyper}}


_RUN_KEYS = {f.name for f in dataclasses.fields(TrainConfig)} - {"env_id", "hyperparams"}


def _algo_class(algo: str):
    import stable_baselines3 as sb3

    return getattr(sb3, algo)


#: Allowed values of the documented hyperparameters: name -> (low, high, low open, integer,
#: meaning); ``None`` is unbounded.
HYPER_RANGES: dict[str, tuple[float | None, float | None, bool, bool, str]] = {
    "learning_rate": (0.0, None, True, False, "the optimizer's step size"),
    "gamma": (0.0, 1.0, False, False, "the discount factor"),
    "gae_lambda": (0.0, 1.0, False, False, "the GAE factor"),
    "clip_range": (0.0, None, True, False, "PPO's clipping of the policy ratio"),
    "ent_coef": (0.0, None, False, False, "the entropy bonus weight"),
    "vf_coef": (0.0, None, False, False, "the value loss weight"),
    "max_grad_norm": (0.0, None, True, False, "the gradient clipping norm"),
    "n_steps": (1, None, False, True, "steps per env per rollout"),
    "batch_size": (2, None, False, True, "the minibatch size"),
    "n_epochs": (1, None, False, True, "passes over each rollout"),
    "tau": (0.0, 1.0, True, False, "SAC's target update rate"),
    "buffer_size": (1, None, False, True, "the replay buffer size"),
    "learning_starts": (0, None, False, True, "steps before SAC learns"),
    "train_freq": (1, None, False, True, "steps between SAC updates"),
}


def _check_range(key: str, value: Any) -> None:
    """Raise ``ConfigError`` unless hyperparameter ``key`` is within :data:`HYPER_RANGES`."""
    lo, hi, lo_open, integer, meaning = HYPER_RANGES[key]
    number = plain_number(value, integer=integer)
    allowed = f"{'(' if lo_open else '['}{lo}, {'inf)' if hi is None else f'{hi}]'}"
    kind = "an integer" if integer else "a number"
    if number is None or not math.isfinite(number) or (number <= lo if lo_open else number < lo) or (
        hi is not None and number > hi
    ):
        raise ConfigError(f"hyperparameter {key} = {value!r} must be {kind} in {allowed} ({meaning})")


def _check_hyperparams(algo: str, hyper: dict[str, Any]) -> None:
    params = inspect.signature(_algo_class(algo).__init__).parameters
    reserved = {"self", "policy", "env", "policy_kwargs", "seed", "tensorboard_log", "verbose",
                "_init_setup_model", "device"}
    valid = sorted(set(params) - reserved)
    for key, value in hyper.items():
        if key not in valid:
            close = difflib.get_close_matches(key, valid + sorted(_RUN_KEYS), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ConfigError(f"unknown hyperparameter {key!r} for {algo}{hint}")
        if isinstance(value, str) and key not in ("gradient_steps",):
            raise ConfigError(
                f"hyperparameter {key} = {value!r} is a string; give a number (schedules and "
                "code are not evaluated from YAML)"
            )
        if key in HYPER_RANGES:
            _check_range(key, value)
        elif key == "gradient_steps" and (plain_number(value, integer=True) is None or value == 0 or value < -1):
            raise ConfigError(
                f"hyperparameter gradient_steps = {value!r} must be an integer >= 1, or -1 (as many as "
                "steps collected)"
            )


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``base`` updated by ``over``; nested mappings merge key by key."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def load_train_config(env_id: str, algo: str = "PPO", path: str | Path | None = None,
                      overrides: dict[str, Any] | None = None) -> TrainConfig:
    """The run configuration for ``env_id`` from a zoo-style YAML file and overrides.

    Args:
        env_id: the key to read in the file.
        algo: selects the default file ``configs/<algo>.yml`` shipped in the package.
        path: another YAML file of the same layout.
        overrides: run settings or hyperparameters that win over the file
            (``{"n_timesteps": 1000, "learning_rate": 1e-4}``).

    Raises:
        ConfigError: a missing or malformed file, an env id the file lacks, unknown keys.
    """
    path = Path(path) if path is not None else CONFIGS / f"{algo.lower()}.yml"
    data = load_yaml(path)
    if env_id not in data:
        known = ", ".join(map(str, data)) or "none"
        raise ConfigError(f"{path.name} has no section for env id {env_id!r} (it has: {known})")
    section = data[env_id]
    if not isinstance(section, dict):
        raise ConfigError(f"{path.name}: the section {env_id!r} must be a mapping of keys to values")
    merged = _deep_merge({"algo": algo, **section}, overrides or {})
    run = {k: v for k, v in merged.items() if k in _RUN_KEYS}
    hyper = {k: v for k, v in merged.items() if k not in _RUN_KEYS}
    for key in ("n_timesteps", "eval_freq", "checkpoint_freq"):
        if isinstance(run.get(key), float) and float(run[key]).is_integer():
            run[key] = int(run[key])  # 2.0e6 in YAML
    return TrainConfig(env_id=env_id, hyperparams=hyper, **run)


# --- environments ---------------------------------------------------------------------------
def _check_env_id(env_id: str) -> None:
    import gymnasium as gym

    from soft_snake_gym.envs import register_envs

    register_envs()
    if env_id not in gym.registry:
        ours = [k for k in gym.registry if k.startswith("Soft")]
        close = difflib.get_close_matches(env_id, list(gym.registry), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ConfigError(f"environment id {env_id!r} does not exist{hint} (this package has {', '.join(ours)})")


def make_train_env(cfg: TrainConfig, seed: int):
    """The vectorized training env (Monitor-wrapped, seeded ``seed, seed + 1, ...``)."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if cfg.vec_env == "batched":
        from soft_snake_gym.sb3 import SoftVecEnv

        return SoftVecEnv(cfg.env_id, n_envs=cfg.n_envs, seed=seed, **dict(cfg.env_kwargs))
    cls = SubprocVecEnv if cfg.vec_env == "subproc" else DummyVecEnv
    return make_vec_env(cfg.env_id, n_envs=cfg.n_envs, seed=seed, env_kwargs=dict(cfg.env_kwargs),
                        vec_env_cls=cls)


def _policy_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    import torch.nn as nn

    kwargs = dict(cfg.policy_kwargs)
    act = kwargs.pop("activation_fn", None)
    if act is not None:
        kwargs["activation_fn"] = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU,
                                   "leaky_relu": nn.LeakyReLU}[act]
    if "net_arch" in kwargs and isinstance(kwargs["net_arch"], dict):
        kwargs["net_arch"] = {k: list(v) for k, v in kwargs["net_arch"].items()}
    return kwargs


# --- trained policies as plain predict() objects --------------------------------------------
class TrainedPolicy:
    """A trained SB3 model with its ``VecNormalize`` observation statistics, behaving like
    the baselines: ``predict`` takes raw observations, so it runs through the same
    evaluation as any controller."""

    def __init__(self, model: Any, obs_rms: Any | None, clip_obs: float = 10.0, epsilon: float = 1e-8,
                 name: str = "trained") -> None:
        self.model = model
        self.obs_rms = obs_rms
        self.clip_obs = clip_obs
        self.epsilon = epsilon
        self.name = name
        self.observation_space = model.observation_space
        self.action_space = model.action_space

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_rms is None:
            return obs
        return np.clip((obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon),
                       -self.clip_obs, self.clip_obs).astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        return self.model.predict(self.normalize(np.asarray(observation)), state, episode_start,
                                  deterministic)

    def __repr__(self) -> str:
        return f"TrainedPolicy({self.name})"


def _find_model(path: Path) -> tuple[Path, Path | None]:
    """The model zip and its VecNormalize statistics for a run folder or a zip."""
    if path.is_dir():
        for name, stats in (("best_model.zip", "best_vecnormalize.pkl"),
                            ("final_model.zip", "vecnormalize.pkl"),
                            ("model.zip", "vecnormalize.pkl")):
            if (path / name).is_file():
                return path / name, (path / stats if (path / stats).is_file() else None)
        ckpt = latest_checkpoint(path)
        if ckpt is not None:
            return ckpt
        raise ConfigError(
            f"run folder {str(path)!r} holds no model (best_model.zip, final_model.zip or a checkpoint)"
        )
    if not path.is_file():
        raise ConfigError(f"model {str(path)!r} does not exist; give a run folder or a .zip written by training")
    for stats in (path.with_name(path.stem.replace("model", "vecnormalize") + ".pkl"),
                  path.parent / "vecnormalize.pkl"):
        if stats.is_file() and stats != path:
            return path, stats
    return path, None


def load_trained(path: str | Path, env: Any) -> TrainedPolicy:
    """Load a trained agent from a run folder or a model zip (with the VecNormalize
    statistics saved beside it) as a :class:`TrainedPolicy`.

    Raises:
        ConfigError: nothing loadable at ``path``.
        PolicyEnvMismatch: the model does not fit ``env``.
    """
    import pickle

    from soft_snake_gym.policies import load_model

    model_path, stats_path = _find_model(Path(path))
    model = load_model(model_path, env)
    obs_rms, clip = None, 10.0
    if stats_path is not None:
        with open(stats_path, "rb") as fh:
            vn = pickle.load(fh)
        if getattr(vn, "norm_obs", True):
            obs_rms, clip = vn.obs_rms, vn.clip_obs
    return TrainedPolicy(model, obs_rms, clip, name=str(path))


ZOO = Path(__file__).resolve().parent / "zoo"


def zoo_path(env_id: str, algo: str) -> Path:
    """The folder of the agent shipped with the package for ``env_id`` and ``algo``."""
    path = ZOO / env_id / algo.lower()
    if not (path / "model.zip").is_file():
        shipped = sorted(f"zoo:{p.name} on {p.parent.name}" for p in ZOO.glob("*/*") if (p / "model.zip").is_file())
        raise ConfigError(
            f"no shipped {algo.lower()} agent for {env_id}; shipped agents: {', '.join(shipped) or 'none'}"
        )
    return path


def latest_checkpoint(run_dir: Path) -> tuple[Path, Path | None] | None:
    """The newest checkpoint of a run folder (model zip, VecNormalize pickle or None)."""
    ckpts = sorted((run_dir / "checkpoints").glob("model_*_steps.zip"),
                   key=lambda p: int(p.stem.split("_")[1]))
    if not ckpts:
        return None
    model = ckpts[-1]
    stats = model.with_name(f"vecnormalize_{model.stem.split('_')[1]}_steps.pkl")
    return model, (stats if stats.is_file() else None)


# --- callbacks ------------------------------------------------------------------------------
def _make_callbacks(cfg: TrainConfig, run_dir: Path, started: float, stage_start: int = 0):
    """Checkpoints and the baseline evaluation; ``wall_s`` counts from ``started``; the best
    model is the best evaluation since ``stage_start`` (returns of a curriculum's earlier
    stages used other rewards)."""
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    from soft_snake_gym.evaluation import evaluate, make_eval_env, summarize
    from soft_snake_gym.agents import make_policy

    class Checkpoint(BaseCallback):
        """Model and VecNormalize statistics at every multiple of ``checkpoint_freq``
        environment steps (counted from the run's start, so a resumed run keeps the grid;
        the first step at or past the multiple when ``n_envs`` does not divide it)."""

        def _on_training_start(self) -> None:
            self.last = self.num_timesteps

        def _on_step(self) -> bool:
            freq = cfg.checkpoint_freq
            if freq and self.num_timesteps // freq > self.last // freq:
                save_checkpoint(self.model, run_dir, started)
                self.last = self.num_timesteps
            return True

    class BaselineEval(BaseCallback):
        """Scores the agent every ``eval_freq`` steps and the baseline once, on the same
        seeds with the same metrics; logs both and appends them to learning_curve.csv."""

        def __init__(self):
            super().__init__()
            self.last = -1
            self.best = -math.inf
            self.baseline: dict[str, tuple[float, float]] | None = None
            self.env = make_eval_env(cfg.env_id, n_envs=1, seed=cfg.eval_seed, env_kwargs=cfg.env_kwargs)
            spec = cfg.baseline_spec  # made now, so a bad spec fails before any training
            self.baseline_policy = make_policy(spec, self.env) if spec is not None and cfg.eval_freq else None
            self.csv = run_dir / "learning_curve.csv"
            if self.csv.is_file():  # resumed: keep the best so far and the baseline line
                with open(self.csv) as fh:
                    rows = list(csv.DictReader(fh))
                stage = [float(r["return_mean"]) for r in rows if int(r["timesteps"]) > stage_start]
                if stage:
                    self.best = max(stage)

        def _score(self, policy) -> dict[str, tuple[float, float]]:
            self.env.seed(cfg.eval_seed)
            return summarize(evaluate(policy, self.env, episodes=cfg.eval_episodes))

        def _on_step(self) -> bool:
            freq = cfg.eval_freq
            if not freq or (self.last >= 0 and self.num_timesteps // freq <= self.last // freq):
                return True
            self.last = self.num_timesteps
            if self.baseline is None and self.baseline_policy is not None:
                self.baseline = self._score(self.baseline_policy)
            vn = self.model.get_vec_normalize_env()
            agent = TrainedPolicy(self.model, vn.obs_rms if vn is not None else None,
                                  vn.clip_obs if vn is not None else 10.0)
            scores = self._score(agent)
            row = {"timesteps": self.num_timesteps, "wall_s": round(time.time() - started, 1)}
            for key in ("return", "average_speed", "cost_of_transport"):
                row[f"{key}_mean"], row[f"{key}_std"] = scores.get(key, (math.nan, math.nan))
                self.logger.record(f"eval/{key}", row[f"{key}_mean"])
                if self.baseline is not None:
                    row[f"baseline_{key}"] = self.baseline.get(key, (math.nan,))[0]
                    self.logger.record(f"eval/baseline_{key}", row[f"baseline_{key}"])
            new = not self.csv.is_file()
            with open(self.csv, "a", newline="") as fh:
                writer = csv.DictWriter(fh, fieldnames=list(row))
                if new:
                    writer.writeheader()
                writer.writerow(row)
            if row["return_mean"] > self.best:
                self.best = row["return_mean"]
                self.model.save(run_dir / "best_model.zip")
                if vn is not None:
                    vn.save(str(run_dir / "best_vecnormalize.pkl"))
            return True

        def _on_training_end(self) -> None:
            if cfg.eval_freq and self.last != self.num_timesteps:
                self.last = -1
                self._on_step()

    return CallbackList([Checkpoint(), BaselineEval()])


@contextlib.contextmanager
def _signals_held():
    """Ctrl-C and SIGTERM wait until the block ends (a save is never cut in half); on
    platforms without ``pthread_sigmask`` the block runs as is."""
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)  # a held signal is delivered here


def save_checkpoint(model, run_dir: Path, started: float | None = None) -> Path:
    """Save the model and its VecNormalize statistics under ``checkpoints/``; with
    ``started`` (the run's ``time.time()`` origin) also the wall time so far, so that a
    resumed run's learning curve continues the clock (``checkpoints/wall_s.json``).

    Each file is written under a temporary name and renamed, with Ctrl-C and SIGTERM held
    meanwhile: an interrupt never leaves a half-written checkpoint for ``--resume`` to find.
    """
    ckdir = run_dir / "checkpoints"
    ckdir.mkdir(parents=True, exist_ok=True)
    steps = model.num_timesteps
    path = ckdir / f"model_{steps}_steps.zip"
    with _signals_held():
        partial = ckdir / f"model_{steps}_steps.partial.zip"
        model.save(partial)
        vn = model.get_vec_normalize_env()
        if vn is not None:
            stats = ckdir / f"vecnormalize_{steps}_steps.pkl"
            vn.save(str(stats.with_suffix(".partial")))
            os.replace(stats.with_suffix(".partial"), stats)
        os.replace(partial, path)
        if started is not None:
            walls = _checkpoint_walls(run_dir)
            walls[str(steps)] = round(time.time() - started, 1)
            (ckdir / "wall_s.json").write_text(json.dumps(walls, indent=1) + "\n")
    return path


def _checkpoint_walls(run_dir: Path) -> dict[str, float]:
    """Training wall time [s] at each checkpoint, by step count."""
    path = run_dir / "checkpoints" / "wall_s.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def steps_per_iteration(cfg: TrainConfig) -> int:
    """Environment steps SB3 takes between two checks of the total: a whole rollout of
    ``n_steps x n_envs`` for PPO, ``train_freq x n_envs`` for SAC. ``learn`` stops at the first
    multiple of this at or past the total asked for."""
    defaults = inspect.signature(_algo_class(cfg.algo).__init__).parameters
    key = "n_steps" if cfg.algo == "PPO" else "train_freq"
    per_env = cfg.hyperparams.get(key, defaults[key].default)
    return int(per_env if isinstance(per_env, int) else 1) * cfg.n_envs


def planned_steps(cfg: TrainConfig, start: int = 0) -> int:
    """The step count a run reaches when it trains from ``start`` towards ``cfg.n_timesteps``:
    ``n_timesteps`` rounded up to whole iterations (:func:`steps_per_iteration`) counted from
    ``start``; ``start`` itself if it is already there."""
    chunk = steps_per_iteration(cfg)
    remaining = cfg.n_timesteps - start
    return start + (-(-remaining // chunk) * chunk if remaining > 0 else 0)


class Terminated(KeyboardInterrupt):
    """Training stopped by SIGTERM (a scheduler or ``kill``): handled as Ctrl-C, a checkpoint
    is saved first."""


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """Within the block, SIGTERM raises :class:`Terminated` (once; a repeat is ignored while
    the checkpoint is written). Outside the main thread, signals stay as they are."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise Terminated(f"stopped by signal {signal.Signals(signum).name}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


# --- the run --------------------------------------------------------------------------------
NO_CHECKOUT = "none: the package is not a git checkout (an installed copy); see soft_snake_gym's version"


def _git_commit(package_dir: Path | None = None) -> str:
    """The commit of the git checkout the package runs from, or :data:`NO_CHECKOUT` when it
    runs from an installed copy (``pip install .``) or git is missing. A checkout counts only
    if it tracks the package itself, not merely encloses it (a venv inside another repo)."""
    where = package_dir or Path(__file__).resolve().parent
    try:
        tracked = subprocess.run(["git", "ls-files", "--error-unmatch", "__init__.py"], cwd=where,
                                 capture_output=True, text=True, timeout=5)
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True,
                              timeout=5)
    except (OSError, subprocess.SubprocessError):
        return NO_CHECKOUT
    if tracked.returncode != 0 or head.returncode != 0 or not head.stdout.strip():
        return NO_CHECKOUT
    return head.stdout.strip()


def _is_new_stage(cfg: TrainConfig, run_dir: Path) -> bool:
    """True if ``cfg`` changes settings other than ``n_timesteps`` of the run's config.yaml."""
    path = run_dir / "config.yaml"

    def settings(data: dict[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in next(iter(data.values())).items() if k != "n_timesteps"}

    return path.is_file() and settings(load_yaml(path)) != settings(cfg.to_yaml_dict())


def _record_resume(cfg: TrainConfig, run_dir: Path, command: list[str] | None) -> bool:
    """Append the resuming command to command.txt. If settings other than ``n_timesteps``
    changed (a curriculum: ``--resume DIR --hyperparams ...``), keep the earlier config.yaml
    as config.<k>.yaml and return True: a new stage begins."""
    path = run_dir / "config.yaml"
    new_stage = _is_new_stage(cfg, run_dir)
    if new_stage:
        k = 1
        while (run_dir / f"config.{k}.yaml").exists():
            k += 1
        path.rename(run_dir / f"config.{k}.yaml")
    path.write_text(yaml.safe_dump(cfg.to_yaml_dict(), sort_keys=False))
    with open(run_dir / "command.txt", "a") as fh:
        fh.write(shlex.join(command if command is not None else sys.argv) + "\n")
    return new_stage


#: The files a run writes: a folder holding only these and no checkpoint may be reused.
RUN_FILES = ("config.yaml", "command.txt", "meta.json", "tb", "progress.csv", "learning_curve.csv",
             "learning_curve.png", "checkpoints", "best_model.zip", "best_vecnormalize.pkl",
             "final_model.zip", "vecnormalize.pkl")


def _check_new_run_dir(run_dir: Path) -> None:
    """A new run may start in a missing or empty folder, or in a folder of a run that left no
    checkpoint (it failed or was stopped before its first one)."""
    if not run_dir.exists():
        return
    if not run_dir.is_dir():
        raise ConfigError(f"run folder {str(run_dir)!r} is a file; choose another --run-dir")
    if latest_checkpoint(run_dir) is not None:
        raise ConfigError(
            f"run folder {str(run_dir)!r} already holds a run with checkpoints; "
            "pass --resume to continue it or choose another --run-dir"
        )
    other = sorted(p.name for p in run_dir.iterdir()
                   if p.name not in RUN_FILES and not (p.name.startswith(("config.", "progress."))))
    if other:
        raise ConfigError(
            f"run folder {str(run_dir)!r} is not empty and not a run folder (it holds {', '.join(other[:3])}"
            f"{', ...' if len(other) > 3 else ''}); choose another --run-dir"
        )


def _clear_run_files(run_dir: Path) -> None:
    """Remove what an earlier run without checkpoints left, so the logs do not mix runs."""
    import shutil

    if not run_dir.is_dir():
        return
    for p in run_dir.iterdir():
        if p.name in RUN_FILES or p.name.startswith(("config.", "progress.")):
            shutil.rmtree(p) if p.is_dir() else p.unlink()


def _write_run_files(cfg: TrainConfig, run_dir: Path, command: list[str] | None) -> None:
    import gymnasium
    import stable_baselines3
    import torch

    import soft_snake_gym

    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.yaml").write_text(yaml.safe_dump(cfg.to_yaml_dict(), sort_keys=False))
    (run_dir / "command.txt").write_text(shlex.join(command if command is not None else sys.argv) + "\n")
    meta = {
        "soft_snake_gym": soft_snake_gym.__version__,
        "git_commit": _git_commit(),
        "python": platform.python_version(),
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    (run_dir / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")


def _make_logger(run_dir: Path):
    """SB3's logger writing progress.csv into the run folder and TensorBoard into tb/; a
    resumed run moves the earlier progress.csv aside (progress.1.csv, ...) instead of
    overwriting it."""
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat

    csv_path = run_dir / "progress.csv"
    if csv_path.is_file():
        k = 1
        while (run_dir / f"progress.{k}.csv").exists():
            k += 1
        csv_path.rename(run_dir / f"progress.{k}.csv")
    return Logger(str(run_dir), [CSVOutputFormat(str(csv_path)), TensorBoardOutputFormat(str(run_dir / "tb"))])


def train(cfg: TrainConfig, run_dir: str | Path, resume: bool = False, progress: bool = True,
          command: list[str] | None = None) -> Path:
    """Train (or, with ``resume``, continue) a run in ``run_dir``; returns the final model path.

    Everything is checked (env keywords, hyperparameters, the baseline, the folder) before the
    run folder is written. A new run may use a missing or empty folder, or one whose earlier
    run left no checkpoint. Training stops at :func:`planned_steps` (the total rounded up to
    whole rollouts). An interrupt (Ctrl-C, or SIGTERM from a scheduler or ``kill``) saves a
    checkpoint before the exception propagates (:class:`Terminated` for SIGTERM); a killed
    run resumes from its last periodic checkpoint.

    Raises:
        ConfigError: an unknown env id, a resume folder without a checkpoint, a folder that
            holds another run, a config that SB3 or the env rejects.
    """
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    _check_env_id(cfg.env_id)
    run_dir = Path(run_dir)
    started = time.time()
    torch.set_num_threads(1)  # small MLPs: threads cost more than they give on 2 cores
    algo = _algo_class(cfg.algo)
    if resume:
        found = latest_checkpoint(run_dir) if run_dir.is_dir() else None
        if found is None:
            raise ConfigError(
                f"cannot resume {str(run_dir)!r}: it has no checkpoint (checkpoints/model_*_steps.zip); "
                "start a new run without --resume (the same --run-dir may be reused)"
            )
        model_path, stats_path = found
        if cfg.normalize and stats_path is None:
            raise ConfigError(f"checkpoint {model_path.name} has no VecNormalize statistics beside it")
        steps = int(model_path.stem.split("_")[1])
        started -= _checkpoint_walls(run_dir).get(str(steps), 0.0)  # the clock continues
        env = make_train_env(cfg, seed=cfg.seed + 7919 * (1 + steps))
        if cfg.normalize:
            env = VecNormalize.load(str(stats_path), env)
        model = algo.load(model_path, env=env, device="cpu")
    else:
        _check_new_run_dir(run_dir)
        env = make_train_env(cfg, seed=cfg.seed)
        if cfg.normalize:
            env = VecNormalize(env, gamma=cfg.hyperparams.get("gamma", 0.99))
        try:
            model = algo(cfg.policy, env, policy_kwargs=_policy_kwargs(cfg), seed=cfg.seed, device="cpu",
                         verbose=0, **cfg.hyperparams)
        except (TypeError, ValueError, AssertionError) as err:
            env.close()
            raise ConfigError(f"{cfg.algo} rejected the configuration: {err}") from None
    try:
        stage_start = model.num_timesteps if resume and _is_new_stage(cfg, run_dir) else 0
        callbacks = _make_callbacks(cfg, run_dir, started, stage_start)  # checks the baseline
        if resume:  # every check passed: now the folder is written
            _record_resume(cfg, run_dir, command)
        else:
            _clear_run_files(run_dir)
            _write_run_files(cfg, run_dir, command)
        model.set_logger(_make_logger(run_dir))
        steps = planned_steps(cfg, model.num_timesteps) - model.num_timesteps
        with _sigterm_as_interrupt():
            try:
                if steps > 0:
                    model.learn(steps, callback=callbacks, reset_num_timesteps=not resume,
                                progress_bar=progress)
            except KeyboardInterrupt:
                save_checkpoint(model, run_dir, started)
                raise
    finally:
        env.close()
    final = run_dir / "final_model.zip"
    model.save(final)
    vn = model.get_vec_normalize_env()
    if vn is not None:
        vn.save(str(run_dir / "vecnormalize.pkl"))
    save_checkpoint(model, run_dir, started)
    return final


# --- command line ---------------------------------------------------------------------------
def _parse_overrides(items: list[str] | None) -> dict[str, Any]:
    """``key=value`` pairs; values are YAML scalars or lists (``net_arch=[128,128]``), dotted
    keys reach ``policy_kwargs`` and ``env_kwargs`` (``policy_kwargs.log_std_init=-0.5``)."""
    from soft_snake_gym.cli import CLIError

    out: dict[str, Any] = {}
    for item in items or []:
        key, eq, text = item.partition("=")
        if not eq or not key.strip():
            raise CLIError(f"--hyperparams {item!r} is not key=value; write e.g. --hyperparams gamma=0.999")
        try:
            value = yaml.load(text, Loader=_Loader)  # noqa: S506 - SafeLoader subclass; reads 1e-3
        except yaml.YAMLError:
            raise CLIError(f"--hyperparams {item!r}: {text!r} is not a YAML value") from None
        node = out
        parts = key.strip().split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return out


def _train_arguments(p) -> None:
    p.add_argument("env_id", nargs="?", default="SoftEel-v0", help="environment id (default SoftEel-v0)")
    p.add_argument("--algo", default="PPO", type=str.upper, choices=ALGOS, help="algorithm (default PPO)")
    p.add_argument("--config", metavar="YAML",
                   help="zoo-style hyperparameter file keyed by env id (default: the package's "
                        "configs/<algo>.yml)")
    p.add_argument("--hyperparams", nargs="+", metavar="KEY=VALUE",
                   help="override run settings or hyperparameters, e.g. gamma=0.999 n_envs=4")
    p.add_argument("--n-timesteps", type=int, help="total environment steps (overrides the config)")
    p.add_argument("--seed", type=int, help="seed (overrides the config)")
    p.add_argument("--run-dir", metavar="DIR", help="run folder (default runs/<env>_<algo>_s<seed>)")
    p.add_argument("--resume", metavar="DIR", help="continue the run in DIR from its last checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _step_plan(cfg: TrainConfig, start: int) -> str:
    """``for 4,096 steps (3,000 rounded up to whole rollouts of 512 x 8 steps)``, and where the
    checkpoints land when ``n_envs`` does not divide ``checkpoint_freq``."""
    end = planned_steps(cfg, start)
    chunk = steps_per_iteration(cfg)
    what = "rollouts of n_steps x n_envs" if cfg.algo == "PPO" else "iterations of train_freq x n_envs"
    text = f"from step {start:,} to {end:,}" if start else f"for {end:,} steps"
    if end != max(cfg.n_timesteps, start):
        text += f" ({cfg.n_timesteps:,} rounded up to whole {what} = {chunk:,} steps)"
    freq = cfg.checkpoint_freq
    if freq and freq % cfg.n_envs:
        text += (f"; checkpoints at the first step at or past each multiple of {freq:,} (the {cfg.n_envs} "
                 f"envs step together)")
    return text


def _train(args) -> int:
    from soft_snake_gym.cli import CLIError

    overrides = _parse_overrides(args.hyperparams)
    for key in ("n_timesteps", "seed"):
        if getattr(args, key) is not None:
            overrides[key] = getattr(args, key)
    if args.resume:
        run_dir = Path(args.resume)
        if args.run_dir or args.config:
            raise CLIError("--resume continues a run with its own config.yaml; drop --run-dir and --config")
        if not (run_dir / "config.yaml").is_file():
            raise CLIError(f"cannot resume {str(run_dir)!r}: it has no config.yaml (is it a run folder?)")
        saved = load_yaml(run_dir / "config.yaml")
        env_id = next(iter(saved))
        algo = saved[env_id].get("algo", "PPO")
        cfg = load_train_config(env_id, algo, run_dir / "config.yaml", overrides)
    else:
        _check_env_id(args.env_id)
        cfg = load_train_config(args.env_id, args.algo, args.config, overrides)
        run_dir = Path(args.run_dir or f"runs/{cfg.env_id}_{cfg.algo}_s{cfg.seed}")
    found = latest_checkpoint(run_dir) if args.resume and run_dir.is_dir() else None
    start = int(found[0].stem.split("_")[1]) if found else 0
    print(f"training {cfg.algo} on {cfg.env_id} {_step_plan(cfg, start)} with {cfg.n_envs} envs "
          f"-> {run_dir}" + (" (resumed)" if args.resume else ""))
    t0 = time.time()
    try:
        final = train(cfg, run_dir, resume=bool(args.resume), progress=not args.no_progress)
    except KeyboardInterrupt as err:
        how = "terminated (SIGTERM)" if isinstance(err, Terminated) else "interrupted"
        print(f"{how}; a checkpoint was saved. Continue with: soft-snake train --resume {run_dir}",
              file=sys.stderr)
        return 143 if isinstance(err, Terminated) else 130
    wall = time.time() - t0
    print(f"done in {wall:.0f} s; final model {final}")
    curve = run_dir / "learning_curve.csv"
    if curve.is_file():
        with open(curve) as fh:
            last = list(csv.DictReader(fh))[-1]
        line = (f"last evaluation at {last['timesteps']} steps: return {float(last['return_mean']):.4g}, "
                f"average speed {float(last['average_speed_mean']):.4g} m/s")
        if "baseline_return" in last:
            line += (f" (baseline {cfg.baseline_spec}: return {float(last['baseline_return']):.4g}, "
                     f"average speed {float(last['baseline_average_speed']):.4g} m/s)")
        print(line)
    print(f"evaluate it with: soft-snake evaluate {cfg.env_id} --policy {run_dir}")
    return 0


def _register() -> None:
    from soft_snake_gym.cli import subcommand

    subcommand("train", "train an SB3 agent (PPO or SAC) with YAML hyperparameters; resumable",
               _train_arguments)(_train)


_register()


def plot_learning_curve(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Plot a run's learning_curve.csv: the agent's average speed and cost of transport
    (mean ± std over the evaluation episodes) against environment steps, with the baseline's
    figures on the same seeds as horizontal lines. Written next to the CSV by default."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run_dir = Path(run_dir)
    with open(run_dir / "learning_curve.csv") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise ConfigError(f"{run_dir / 'learning_curve.csv'} has no evaluations yet")
    cfg = load_train_config(next(iter(load_yaml(run_dir / "config.yaml"))), path=run_dir / "config.yaml")
    steps = np.array([int(r["timesteps"]) for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, label in ((axes[0], "average_speed", "average speed [m/s]"),
                           (axes[1], "cost_of_transport", "cost of transport [-]")):
        mean = np.array([float(r[f"{key}_mean"]) for r in rows])
        std = np.array([float(r[f"{key}_std"]) for r in rows])
        ax.plot(steps, mean, "o-", ms=3, label=f"{cfg.algo} agent")
        ax.fill_between(steps, mean - std, mean + std, alpha=0.25)
        if f"baseline_{key}" in rows[0]:
            ax.axhline(float(rows[0][f"baseline_{key}"]), color="C3", ls="--",
                       label=f"baseline ({cfg.baseline_spec})")
        ax.set_xlabel("environment steps")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend()
    axes[1].set_ylim(bottom=0)
    fig.suptitle(f"{cfg.env_id}: evaluation on {cfg.eval_episodes} fixed seeds every {cfg.eval_freq} steps")
    fig.tight_layout()
    out = Path(out) if out is not None else run_dir / "learning_curve.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
