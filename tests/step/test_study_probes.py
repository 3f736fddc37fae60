"""The study's probe ids (penny_env/presets/envs.yaml, PennyProbe*): the grid is complete, the
target distribution keeps its documented heading offset, and the open plane's invariants that
make two probes impossible there hold in the simulator."""
import numpy as np
import pytest
import gymnasium as gym

import penny_env  # noqa: F401
from penny_env.envs import ConfigError, PennyEnv, PennyVectorEnv, env_ids, resolve
from penny_env.envs.core import seed_keys
from penny_env.envs.scene import env_presets

PROBES = ("Steer", "Drive", "Both")
TABLES = ("Plane", "Ellipse-Elastic", "Ellipse-Plastic", "Ellipse-E05",
          "Stadium-Elastic", "Stadium-Plastic", "Stadium-E05")


def test_probe_grid_is_complete():
    ids = {i for i in env_ids() if i.startswith("PennyProbe")}
    assert ids == {f"PennyProbe{p}-{t}-v0" for p in PROBES for t in TABLES}
    for i in ids:
        scene, task = resolve(**env_presets()[i])
        probe, table = i[len("PennyProbe"):-3].split("-", 1)
        assert scene.actuation == {"Steer": "steer", "Drive": "drive", "Both": "both"}[probe]
        assert task.kind == ("reach" if probe == "Drive" else "park")
        kind = table.split("-")[0].lower()
        assert scene.table["kind"] == ("none" if kind == "plane" else kind)
        if kind != "plane":
            law = table.split("-")[1]
            assert scene.law == {"Elastic": "elastic", "Plastic": "plastic", "E05": 0.5}[law]


@pytest.mark.parametrize("table", ["Plane", "Ellipse-E05", "Stadium-Plastic"])
def test_drive_probe_targets_off_the_heading_line(table):
    env_id = f"PennyProbeDrive-{table}-v0"
    venv = PennyVectorEnv(1, **env_presets()[env_id])
    core = venv._core
    S, target, _ = core.draw_episodes(seed_keys(np.arange(4096)), 0)
    off = np.abs((target[0] - S[0]) * np.sin(S[3]) - (target[1] - S[1]) * np.cos(S[3]))
    assert off.min() >= 0.03
    assert np.all(S[4] == 0) and np.all(S[5] == 0)
    # the targets stay in the documented region (target_fraction of the spawn ellipse, shrunk)
    ax, ay = venv.scene.spawn_axes()
    assert np.all((target[0] / ax) ** 2 + (target[1] / ay) ** 2 <= core.k.target_scale ** 2 * (1 + 1e-12))
    venv.close()


def test_heading_offset_leaves_other_draws_alone():
    a = PennyEnv("ellipse", "reach", actuation="drive")
    b = PennyEnv("ellipse", "reach", actuation="drive", heading_offset=0.03)
    for seed in range(20):
        a.reset(seed=seed)
        b.reset(seed=seed)
        assert np.array_equal(a.state, b.state)


def test_heading_offset_validated():
    with pytest.raises(ConfigError, match="heading_offset"):
        PennyEnv("stadium", "reach", heading_offset=0.2)
    with pytest.raises(ConfigError, match="heading_offset"):
        PennyEnv("stadium", "reach", heading_offset=-0.01)


def test_plane_invariants_behind_the_impossible_probes():
    """Proven on the plane (no impacts): steer only keeps theta_dot, drive only keeps phi_dot
    and so the heading line; the simulator agrees under random actions."""
    rng = np.random.default_rng(0)
    steer = gym.make("PennyProbeSteer-Plane-v0").unwrapped
    steer.reset(seed=1)
    W0 = steer.state[4]
    for _ in range(200):
        _, _, term, trunc, _ = steer.step(rng.uniform(-1, 1, 1))
        assert steer.state[4] == pytest.approx(W0, rel=1e-12) and not term
    drive = gym.make("PennyProbeDrive-Plane-v0").unwrapped
    drive.reset(seed=2)
    s0 = drive.state
    for _ in range(200):
        _, _, term, trunc, _ = drive.step(rng.uniform(-1, 1, 1))
        s = drive.state
        assert s[5] == 0.0 and s[3] == s0[3] and not term
        assert abs((s[0] - s0[0]) * np.sin(s0[3]) - (s[1] - s0[1]) * np.cos(s0[3])) < 1e-12


def test_walls_break_the_invariants():
    """On a table an impact changes theta_dot (steer probe) and phi_dot (drive probe)."""
    rng = np.random.default_rng(0)
    for env_id, k in (("PennyProbeSteer-Ellipse-Plastic-v0", 4), ("PennyProbeDrive-Stadium-Elastic-v0", 5)):
        env = gym.make(env_id).unwrapped
        env.reset(seed=0)
        v0, changed = env.state[k], False
        for _ in range(2000):
            a = rng.uniform(-1, 1, 1) if k == 4 else np.ones(1)
            _, _, term, trunc, info = env.step(a)
            if info["impacts"]:
                changed = env.state[k] != v0
                break
            if term or trunc:
                env.reset()
                v0 = env.state[k]
        assert changed, env_id


def test_park_probes_need_both_speeds_at_rest():
    # the "come to rest (both speeds under tolerances)": a penny on the target with
    # |R theta_dot| under speed_tolerance but spinning (|phi_dot| >= spin_tolerance) has not parked
    for probe in ("Steer", "Both"):
        env = gym.make(f"PennyProbe{probe}-Ellipse-Elastic-v0")
        core = env.unwrapped._core
        assert core.task.spin_tolerance == 0.5
        for w, parked in ((0.0, True), (0.45, True), (0.6, False), (-3.0, False)):
            env.reset(seed=1, options={"state": (0.0, 0.0, 0.0, 0.0, 0.0, w), "target": (0.0, 0.0)})
            _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
            assert terminated == parked and info["is_success"] == parked, (probe, w)
    # PennyPark-* keep their rest as before: no spin bound
    env = gym.make("PennyPark-Stadium-v0")
    assert env.unwrapped._core.task.spin_tolerance is None
    env.reset(seed=1, options={"state": (0.0, 0.0, 0.0, 0.0, 0.0, -3.0), "target": (0.0, 0.0)})
    assert env.step(np.zeros(env.action_space.shape, np.float32))[2]


@pytest.mark.parametrize("bad,err", [(0.0, ConfigError), (-1.0, ConfigError), (float("inf"), ConfigError),
                                     ("0.5", TypeError)])
def test_spin_tolerance_validated(bad, err):
    with pytest.raises(err, match="spin_tolerance"):
        PennyEnv("ellipse", "park", spin_tolerance=bad)
