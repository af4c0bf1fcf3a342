"""Hyperparameter tuning of PPO with Ray Tune: Optuna's TPE search and an ASHA scheduler.

Each trial is a short :func:`~soft_snake_gym.training.train` run in its own run folder, from the
env's zoo-style config (``configs/algorithm/ppo.yml``) with the sampled values laid over it. It
reports every evaluation (the learning-curve row: the agent on the config's evaluation seeds,
the same for every trial) to Tune, so ASHA stops the trials that trail at the same step count.
The best trial's values become a zoo-style YAML block keyed by env id, which
``soft-snake train --hyperparams-file`` takes as is. An experiment folder that holds an
interrupted tuning run is resumed (Tune's experiment restore); its finished trials are kept
and its unfinished ones continue from their last checkpoint.

The search space (:data:`SEARCH_SPACE`)::

    key                 sampled                                   sets
    learning_rate       log-uniform 1e-5 .. 1e-3                  learning_rate
    n_steps             64, 128, 256, 512, 1024                   n_steps (per env per rollout)
    batch_size          64, 128, 256, 512                         batch_size
    gamma               0.95, 0.98, 0.99, 0.995, 0.999            gamma
    gae_lambda          uniform 0.8 .. 0.99                       gae_lambda
    ent_coef            log-uniform 1e-8 .. 1e-2                  ent_coef
    net_width           32, 64, 128, 256                          policy_kwargs.net_arch (every layer)
    energy_cost_weight  log-uniform 1e-4 .. 3e-2 (only if asked)  env_kwargs.energy_cost_weight

Ray is imported inside the functions that use it (an optional extra, seconds to import).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from soft_snake_gym.config import ConfigError
from soft_snake_gym.distributed import RAY_INSTALL, RayNotInstalled
from soft_snake_gym.tables import read_rows
from soft_snake_gym.training.config import CURVE_METRICS, TrainConfig, check_env_id, load_train_config
from soft_snake_gym.training.run import latest_checkpoint
from soft_snake_gym.training.train import train

__all__ = [
    "DEFAULT_KEYS",
    "METRIC_MODES",
    "SEARCH_SPACE",
    "Param",
    "TuneInterrupted",
    "TuneResult",
    "TuneSettings",
    "ppo_trial",
    "tune_ppo",
]


@dataclass(frozen=True)
class Param:
    """One key of the search space.

    Attributes:
        name: the key (``--search-space``).
        kind: ``"loguniform"``, ``"uniform"`` (``values`` = low, high) or ``"choice"``.
        values: the bounds or the choices.
        meaning: what it sets.
    """

    name: str
    kind: str
    values: tuple[float, ...]
    meaning: str

    def domain(self):
        """The Ray Tune domain to sample from."""
        from ray import tune  # here, not above: Ray is optional and takes seconds to import

        if self.kind == "choice":
            return tune.choice(list(self.values))
        return getattr(tune, self.kind)(*self.values)

    def describe(self) -> str:
        """The sampled values as text, e.g. ``log-uniform 1e-05 .. 0.001``."""
        if self.kind == "choice":
            return ", ".join(f"{v:g}" for v in self.values)
        return f"{self.kind.replace('log', 'log-')} {self.values[0]:g} .. {self.values[1]:g}"


#: Every key of the search space, by name (module docstring: the table).
SEARCH_SPACE: dict[str, Param] = {
    p.name: p
    for p in (
        Param("learning_rate", "loguniform", (1e-5, 1e-3), "PPO's learning_rate"),
        Param("n_steps", "choice", (64, 128, 256, 512, 1024), "PPO's n_steps (per env per rollout)"),
        Param("batch_size", "choice", (64, 128, 256, 512), "PPO's batch_size"),
        Param("gamma", "choice", (0.95, 0.98, 0.99, 0.995, 0.999), "PPO's gamma"),
        Param("gae_lambda", "uniform", (0.8, 0.99), "PPO's gae_lambda"),
        Param("ent_coef", "loguniform", (1e-8, 1e-2), "PPO's ent_coef"),
        Param(
            "net_width", "choice", (32, 64, 128, 256), "the width of every layer of policy_kwargs.net_arch"
        ),
        Param(
            "energy_cost_weight",
            "loguniform",
            (1e-4, 3e-2),
            "the env's energy_cost_weight (env_kwargs); only when asked",
        ),
    )
}

#: The keys tuned unless ``--search-space`` says otherwise: all but the reward's energy weight.
DEFAULT_KEYS = tuple(k for k in SEARCH_SPACE if k != "energy_cost_weight")

#: The metrics a trial can be scored by (learning-curve means) and whether more is better.
METRIC_MODES = {"return": "max", "average_speed": "max", "cost_of_transport": "min"}
assert set(METRIC_MODES) <= set(CURVE_METRICS)


@dataclass(frozen=True)
class TuneSettings:
    """One tuning run, checked before Ray starts.

    Attributes:
        env_id: the environment.
        trials: how many trials (hyperparameter draws).
        trial_steps: environment steps of a trial that ASHA does not stop.
        evals: evaluations (reports to Tune) per trial, every ``trial_steps / evals`` steps.
        keys: the search-space keys tuned (:data:`SEARCH_SPACE`).
        metric: the learning-curve metric scored (:data:`METRIC_MODES`).
        config: a zoo-style hyperparameter YAML file (default: the package's ppo.yml).
        overrides: run settings or hyperparameters laid over the config for every trial (and
            written into the best YAML).
        seed: seeds the TPE sampler (trials train with the config's seed).
        cpus_per_trial: Ray CPUs each trial holds (the workers' thread cap, given to ``connect``).
    """

    env_id: str
    trials: int = 20
    trial_steps: int = 100_000
    evals: int = 4
    keys: tuple[str, ...] = DEFAULT_KEYS
    metric: str = "return"
    config: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    cpus_per_trial: int = 1

    def __post_init__(self) -> None:
        """Check every value, raising ``ConfigError`` (before any Ray work)."""
        check_env_id(self.env_id)
        unknown = [k for k in self.keys if k not in SEARCH_SPACE]
        if unknown or not self.keys:
            what = f"unknown search-space key {unknown[0]!r}" if unknown else "an empty search space"
            raise ConfigError(f"{what}; valid keys: {', '.join(SEARCH_SPACE)}")
        for name, lo in (("trials", 1), ("trial_steps", 1), ("evals", 1), ("seed", 0), ("cpus_per_trial", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise ConfigError(f"{name} = {value!r} must be an integer >= {lo}")
        if self.evals > self.trial_steps:
            raise ConfigError(f"evals = {self.evals} must be at most trial_steps = {self.trial_steps}")
        if self.metric not in METRIC_MODES:
            raise ConfigError(f"metric = {self.metric!r} must be one of {', '.join(METRIC_MODES)}")
        if self.metric == "return" and "energy_cost_weight" in self.keys:
            raise ConfigError(
                "energy_cost_weight changes the reward, so the trials' returns are not comparable; "
                "score them with metric average_speed or cost_of_transport"
            )
        self.trial_config({k: SEARCH_SPACE[k].values[0] for k in self.keys})  # the config loads

    @property
    def eval_freq(self) -> int:
        """Environment steps between a trial's evaluations."""
        return self.trial_steps // self.evals

    def overrides_for(self, params: dict[str, Any]) -> dict[str, Any]:
        """The config overrides of sampled ``params`` (search-space key -> value), user's first."""
        base = load_train_config(self.env_id, "PPO", self.config, self.overrides)
        over: dict[str, Any] = dict(self.overrides)
        for key, value in params.items():
            if key == "net_width":  # every layer this wide; the depth (of pi and vf) is the config's
                arch = base.policy_kwargs.get("net_arch") or [64, 64]
                width = int(value)
                arch = (
                    {k: [width] * len(v) for k, v in arch.items()}
                    if isinstance(arch, dict)
                    else [width] * len(arch)
                )
                over["policy_kwargs"] = {**over.get("policy_kwargs", {}), "net_arch": arch}
            elif key == "energy_cost_weight":
                over["env_kwargs"] = {**over.get("env_kwargs", {}), key: float(value)}
            else:
                over[key] = int(value) if key in ("n_steps", "batch_size") else float(value)
        return over

    def config_for(self, params: dict[str, Any]) -> TrainConfig:
        """The run configuration with sampled ``params`` (its own budget; what the YAML keeps)."""
        return load_train_config(self.env_id, "PPO", self.config, self.overrides_for(params))

    def trial_config(self, params: dict[str, Any]) -> TrainConfig:
        """A trial's configuration: :meth:`config_for`, with the trial's budget and evaluations.

        ``trial_steps`` steps, an evaluation (and a checkpoint, to resume) every
        :attr:`eval_freq` steps, no baseline (only the agent is scored).
        """
        run = {
            "n_timesteps": self.trial_steps,
            "eval_freq": self.eval_freq,
            "checkpoint_freq": self.eval_freq,
            "baseline": "none",
        }
        return load_train_config(self.env_id, "PPO", self.config, {**self.overrides_for(params), **run})


def ppo_trial(params: dict[str, Any], settings: TuneSettings) -> None:
    """One trial, in a Ray worker: train in the trial's folder and report every evaluation.

    A trial of a restored experiment continues its run folder from the last checkpoint.
    """
    from ray import tune  # here, not above: Ray is optional and takes seconds to import

    cfg = settings.trial_config(params)
    # the trial's folder in the experiment folder itself (the CLI's --out, a local path that every
    # node of the cluster shares), not Tune's staging copy, which reaches it only when the driver
    # syncs (every few seconds, and at the end): its learning curve is read live, and its
    # checkpoints are where a restored trial looks for them, whichever node runs it
    run_dir = Path(tune.get_context().get_storage().trial_fs_path) / "run"
    resume = run_dir.is_dir() and latest_checkpoint(run_dir) is not None  # a restored experiment

    def report(row: dict[str, float]) -> None:
        tune.report({k: float(v) for k, v in row.items()})

    train(cfg, run_dir, resume=resume, progress=False, on_eval=report)


class TuneInterrupted(KeyboardInterrupt):
    """The tuning run stopped before every trial ended (Ctrl-C, SIGTERM); Tune saved its state."""


def _trial_dirname(trial) -> str:
    """A trial's folder: ``ppo_trial_<id>`` (Tune's default spells out every sampled value)."""
    return f"{trial.trainable_name}_{trial.trial_id}"


@dataclass(frozen=True)
class TuneResult:
    """What a tuning run found.

    Attributes:
        best_params: the best trial's sampled values (search-space key -> value).
        best_score: its last evaluation's ``<metric>_mean``.
        best_steps: the environment steps it had trained when scored.
        yaml_path: the zoo-style YAML block written for ``soft-snake train --hyperparams-file``.
        trials: every trial that reported: (sampled values, last score, steps trained).
        errors: trials that failed.
        resumed: the experiment folder held an earlier run that was continued.
    """

    best_params: dict[str, Any]
    best_score: float
    best_steps: int
    yaml_path: Path
    trials: list[tuple[dict[str, Any], float, int]]
    errors: int
    resumed: bool


def _settings_record(settings: TuneSettings) -> dict[str, Any]:
    data = dataclasses.asdict(settings)
    data["keys"] = list(settings.keys)
    return data


def tune_ppo(settings: TuneSettings, out_dir: str | Path, verbose: int = 1) -> TuneResult:
    """Tune PPO's hyperparameters on Ray (which must already be connected, or starts locally).

    The experiment lives in ``out_dir`` (Tune's experiment folder: one folder per trial, with its
    run folder ``run/``), beside ``settings.json`` and the result ``best.yml``. If ``out_dir``
    holds an interrupted run with the same settings, it resumes.

    Args:
        settings: the checked tuning settings.
        out_dir: the experiment folder.
        verbose: Tune's console output (0 silent, 1 a status table, 2 every result).

    Raises:
        ConfigError: ``out_dir`` holds a tuning run with other settings, or no trial reported.
        RayNotInstalled: Optuna is missing (the ``ray`` extra installs it).
        TuneInterrupted: interrupted before every trial ended; the same call resumes it.
    """
    from ray import tune  # here, not above: Ray is optional and takes seconds to import
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    try:
        import optuna  # noqa: F401 - OptunaSearch fails later, with an assertion, without it
    except ImportError:
        raise RayNotInstalled(
            f"soft-snake tune needs Optuna, which is not installed; install: {RAY_INSTALL}"
        ) from None
    out_dir = Path(out_dir).resolve()
    record = _settings_record(settings)
    saved = out_dir / "settings.json"
    resumed = tune.Tuner.can_restore(str(out_dir))
    if resumed and saved.is_file() and json.loads(saved.read_text()) != record:
        old = json.loads(saved.read_text())
        diff = ", ".join(f"{k} {old.get(k)!r} -> {v!r}" for k, v in record.items() if old.get(k) != v)
        raise ConfigError(
            f"{out_dir} holds a tuning run with other settings ({diff}); use another output folder "
            "or the same settings to resume it"
        )
    if not resumed and out_dir.is_dir() and any(out_dir.iterdir()):
        raise ConfigError(f"{out_dir} exists and holds no tuning run to resume; choose an empty folder")
    metric = f"{settings.metric}_mean"
    mode = METRIC_MODES[settings.metric]
    trainable = tune.with_resources(
        tune.with_parameters(ppo_trial, settings=settings), {"cpu": settings.cpus_per_trial}
    )
    if resumed:
        tuner = tune.Tuner.restore(str(out_dir), trainable, resume_errored=True)
    else:
        out_dir.mkdir(parents=True, exist_ok=True)
        saved.write_text(json.dumps(record, indent=1))
        tuner = tune.Tuner(
            trainable,
            param_space={k: SEARCH_SPACE[k].domain() for k in settings.keys},
            tune_config=tune.TuneConfig(
                metric=metric,
                mode=mode,
                num_samples=settings.trials,
                search_alg=OptunaSearch(seed=settings.seed),
                scheduler=ASHAScheduler(
                    time_attr="timesteps",
                    max_t=settings.trial_steps,
                    grace_period=settings.eval_freq,
                    reduction_factor=2,
                ),
                trial_dirname_creator=_trial_dirname,
            ),
            run_config=tune.RunConfig(name=out_dir.name, storage_path=str(out_dir.parent), verbose=verbose),
        )
    grid = tuner.fit()  # Ctrl-C: Tune stops the trials, saves its state and returns
    # the saved state tells (the returned grid marks the trials stopped by Ctrl-C terminated)
    state = tune.ExperimentAnalysis(str(out_dir)).trials
    ended = sum(t.status in ("TERMINATED", "ERROR") for t in state)
    if ended < settings.trials:
        raise TuneInterrupted(f"{ended} of {settings.trials} trials ended")
    # each trial scored by the last row of its own learning curve: a report that Ctrl-C cut off
    # is lost to Tune's records (the trial then resumes as finished), not to the trial's CSV
    trials = []
    for r in grid:
        rows = read_rows(Path(r.path) / "run" / "learning_curve.csv")
        last = rows[-1] if rows else None
        if last and math.isfinite(float(last[metric])):
            trials.append(
                ({k: r.config[k] for k in settings.keys}, float(last[metric]), int(last["timesteps"]))
            )
    if not trials:
        raise ConfigError(
            f"no trial reported a score ({grid.num_errors} failed); see the trials in {out_dir}"
        )
    # trials ASHA stopped were scored earlier in training: the best is chosen among the trials
    # that trained longest
    longest = max(steps for _, _, steps in trials)
    finished = [t for t in trials if t[2] >= min(longest, settings.trial_steps)]
    sign = 1.0 if mode == "max" else -1.0
    params, score, steps = max(finished, key=lambda t: sign * t[1])
    path = out_dir / "best.yml"
    write_best_yaml(settings, params, score, steps, len(trials), path)
    return TuneResult(params, score, steps, path, trials, grid.num_errors, resumed)


def write_best_yaml(
    settings: TuneSettings, params: dict[str, Any], score: float, steps: int, n_trials: int, path: Path
) -> None:
    """Write the zoo-style YAML block of ``params`` (keyed by env id) with a comment saying how."""
    cfg = settings.config_for(params)
    first = cfg.eval_seed
    header = (
        f"# soft-snake tune {settings.env_id}: the best of {n_trials} trials (Optuna TPE + ASHA, up to "
        f"{settings.trial_steps:,} steps each),\n"
        f"# {settings.metric} {score:.6g} after {steps:,} steps on evaluation seeds {first}..{first + cfg.eval_episodes - 1}.\n"
        f"# Tuned: {', '.join(f'{k} = {v:.6g}' for k, v in params.items())}.\n"
        f"# Train with: soft-snake train {settings.env_id} --hyperparams-file {path.name}\n"
    )
    body = yaml.safe_dump(cfg.to_yaml_dict(), sort_keys=False, default_flow_style=None)
    path.write_text(header + body)
