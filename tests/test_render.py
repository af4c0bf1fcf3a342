"""Rendering of the environments: headless rgb_array frames, human mode, video."""

from __future__ import annotations

import math
import sys

import gymnasium as gym
import numpy as np
import pytest

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.gaits import serpenoid, serpenoid_phase

BODY_RGB = np.array([0x1F, 0x4E, 0x79])  # the body's colour in render.py
HEAD_RGB = np.array([0xD6, 0x27, 0x28])
STUCK_RGB = np.array([0xFF, 0x7F, 0x0E])


def mask(frame, rgb, tol=40):
    return np.abs(frame.astype(int) - rgb).sum(axis=-1) < tol


def swim(env, steps, alpha=math.pi / 4, omega=math.pi):
    u = env.unwrapped
    n = u.N - 2
    for _ in range(steps):
        _, kd = serpenoid(serpenoid_phase(u.sim.time + 0.5 * u.dt, n, omega, 2 * math.pi / n), omega, alpha)
        env.step((kd / u.max_curvature_rate).astype(np.float32))


def test_rgb_array_frame_is_a_drawn_body_that_moves_while_swimming():
    env = gym.make("SoftEel-v0", render_mode="rgb_array", initial_shape="serpenoid", reset_noise_scale=0.0)
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.shape == (360, 480, 3)
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 20  # not blank
    body0, head0 = mask(first, BODY_RGB), mask(first, HEAD_RGB)
    assert body0.sum() > 500 and head0.sum() > 10
    # the body is drawn where the simulator puts it: the view is centred on the centre of mass,
    # so the head marker sits right of the centre by (head - com) at 2 body lengths per width
    sim = env.unwrapped.sim
    px_per_m = 480 / (2 * sim.config.rod.length)
    head_col = np.argwhere(head0)[:, 1].mean()
    assert head_col == pytest.approx(240 + (sim.x[-1, 0] - sim.com[0]) * px_per_m, abs=4)

    swim(env, 60)
    second = env.render()
    body1, head1 = mask(second, BODY_RGB), mask(second, HEAD_RGB)
    assert body1.sum() > 500
    iou = (body0 & body1).sum() / (body0 | body1).sum()
    assert iou < 0.5, f"the drawn body barely changed (IoU {iou:.2f})"
    assert np.abs(np.argwhere(head1).mean(axis=0) - np.argwhere(head0).mean(axis=0)).max() > 5
    assert not np.array_equal(first, second)
    env.close()


def test_worm_frame_renders_on_ground_colour():
    env = gym.make("SoftWorm-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    water = gym.make("SoftEel-v0", render_mode="rgb_array")
    water.reset(seed=0)
    corner, corner_water = frame[200, 5], water.render()[200, 5]
    assert not np.array_equal(corner, corner_water)
    assert mask(frame, BODY_RGB).sum() > 500
    assert mask(frame, STUCK_RGB).sum() == 0  # nothing has stuck before the first step
    for _ in range(100):  # at rest on the ground, the nodes stick
        _, _, _, _, info = env.step(np.zeros(9, dtype=np.float32))
    assert info["stuck"].sum() >= 5
    assert mask(env.render(), STUCK_RGB).sum() > 20 * (info["stuck"].sum() - 1)


def test_render_without_a_mode_warns_and_returns_none():
    env = gym.make("SoftEel-v0").unwrapped
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


@pytest.mark.skipif(sys.platform != "linux", reason="display detection by environment variables")
def test_human_mode_without_a_display_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="needs a display.*rgb_array"):
        gym.make("SoftEel-v0", render_mode="human")


def test_human_mode_with_a_display_but_no_window_backend_is_a_clear_error(monkeypatch):
    import matplotlib

    monkeypatch.setenv("DISPLAY", ":99")
    previous = matplotlib.get_backend()
    matplotlib.use("agg")  # as MPLBACKEND=agg, or no usable display, would choose
    try:
        with pytest.raises(RuntimeError, match="interactive matplotlib backend.*'agg'.*rgb_array"):
            gym.make("SoftEel-v0", render_mode="human")
    finally:
        matplotlib.use(previous)


def test_record_video_writes_an_episode(tmp_path):
    pytest.importorskip("moviepy")
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(
        gym.make("SoftEel-v0", render_mode="rgb_array", max_episode_steps=20),
        video_folder=str(tmp_path / "videos"),
        episode_trigger=lambda ep: True,
        disable_logger=True,
    )
    env.reset(seed=0)
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(env.action_space.sample() * 0.2)
        done = term or trunc
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
