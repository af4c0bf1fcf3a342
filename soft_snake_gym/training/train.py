"""``train()``: one Stable-Baselines3 run (PPO or SAC) in a run folder, new or resumed."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from soft_snake_gym.agents import zoo_path
from soft_snake_gym.config import ConfigError
from soft_snake_gym.envs.registration import importable_id
from soft_snake_gym.training.callbacks import make_callbacks
from soft_snake_gym.training.config import TrainConfig, _algo_class, check_env_id, planned_steps
from soft_snake_gym.training.imitation import imitate
from soft_snake_gym.training.run import (
    _check_new_run_dir,
    _checkpoint_walls,
    _clear_run_files,
    _is_new_stage,
    _make_logger,
    _record_resume,
    _write_run_files,
    latest_checkpoint,
    save_checkpoint,
    sigterm_as_interrupt,
)

__all__ = ["init_from", "make_train_env", "policy_kwargs", "torch_for_learning", "train"]


def make_train_env(cfg: TrainConfig, seed: int):
    """The vectorized training env (Monitor-wrapped, seeded ``seed, seed + 1, ...``)."""
    # here, not above: SB3 and torch take seconds to import (soft_snake_gym.sb3 imports SB3)
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if cfg.env_id == "SoftEelSegments-v0":  # every agent a slot: one shared local policy
        from soft_snake_gym.sb3 import SegmentVecEnv

        if cfg.vec_env != "batched":
            raise ConfigError(
                f"vec_env = {cfg.vec_env!r}: SoftEelSegments-v0 trains on the batched segment adapter; "
                "set vec_env: batched"
            )
        try:
            return SegmentVecEnv(cfg.n_envs, seed=seed, **dict(cfg.env_kwargs))
        except ValueError as err:
            raise ConfigError(str(err)) from None
    if cfg.vec_env == "batched":
        from soft_snake_gym.sb3 import SoftVecEnv

        return SoftVecEnv(cfg.env_id, n_envs=cfg.n_envs, seed=seed, **dict(cfg.env_kwargs))
    cls = SubprocVecEnv if cfg.vec_env == "subproc" else DummyVecEnv
    return make_vec_env(
        importable_id(cfg.env_id),
        n_envs=cfg.n_envs,
        seed=seed,
        env_kwargs=dict(cfg.env_kwargs),
        vec_env_cls=cls,
    )


def policy_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    """The run's ``policy_kwargs`` as SB3 takes them (activation names become torch classes).

    Adam runs fused (one kernel over all the parameters instead of about a dozen tensor
    operations each) unless ``optimizer_kwargs.fused`` is false: at the PPO settings of
    ``SoftEel-v0`` the update is 1.14x faster and ``learn`` 1.07x (docs/performance_history.md, "Adam
    fused"). Its digits differ from the unfused Adam's in float32's last place.
    """
    import torch.nn as nn  # here, not above: torch takes seconds to import

    kwargs = dict(cfg.policy_kwargs)
    given = kwargs.get("optimizer_kwargs") or {}  # YAML null: no keywords, as SB3 reads it
    kwargs["optimizer_kwargs"] = {"fused": True, **given}
    act = kwargs.pop("activation_fn", None)
    if act is not None:
        kwargs["activation_fn"] = {
            "tanh": nn.Tanh,
            "relu": nn.ReLU,
            "elu": nn.ELU,
            "leaky_relu": nn.LeakyReLU,
        }[act]
    if "net_arch" in kwargs and isinstance(kwargs["net_arch"], dict):
        kwargs["net_arch"] = {k: list(v) for k, v in kwargs["net_arch"].items()}
    return kwargs


def _source_paths(spec: str) -> tuple[Path, Path | None]:
    """The model zip and its VecNormalize statistics (or None) of an ``init_from`` spec."""
    if spec.startswith("zoo:"):
        path = zoo_path(spec[4:], "ppo")
    else:
        path = Path(spec)
    if path.is_dir():
        model = path / "best_model.zip" if (path / "best_model.zip").is_file() else path / "model.zip"
        stats = [path / "best_vecnormalize.pkl", path / "vecnormalize.pkl"]
    else:
        model, stats = path, [path.with_name("vecnormalize.pkl")]
    if not model.is_file():
        raise ConfigError(
            f"init_from = {spec!r}: no model found at {str(model)!r}; give a model zip, a run folder "
            "or zoo:<env id>"
        )
    return model, next((s for s in stats if s.is_file()), None)


def init_from(model: Any, spec: str) -> None:
    """Start ``model`` (a new SB3 model on its env) from the weights of the agent ``spec``.

    Every parameter of the same name and shape is copied, the exploration noise ``log_std`` too
    (starting the goal task again at ``log_std_init = -1``, a spread 5 times the source's, made the
    eel fold onto itself: 4 % of the training episodes reached the target after 45k steps, against
    9-11 % with the source's spread). A first layer that reads more
    observation entries than the source's (a task that appends entries to the source env's
    observation, as ``SoftEelGoal-v0`` and ``SoftEelPath-v0`` append one to ``SoftEel-v0``'s) gets
    the source's weights for the source's entries and zero for the new ones, so the new agent
    starts acting exactly as the source does on the shared entries. The source's ``VecNormalize``
    observation statistics are copied likewise (the new entries keep theirs), and its return
    statistics whole.

    Raises:
        ConfigError: the source cannot be found or loaded, or its network does not fit.
    """
    import torch  # here, not above: torch takes seconds to import

    model_path, stats_path = _source_paths(spec)
    src = type(model).load(model_path, device="cpu")
    dst_params = model.policy.state_dict()
    for name, value in src.policy.state_dict().items():
        target = dst_params.get(name)
        if target is None:
            raise ConfigError(f"init_from = {spec!r}: its network has {name!r}, which this run's lacks")
        if target.shape == value.shape:
            dst_params[name] = value.clone()
        elif target.ndim == 2 and target.shape[0] == value.shape[0] and target.shape[1] > value.shape[1]:
            grown = torch.zeros_like(target)
            grown[:, : value.shape[1]] = value
            dst_params[name] = grown
        else:
            raise ConfigError(
                f"init_from = {spec!r}: {name} has shape {tuple(value.shape)} there and "
                f"{tuple(target.shape)} here; the networks must match (net_arch) and this run may "
                "only observe more entries, appended"
            )
    model.policy.load_state_dict(dst_params)
    vn = model.get_vec_normalize_env()
    if vn is not None and stats_path is not None:
        import pickle

        with open(stats_path, "rb") as f:
            source = pickle.load(f)
        n = source.obs_rms.mean.shape[0]
        vn.obs_rms.mean[:n] = source.obs_rms.mean
        vn.obs_rms.var[:n] = source.obs_rms.var
        vn.obs_rms.count = source.obs_rms.count
        vn.ret_rms = source.ret_rms


@contextlib.contextmanager
def torch_for_learning() -> Iterator[None]:
    """Torch as :func:`train` runs it; both settings are restored on leaving.

    - One thread: the policies are small MLPs, whose operations threads slow down on 2 cores.
    - ``torch.distributions`` without argument checks: each policy call builds a ``Normal`` and
      would check its mean and standard deviation (and ``log_prob`` its sample) for NaN and
      sign, which is 14 % of a rollout's policy call and 8 % of PPO's ``learn`` at the
      ``SoftEel-v0`` settings (docs/performance_history.md, "Distributions unchecked"). A policy that
      goes NaN is still stopped, with a message, by the env: a NaN action raises ``ValueError``.
    """
    import torch  # here, not above: torch takes seconds to import
    from torch.distributions import Distribution

    threads, checked = torch.get_num_threads(), Distribution._validate_args
    torch.set_num_threads(1)
    Distribution.set_default_validate_args(False)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
        Distribution.set_default_validate_args(checked)


def train(
    cfg: TrainConfig,
    run_dir: str | Path,
    resume: bool = False,
    progress: bool = True,
    command: list[str] | None = None,
    on_eval: Callable[[dict[str, float]], None] | None = None,
) -> Path:
    """Train (or, with ``resume``, continue) a run in ``run_dir``; returns the final model path.

    Everything is checked (env keywords, hyperparameters, the baseline, the folder) before the
    run folder is written. A new run may use a missing or empty folder, or one whose earlier
    run left no checkpoint. Training stops at :func:`planned_steps` (the total rounded up to
    whole rollouts). An interrupt (Ctrl-C, or SIGTERM from a scheduler or ``kill``) saves a
    checkpoint before the exception propagates (:class:`Terminated` for SIGTERM); a killed
    run resumes from its last periodic checkpoint. ``on_eval`` is called with each evaluation's
    learning-curve row (``timesteps``, ``wall_s``, ``<metric>_mean``/``_std``, ``baseline_<metric>``).

    Raises:
        ConfigError: an unknown env id, a resume folder without a checkpoint, a folder that
            holds another run, a config that SB3 or the env rejects.
    """
    check_env_id(cfg.env_id)
    with torch_for_learning():
        return _train(cfg, Path(run_dir), resume, progress, command, on_eval)


def _train(
    cfg: TrainConfig,
    run_dir: Path,
    resume: bool,
    progress: bool,
    command: list[str] | None,
    on_eval: Callable[[dict[str, float]], None] | None,
) -> Path:
    """:func:`train`'s run, under :func:`torch_for_learning`."""
    from stable_baselines3.common.vec_env import VecNormalize  # here: SB3 takes seconds to import

    started = time.time()
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
            model = algo(
                cfg.policy,
                env,
                policy_kwargs=policy_kwargs(cfg),
                seed=cfg.seed,
                device="cpu",
                verbose=0,
                **cfg.hyperparams,
            )
        except (TypeError, ValueError, AssertionError) as err:
            env.close()
            raise ConfigError(f"{cfg.algo} rejected the configuration: {err}") from None
        if cfg.init_from:
            try:
                init_from(model, cfg.init_from)
            except ConfigError:
                env.close()
                raise
    try:
        stage_start = model.num_timesteps if resume and _is_new_stage(cfg, run_dir) else 0
        callbacks = make_callbacks(cfg, run_dir, started, stage_start, on_eval)  # checks the baseline
        if cfg.imitate != "none" and not resume:  # a bad spec raises before the folder is written
            imitate(model, cfg)
        if resume:  # every check passed: now the folder is written
            _record_resume(cfg, run_dir, command)
        else:
            _clear_run_files(run_dir)
            _write_run_files(cfg, run_dir, command)
        model.set_logger(_make_logger(run_dir))
        steps = planned_steps(cfg, model.num_timesteps) - model.num_timesteps
        with sigterm_as_interrupt():
            try:
                if steps > 0:
                    model.learn(
                        steps, callback=callbacks, reset_num_timesteps=not resume, progress_bar=progress
                    )
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
