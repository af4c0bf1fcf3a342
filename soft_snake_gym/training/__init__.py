"""Stable-Baselines3 training.

YAML hyperparameters keyed by env id (:mod:`.config`), run folders and resume (:mod:`.run`), an
evaluation callback that scores the agent against a baseline controller (:mod:`.callbacks`), and
:func:`train` (:mod:`.train`).
"""

from soft_snake_gym.training.config import (
    ACTIVATIONS,
    ALGOS,
    CONFIGS,
    HYPER_RANGES,
    TrainConfig,
    check_env_id,
    load_train_config,
    planned_steps,
    steps_per_iteration,
)
from soft_snake_gym.training.run import (
    NO_CHECKOUT,
    RUN_FILES,
    Terminated,
    latest_checkpoint,
    plot_learning_curve,
    save_checkpoint,
    sigterm_as_interrupt,
    stopped_by,
)
from soft_snake_gym.training.train import make_train_env, policy_kwargs, torch_for_learning, train

__all__ = [
    "ACTIVATIONS",
    "ALGOS",
    "CONFIGS",
    "HYPER_RANGES",
    "NO_CHECKOUT",
    "RUN_FILES",
    "Terminated",
    "TrainConfig",
    "check_env_id",
    "latest_checkpoint",
    "load_train_config",
    "make_train_env",
    "planned_steps",
    "plot_learning_curve",
    "policy_kwargs",
    "save_checkpoint",
    "sigterm_as_interrupt",
    "stopped_by",
    "steps_per_iteration",
    "torch_for_learning",
    "train",
]
