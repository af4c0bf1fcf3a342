"""Training callbacks.

Periodic checkpoints, and the evaluation that scores the agent against a baseline controller on the
same seeds (learning_curve.csv, the best model).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

from soft_snake_gym.agents import TrainedPolicy, for_env, make_policy
from soft_snake_gym.evaluation import evaluate, make_eval_env, summarize
from soft_snake_gym.tables import appending, read_rows
from soft_snake_gym.training.config import CURVE_METRICS, TrainConfig
from soft_snake_gym.training.run import save_checkpoint

__all__ = ["make_callbacks"]


def make_callbacks(
    cfg: TrainConfig,
    run_dir: Path,
    started: float,
    stage_start: int = 0,
    on_eval: Callable[[dict[str, float]], None] | None = None,
):
    """Checkpoints and the baseline evaluation.

    ``wall_s`` counts from ``started``; the best model is the best evaluation since ``stage_start``
    (returns of a curriculum's earlier stages used other rewards). ``on_eval`` is called with each
    evaluation's learning_curve.csv row once it is written (``soft-snake tune`` reports it to Tune).
    """
    # here, not above: SB3 and torch take seconds to import
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    class Checkpoint(BaseCallback):
        """Model and VecNormalize statistics at every multiple of ``checkpoint_freq`` environment steps.

        Counted from the run's start, so a resumed run keeps the grid; the first step at or past the
        multiple when ``n_envs`` does not divide it.
        """

        def _on_training_start(self) -> None:
            self.last = self.num_timesteps

        def _on_step(self) -> bool:
            freq = cfg.checkpoint_freq
            if freq and self.num_timesteps // freq > self.last // freq:
                save_checkpoint(self.model, run_dir, started)
                self.last = self.num_timesteps
            return True

    class BaselineEval(BaseCallback):
        """Scores the agent every ``eval_freq`` steps and the baseline once, on the same seeds.

        With the same metrics; logs both and appends them to learning_curve.csv.
        """

        def __init__(self):
            super().__init__()
            self.last = -1
            self.best = -math.inf
            self.baseline: dict[str, tuple[float, float]] | None = None
            self.env = make_eval_env(cfg.env_id, n_envs=1, seed=cfg.eval_seed, env_kwargs=cfg.env_kwargs)
            spec = cfg.baseline_spec  # made now, so a bad spec fails before any training
            self.baseline_policy = make_policy(spec, self.env) if spec is not None and cfg.eval_freq else None
            self.csv = run_dir / "learning_curve.csv"
            # resumed: keep the best so far (a torn last row of a killed run is not read)
            stage = [
                float(r["return_mean"]) for r in read_rows(self.csv) if int(r["timesteps"]) > stage_start
            ]
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
            agent = TrainedPolicy(
                self.model, vn.obs_rms if vn is not None else None, vn.clip_obs if vn is not None else 10.0
            )
            agent = for_env(agent, self.env)  # a local policy on a segment team: every agent runs it
            scores = self._score(agent)
            row = {"timesteps": self.num_timesteps, "wall_s": round(time.time() - started, 1)}
            for key in CURVE_METRICS:
                row[f"{key}_mean"], row[f"{key}_std"] = scores.get(key, (math.nan, math.nan))
                self.logger.record(f"eval/{key}", row[f"{key}_mean"])
                if self.baseline is not None:
                    row[f"baseline_{key}"] = self.baseline.get(key, (math.nan,))[0]
                    self.logger.record(f"eval/baseline_{key}", row[f"baseline_{key}"])
            with appending(self.csv, list(row)) as write:
                write(row)
            if row["return_mean"] > self.best:
                self.best = row["return_mean"]
                self.model.save(run_dir / "best_model.zip")
                if vn is not None:
                    vn.save(str(run_dir / "best_vecnormalize.pkl"))
            if on_eval is not None:
                on_eval(row)
            return True

        def _on_training_end(self) -> None:
            if cfg.eval_freq and self.last != self.num_timesteps:
                self.last = -1
                self._on_step()

    return CallbackList([Checkpoint(), BaselineEval()])
