"""The training configuration: zoo-style YAML hyperparameters keyed by env id, checked.

Hyperparameters follow rl-baselines3-zoo's files (``configs/algorithm/ppo.yml``): a mapping from env
id to plain YAML (``n_envs``, ``n_timesteps``, ``normalize``, ``policy_kwargs`` and the
algorithm's own keyword arguments); nothing is ``eval``'d, and unknown keys are rejected.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

from soft_snake_gym.config import CONFIG_DIR, ConfigError, config_path, load_yaml
from soft_snake_gym.envs import register_envs
from soft_snake_gym.params import check_int, check_number, plain_number

__all__ = [
    "ALGOS",
    "ACTIVATIONS",
    "CONFIGS",
    "CURVE_METRICS",
    "HYPER_RANGES",
    "TrainConfig",
    "check_env_id",
    "load_train_config",
    "planned_steps",
    "steps_per_iteration",
]

ALGOS = ("PPO", "SAC")
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")
DEFAULT_BASELINES = {
    "SoftEel-v0": "pid",
    "SoftWorm-v0": "inching-pid",
    "SoftEelGoal-v0": "los",
    "SoftEelPath-v0": "los",
    "SoftEelSegments-v0": "decentralized",
}
CONFIGS = CONFIG_DIR / "algorithm"

#: The metrics (registry names) of each evaluation in a run's learning_curve.csv.
CURVE_METRICS = ("return", "average_speed", "cost_of_transport")


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
        init_from: start a new run from another agent's weights instead of at random: a model
            zip, a run folder, or ``zoo:<env id>`` (the PPO agent shipped for that id); see
            :func:`soft_snake_gym.training.train.init_from`. ``""`` (or None): at random.
        imitate: a baseline spec the new agent first imitates before PPO trains it
            (:mod:`soft_snake_gym.training.imitation`; the ``VecNormalize`` statistics are then
            the baseline's and stay fixed); ``none`` (default): start from scratch.
        imitate_episodes: episodes of the baseline recorded for the imitation.
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
    init_from: str = ""
    imitate: str = "none"
    imitate_episodes: int = 16

    def __post_init__(self) -> None:
        """Check the values, raising ``ConfigError``."""
        if self.algo not in ALGOS:
            raise ConfigError(f"algo = {self.algo!r} is not supported; use one of {', '.join(ALGOS)}")
        for name, lo in (
            ("n_envs", 1),
            ("n_timesteps", 1),
            ("eval_episodes", 1),
            ("eval_freq", 0),
            ("checkpoint_freq", 0),
            ("seed", 0),
            ("eval_seed", 0),
            ("imitate_episodes", 1),
        ):
            value = plain_number(getattr(self, name), integer=True)
            if value is None or value < lo:
                raise ConfigError(f"{name} = {getattr(self, name)!r} must be an integer >= {lo}")
            object.__setattr__(self, name, value)
        if self.init_from is None:  # YAML null, or an empty ``init_from=``: at random, as ""
            object.__setattr__(self, "init_from", "")
        if not isinstance(self.init_from, str):
            raise ConfigError(
                f"init_from = {self.init_from!r} must be a model zip, a run folder or zoo:<env id> "
                "(or empty, to start at random)"
            )
        if not isinstance(self.imitate, str):
            raise ConfigError(
                f"imitate = {self.imitate!r} must be a baseline spec (e.g. decentralized) or none"
            )
        if self.vec_env not in ("dummy", "subproc", "batched"):
            raise ConfigError(f"vec_env = {self.vec_env!r} must be 'dummy', 'subproc' or 'batched'")
        if not isinstance(self.normalize, bool):
            raise ConfigError(f"normalize = {self.normalize!r} must be true or false")
        act = self.policy_kwargs.get("activation_fn")
        if act is not None and act not in ACTIVATIONS:
            raise ConfigError(
                f"policy_kwargs.activation_fn = {act!r} must be one of {', '.join(ACTIVATIONS)}"
            )
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
    import stable_baselines3 as sb3  # here, not above: SB3 and torch take seconds to import

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
    try:
        if integer:
            check_int(f"hyperparameter {key}", value, int(lo), hint=meaning)
        else:
            check_number(f"hyperparameter {key}", value, lo, hi, lo_open=lo_open)
    except ValueError as err:
        raise ConfigError(str(err) if integer else f"{err} ({meaning})") from None


def _check_hyperparams(algo: str, hyper: dict[str, Any]) -> None:
    params = inspect.signature(_algo_class(algo).__init__).parameters
    reserved = {
        "self",
        "policy",
        "env",
        "policy_kwargs",
        "seed",
        "tensorboard_log",
        "verbose",
        "_init_setup_model",
        "device",
    }
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
        elif key == "gradient_steps" and (
            plain_number(value, integer=True) is None or value == 0 or value < -1
        ):
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


def load_train_config(
    env_id: str, algo: str = "PPO", path: str | Path | None = None, overrides: dict[str, Any] | None = None
) -> TrainConfig:
    """The run configuration for ``env_id`` from a zoo-style YAML file and overrides.

    Args:
        env_id: the key to read in the file.
        algo: selects the default file ``configs/algorithm/<algo>.yml`` shipped in the package.
        path: another YAML file of the same layout, or the name of a shipped one.
        overrides: run settings or hyperparameters that win over the file
            (``{"n_timesteps": 1000, "learning_rate": 1e-4}``).

    Raises:
        ConfigError: a missing or malformed file, an env id the file lacks, unknown keys.
    """
    path = config_path(path if path is not None else algo.lower(), "algorithm")
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


def check_env_id(env_id: str) -> None:
    """Raise ``ConfigError`` unless ``env_id`` is a registered Gymnasium id."""
    register_envs()
    if env_id not in gym.registry:
        ours = [k for k in gym.registry if k.startswith("Soft")]
        close = difflib.get_close_matches(env_id, list(gym.registry), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ConfigError(
            f"environment id {env_id!r} does not exist{hint} (this package has {', '.join(ours)})"
        )


def steps_per_iteration(cfg: TrainConfig) -> int:
    """Environment steps SB3 takes between two checks of the total.

    A whole rollout of ``n_steps x n_envs`` for PPO, ``train_freq x n_envs`` for SAC. ``learn``
    stops at the first multiple of this at or past the total asked for.
    """
    defaults = inspect.signature(_algo_class(cfg.algo).__init__).parameters
    key = "n_steps" if cfg.algo == "PPO" else "train_freq"
    per_env = cfg.hyperparams.get(key, defaults[key].default)
    return int(per_env if isinstance(per_env, int) else 1) * cfg.n_envs


def planned_steps(cfg: TrainConfig, start: int = 0) -> int:
    """The step count a run reaches when it trains from ``start`` towards ``cfg.n_timesteps``.

    ``n_timesteps`` rounded up to whole iterations (:func:`steps_per_iteration`) counted from
    ``start``; ``start`` itself if it is already there.
    """
    chunk = steps_per_iteration(cfg)
    remaining = cfg.n_timesteps - start
    return start + (-(-remaining // chunk) * chunk if remaining > 0 else 0)
