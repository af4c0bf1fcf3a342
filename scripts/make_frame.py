"""Render the README's frame of SoftEel-v0: docs/img/softeel_frame.png.

The eel starts on the serpenoid and swims 2 s under the open-loop gait (docs/model.md §7), then
one ``rgb_array`` frame is saved. Run from the repository root: ``python scripts/make_frame.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import matplotlib.image
import numpy as np

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.gaits import serpenoid, serpenoid_phase

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "softeel_frame.png"


def main(seconds: float = 2.0, alpha: float = math.pi / 4, omega: float = math.pi) -> Path:
    """Render SoftEel-v0 after ``seconds`` of the serpenoid gait and save the frame; returns its path."""
    env = gym.make(
        "SoftEel-v0",
        render_mode="rgb_array",
        initial_shape="serpenoid",
        serpenoid_alpha=alpha,
        reset_noise_scale=0.0,
    )
    env.reset(seed=0)
    u = env.unwrapped
    n = u.N - 2
    for _ in range(int(round(seconds / u.dt))):
        _, kd = serpenoid(serpenoid_phase(u.sim.time + 0.5 * u.dt, n, omega, 2 * math.pi / n), omega, alpha)
        env.step((kd / u.max_curvature_rate).astype(np.float32))
    frame = env.render()
    env.close()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(OUT, frame)
    return OUT


if __name__ == "__main__":
    print(main())
