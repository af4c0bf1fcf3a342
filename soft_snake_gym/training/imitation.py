"""Warm start by imitation: the new agent first copies a baseline controller, then PPO improves it.

``imitate: decentralized`` in a training config (``--hyperparams imitate=decentralized``) runs
the baseline for ``imitate_episodes`` episodes on the run's env (seeds ``eval_seed + 10000 ...``,
apart from the evaluation's), with Gaussian noise of ``IMITATION_NOISE`` on the executed
actions so that the data covers states off the teacher's own path (the recorded labels are
the teacher's noiseless actions); sets the ``VecNormalize`` observation and return statistics
from that data and keeps them fixed for the rest of the run (statistics updated from PPO's noisy
rollouts drifted and, with them, the copied behaviour: the segment eel stopped within 200k
agent-steps even at a learning rate of 1e-12); and fits the policy's mean action to the teacher's
(mean squared error) and the value function to the discounted normalized returns. Nothing of
the teacher is kept: PPO then trains the network as any other. On ``SoftEelSegments-v0`` each agent's observation and
action is one sample, so the shared local policy learns what every node's controller does.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from soft_snake_gym.agents import make_policy
from soft_snake_gym.evaluation import make_eval_env
from soft_snake_gym.training.config import TrainConfig

__all__ = ["IMITATION_NOISE", "imitate"]

IMITATION_NOISE = 0.05
"""Standard deviation of the noise on the executed actions while recording the teacher [-]."""


def _record(cfg: TrainConfig, obs_dim: int, act_dim: int, gamma: float) -> dict[str, np.ndarray]:
    """The teacher's episodes: observations, actions, rewards and discounted returns, one row per agent step."""
    env = make_eval_env(cfg.env_id, n_envs=1, seed=cfg.eval_seed + 10000, env_kwargs=cfg.env_kwargs)
    teacher = make_policy(cfg.imitate, env)
    rng = np.random.default_rng(cfg.seed)
    obs_rows, act_rows, returns, raw_returns = [], [], [], []
    rewards_all = []
    for episode in range(cfg.imitate_episodes):
        env.seed(cfg.eval_seed + 10000 + episode)
        obs = env.reset()
        state, start, done = None, np.ones(1, bool), False
        ep_rewards = []
        while not done:
            action, state = teacher.predict(obs, state, start, deterministic=True)
            start = np.zeros(1, bool)
            obs_rows.append(np.asarray(obs, dtype=np.float32).reshape(-1, obs_dim))
            act_rows.append(np.clip(np.asarray(action, dtype=np.float32).reshape(-1, act_dim), -1, 1))
            noisy = np.clip(action + rng.normal(0.0, IMITATION_NOISE, np.shape(action)), -1, 1)
            obs, reward, dones, infos = env.step(noisy.astype(np.float32))
            info = infos[0]
            ep_rewards.append(np.atleast_1d(info.get("agent_rewards", reward)).astype(np.float64))
            done = bool(dones[0])
        r = np.array(ep_rewards)  # (T, agents)
        rewards_all.append(r)
        g = np.zeros_like(r)
        run = np.zeros(r.shape[1])
        for t in range(len(r) - 1, -1, -1):
            run = r[t] + gamma * run
            g[t] = run
        raw_returns.append(g)
    env.close()
    # VecNormalize's return statistics: the running discounted return ret_t = gamma ret_(t-1) + r_t
    forward = []
    for r in rewards_all:
        ret = np.zeros(r.shape[1])
        for t in range(len(r)):
            ret = gamma * ret + r[t]
            forward.append(ret.copy())
    returns = np.concatenate(raw_returns)
    return {
        "obs": np.concatenate(obs_rows),
        "act": np.concatenate(act_rows),
        "returns": returns.reshape(-1),
        "forward": np.concatenate(forward).reshape(-1),
    }


def imitate(model: Any, cfg: TrainConfig, epochs: int = 30, batch_size: int = 1024) -> dict[str, float]:
    """Fit ``model``'s policy (and value) to the baseline ``cfg.imitate``; returns the final losses.

    Args:
        model: a new SB3 PPO model on the run's (``VecNormalize``-wrapped) env.
        cfg: the run's config (``imitate``, ``imitate_episodes``, ``env_id``, ``env_kwargs``).
        epochs: passes over the recorded data.
        batch_size: samples per gradient step.
    """
    import torch  # here, not above: torch takes seconds to import

    obs_dim = int(np.prod(model.observation_space.shape))
    act_dim = int(np.prod(model.action_space.shape))
    gamma = float(model.gamma)
    data = _record(cfg, obs_dim, act_dim, gamma)
    vn = model.get_vec_normalize_env()
    obs = data["obs"].astype(np.float64)
    scale = 1.0
    if vn is not None:
        vn.obs_rms.mean = obs.mean(axis=0)
        vn.obs_rms.var = obs.var(axis=0)
        vn.obs_rms.count = float(len(obs))
        vn.ret_rms.mean = 0.0
        vn.ret_rms.var = float(np.var(data["forward"]))
        vn.ret_rms.count = float(len(data["forward"]))
        # and they stay: the copied controller is a feedback law on the normalized observation, and
        # the on-policy data with exploration noise moves the statistics, the moved statistics move
        # the behaviour, and so on until the eel stops (at a learning rate of 1e-12, too)
        vn.training = False
        obs = np.clip(
            (obs - vn.obs_rms.mean) / np.sqrt(vn.obs_rms.var + vn.epsilon), -vn.clip_obs, vn.clip_obs
        )
        scale = 1.0 / np.sqrt(vn.ret_rms.var + vn.epsilon)
    x = torch.as_tensor(obs, dtype=torch.float32)
    y = torch.as_tensor(data["act"], dtype=torch.float32)
    v = torch.as_tensor(data["returns"] * scale, dtype=torch.float32)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=1e-3)
    rng = np.random.default_rng(cfg.seed)
    n = len(x)
    losses = {"action_mse": float("nan"), "value_mse": float("nan")}
    for _ in range(epochs):
        order = torch.as_tensor(rng.permutation(n))
        for start in range(0, n, batch_size):
            idx = order[start : start + batch_size]
            features = policy.extract_features(x[idx], policy.pi_features_extractor)
            latent_pi, latent_vf = policy.mlp_extractor(features)
            mean = policy.action_net(latent_pi)
            value = policy.value_net(latent_vf).squeeze(-1)
            action_loss = torch.mean((mean - y[idx]) ** 2)
            value_loss = torch.mean((value - v[idx]) ** 2)
            optimizer.zero_grad()
            (action_loss + value_loss).backward()  # separate networks: the sum trains each fully
            optimizer.step()
            losses = {"action_mse": action_loss.item(), "value_mse": value_loss.item()}
    return losses
