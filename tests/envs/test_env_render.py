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
        assert (frame[-1, 0] == rd.OUTSIDE).all()  # (the text line covers the top left)
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
    pytest.importorskip("pygame", reason="pygame-ce (the penny-env[render] extra) is not installed")
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


def _first_impact(env_id, seed=1, max_steps=400):
    """An env (rgb_array) stepped with random actions until a step with an impact."""
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=seed)
    rng = np.random.default_rng(0)
    for _ in range(max_steps):
        _, _, term, trunc, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        if info["impacts"]:
            return env, info
        assert not (term or trunc)
    raise AssertionError("no impact")


def test_impacts_flash_at_the_impact_point_and_fade():
    env, info = _first_impact("PennyImpacts-Stadium-v0")
    u = env.unwrapped
    hud = u._hud
    t_imp, end, st = hud["impacts"][-1]
    assert hud["impact_count"] >= 1 and hud["time"] == pytest.approx(info["time"])
    assert hud["time"] - u.scene.control_dt <= t_imp <= hud["time"]
    R = u._core.R
    px, py = st[0] + end * R * math.cos(st[3]), st[1] + end * R * math.sin(st[3])
    frame = env.render()
    renderer = u._renderer
    plain = renderer.frame(u._s, u._target, list(u._trail), u._arc, dict(hud, impacts=()))
    # the ring (radius >= 4 px around the impact point) is drawn in the flash colour where the plain frame has none
    r, c = renderer.to_pixel(px, py)
    ring = np.zeros(frame.shape[:2], bool)
    rr, cc = np.mgrid[: frame.shape[0], : frame.shape[1]]
    d = np.hypot(rr + 0.5 - (r + 0.5), cc + 0.5 - (c + 0.5))
    ring[(d > 3) & (d < 9)] = True
    changed = (frame != plain).any(axis=2)
    assert changed[ring].sum() >= 10 and not changed[d > 20].any()
    yellowish = (frame[..., 0] > 200) & (frame[..., 1] > 150) & (frame[..., 2] < 120)
    assert (yellowish & ring).sum() >= 10
    # faded out after FLASH_INTERVALS control intervals without impacts (or drawn again for a new impact)
    for _ in range(rd.FLASH_INTERVALS + 1):
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
    recent = [i for i in hud["impacts"] if hud["time"] - i[0] < rd.FLASH_INTERVALS * u.scene.control_dt]
    if not recent:
        later = env.render()
        plain = renderer.frame(u._s, u._target, list(u._trail), u._arc, dict(hud, impacts=()))
        assert np.array_equal(later, plain)


def test_text_line_shows_time_reward_and_impacts():
    env = PennyEnv("stadium", "impacts", render_mode="rgb_array")
    env.reset(seed=0)
    u = env.unwrapped
    env.render()
    r = u._renderer
    args = (u._s, u._target, list(u._trail), u._arc)
    bare = r.frame(*args)
    a = r.frame(*args, {"time": 1.25, "reward": -0.5, "impact_count": 3})
    b = r.frame(*args, {"time": 2.5, "reward": -0.5, "impact_count": 3})
    assert rd.hud_text({"time": 1.25, "reward": -0.5, "impact_count": 3}) == "T 1.25 S   REWARD -0.500   IMPACTS 3"
    top = (slice(0, 7 * rd.TEXT_SCALE), slice(0, r.W))
    white = (a[top] == rd.TEXT).all(axis=2)
    assert white.sum() > 100 and not (bare[top] == rd.TEXT).all(axis=2).any()
    assert not np.array_equal(a[top], b[top])  # the time is drawn
    assert np.array_equal(a[7 * rd.TEXT_SCALE:], bare[7 * rd.TEXT_SCALE:])  # the text stays in its line
    # every character the line can hold has a glyph
    for hud in ({"time": 1234.5, "reward": -1e-3, "impact_count": 0}, {"time": 0.0, "reward": float("nan")}):
        assert set(rd.hud_text(hud)) <= set(rd._GLYPHS), rd.hud_text(hud)
    # the env's own frames carry the line after a step
    env.step(np.zeros(2, np.float32))
    assert (env.render()[top] == rd.TEXT).all(axis=2).sum() > 100


def test_human_mode_opens_the_display_only_and_warns_once_without_one(monkeypatch):
    pygame = pytest.importorskip("pygame", reason="pygame-ce (the penny-env[render] extra) is not installed")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setattr(rd, "_warned_no_display", False)
    env = PennyEnv("circle", "reach", render_mode="human")
    with pytest.warns(UserWarning, match="no display"):
        env.reset(seed=0)
    assert pygame.display.get_init() and not pygame.mixer.get_init()
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env.step(np.zeros(2, np.float32))  # warned once, not at every frame
        other = PennyEnv("circle", "reach", render_mode="human")
        other.reset(seed=0)
        other.close()
    env.close()
