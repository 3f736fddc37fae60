"""Rendering: frame content where the state says, human mode through pygame, RecordVideo."""
import math
import os

import gymnasium as gym
import numpy as np
import pytest

import penny_env
from penny_env import PennyEnv
from penny_env.envs import rendering as rd

os.environ["SDL_VIDEODRIVER"] = "dummy"


def _px(env, x, y):
    r = env.unwrapped._renderer
    return r.to_pixel(x, y)


@pytest.mark.parametrize("scene", ["ellipse", "stadium", "plane", "circle"])
def test_frame_shows_penny_front_target_and_table(scene):
    env = PennyEnv(scene, "reach", render_mode="rgb_array")
    phi = 0.7
    env.reset(seed=0, options={"state": [0.03, -0.02, 0.0, phi, 0.0, 0.0], "target": [-0.06, 0.05]})
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    R = env.unwrapped._core.R
    x, y = 0.03, -0.02
    # the front end is red, the back half of the penny black, the target blue
    fr, fc = _px(env, x + R * math.cos(phi), y + R * math.sin(phi))
    assert (frame[fr, fc] == rd.FRONT).all()
    br, bc = _px(env, x - 0.7 * R * math.cos(phi), y - 0.7 * R * math.sin(phi))
    assert (frame[br, bc] == rd.PENNY).all()
    tr, tc = _px(env, -0.06, 0.05)
    assert (frame[tr, tc] == rd.TARGET).all()
    # nothing penny-coloured far from the penny
    far = np.ones(frame.shape[:2], bool)
    far[max(br - 25, 0):br + 25, max(bc - 25, 0):bc + 25] = False
    assert not ((frame == rd.FRONT).all(axis=2) & far).any()
    if scene != "plane":
        assert (frame[0, 0] == rd.OUTSIDE).all()
        cr, cc = _px(env, -0.02, -0.06)
        assert (frame[cr, cc] == rd.INSIDE).all()
        # the wall crosses the positive x axis at the table's extent
        wr, wc = _px(env, env.unwrapped._core.table.extent[1], 0.0)
        assert (frame[wr, wc - 1:wc + 2] == rd.WALL).all(axis=1).any()


def test_frames_follow_the_state_and_trail():
    env = gym.make("PennyReach-Ellipse-v0", render_mode="rgb_array")
    env.reset(seed=0, options={"state": [0.0, 0.0, 0.0, 0.0, 15.0, 0.0]})
    for _ in range(6):
        env.step(np.zeros(2, np.float32))
    frame = env.render()
    s = env.unwrapped.state
    R = env.unwrapped._core.R
    fr, fc = _px(env, s[0] + R * math.cos(s[3]), s[1] + R * math.sin(s[3]))
    assert (frame[fr, fc] == rd.FRONT).all()
    r0, c0 = _px(env, 0.0, 0.0)  # the start of the trail
    assert (frame[r0, c0] == rd.TRAIL).all()


def test_impacts_arc_is_drawn():
    env = PennyEnv("circle", "impacts", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    cb, sb = env.unwrapped._arc
    beta = math.atan2(sb, cb)
    for off, color in ((0.3, rd.ARC), (-0.3, rd.ARC), (1.5, rd.WALL)):  # half-width 0.5 rad
        r, c = _px(env, 0.15 * math.cos(beta + off), 0.15 * math.sin(beta + off))
        assert (frame[r - 2:r + 3, c - 2:c + 3] == color).all(axis=2).any()


def test_human_mode_and_render_without_mode():
    env = PennyEnv("circle", "reach", render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))
    assert env.render() is None
    env.close()
    with pytest.raises(ValueError, match="render_mode"):
        PennyEnv(render_mode="ascii")


def test_record_video(tmp_path):
    pytest.importorskip("moviepy")
    env = gym.make("PennySteer-Ellipse-v0", render_mode="rgb_array")
    env = gym.wrappers.RecordVideo(env, str(tmp_path / "videos"), episode_trigger=lambda e: True, disable_logger=True)
    env.reset(seed=0)
    for _ in range(10):
        env.step(env.action_space.sample())
    env.close()
    files = list((tmp_path / "videos").glob("*.mp4"))
    assert files and files[0].stat().st_size > 1000


def test_vector_render():
    venv = penny_env.PennyVectorEnv(2, "stadium", "reach", render_mode="rgb_array")
    venv.reset(seed=0)
    venv.step(np.zeros((2, 2), np.float32))
    frames = venv.render()
    assert len(frames) == 2 and frames[0].dtype == np.uint8
