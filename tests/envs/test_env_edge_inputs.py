"""Smaller defects of the environments found by extreme inputs (issue 24.6), each in the single and
the vector env: a tiny control_dt, a huge arena, Gymnasium's seed convention, and a step
interrupted by KeyboardInterrupt."""
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import penny_env  # noqa: F401  (registers the ids)
from penny_env import PennyEnv, PennyVectorEnv
from penny_env.envs.core import MAX_RENDER_FPS, render_fps
from penny_env.envs.scene import ConfigError
from penny_env.backends.choice import available

BACKENDS = ["numba", "python"] if available() else ["python"]


def test_tiny_control_dt_has_a_finite_render_fps():
    # control_dt = 5e-324 raised OverflowError (int(round(1 / dt)) of inf)
    assert render_fps(5e-324) == MAX_RENDER_FPS and render_fps(0.05) == 20 and render_fps(10.0) == 1
    for env in (PennyEnv(control_dt=5e-324), PennyVectorEnv(2, control_dt=5e-324)):
        assert env.metadata["render_fps"] == MAX_RENDER_FPS
        env.reset(seed=0)


@pytest.mark.parametrize("arena", [1e300, 1e101, 0.0, -1.0, math.inf])
def test_arena_beyond_its_range_is_refused(arena):
    # arena = 1e300 gave a NaN reward (the squared distance overflowed)
    with pytest.raises(ConfigError, match="scene.arena"):
        PennyEnv("plane", "reach", arena=arena)
    with pytest.raises(ConfigError, match="scene.arena"):
        PennyVectorEnv(2, "plane", "reach", arena=arena)


@pytest.mark.parametrize("arena, match", [
    (1e-9, r"scene\.arena = 1e-09 m is too small for the penny: .* exceed its radius R = 0\.01 m"),
    (0.01, r"scene\.arena = 0\.01 m is too small for the penny"),
    (0.012, r"task\.tolerance = 0\.015 m must be below scene\.arena \(the open plane's length scale\) = 0\.012 m")])
def test_an_arena_below_the_penny_or_the_tolerance_is_refused_naming_the_field(arena, match):
    # a plane arena of 1e-9 m was accepted and its first step paid -5.7e6 (the reward's length scale is the arena)
    with pytest.raises(ConfigError, match=match):
        gym.make("PennyReach-Plane-v0", backend="python", arena=arena)
    with pytest.raises(ConfigError, match=match):
        PennyVectorEnv(2, "plane", "reach", arena=arena, backend="python")
    with pytest.raises(ConfigError, match=r"task\.tolerance = 0\.5 m must be below the table's size = 0\.15 m"):
        PennyEnv("circle", {"kind": "reach", "tolerance": 0.5}, backend="python")


def test_largest_arena_gives_finite_rewards():
    for env in (PennyEnv("plane", "reach", arena=1e100), PennyVectorEnv(2, "plane", "reach", arena=1e100)):
        env.reset(seed=0)
        for _ in range(3):
            r = env.step(env.action_space.sample())[1]
            assert np.all(np.isfinite(r))


@pytest.mark.parametrize("bad, error", [(1.5, TypeError), (True, TypeError), ("3", TypeError), (np.float64(2.0), TypeError),
                                        (-1, ValueError), (2**64, ValueError), (np.bool_(True), TypeError)])
def test_seed_follows_gymnasium_convention(bad, error):
    # the vector env truncated floats, accepted bools, did not name seed for strings and mapped 2**64 to 0
    for env in (PennyEnv(), PennyVectorEnv(2)):
        with pytest.raises(error, match="seed"):
            env.reset(seed=bad)
    with pytest.raises(error, match=r"seed\[1\]"):
        PennyVectorEnv(2).reset(seed=[0, bad])


def test_seed_range_edges():
    env, vec = PennyEnv(), PennyVectorEnv(2)
    env.reset(seed=2**64 - 1)
    vec.reset(seed=2**64 - 2)  # the sub-envs' seeds 2**64 - 2 and 2**64 - 1
    with pytest.raises(ValueError, match="seed"):
        vec.reset(seed=2**64 - 1)  # sub-env 1 would get 2**64
    # distinct seeds, distinct episodes (2**64 used to share the key of 0)
    a = PennyVectorEnv(2)
    a.reset(seed=[0, 2**64 - 1])
    assert not np.array_equal(a.states[0], a.states[1])
    o1, _ = vec.reset(seed=[np.uint64(5), None])
    o2, _ = PennyEnv().reset(seed=5)
    assert np.array_equal(o1[0], o2)


def _interrupting(fn, after):
    """fn, but raising KeyboardInterrupt (as a Ctrl-C would) once it has run, state already changed."""
    def wrapped(*args):
        fn(*args)
        after()
        raise KeyboardInterrupt
    return wrapped


@pytest.mark.parametrize("backend", BACKENDS)
def test_interrupted_vector_step_needs_a_reset(backend):
    # a KeyboardInterrupt mid-step left the vector env between "taken" and "not taken": sub-envs then
    # overran their time limit until reset. Now the next step refuses (ResetNeeded) until a full reset
    vec = PennyVectorEnv(3, max_episode_steps=2, backend=backend)
    vec.reset(seed=0)
    a = np.zeros((3, 2), np.float32)
    vec.step(a)
    step_envs = vec._runner.step_envs  # (the loop the step calls: the serial one, for 3 envs)
    vec._runner.step_envs = _interrupting(step_envs, lambda: None)
    with pytest.raises(KeyboardInterrupt):
        vec.step(a)  # the kernel ran (each episode reached its 2 steps) but the autoreset flags were not set
    vec._runner.step_envs = step_envs
    with pytest.raises(ResetNeeded, match="interrupted"):
        vec.step(a)
    with pytest.raises(ResetNeeded, match="interrupted"):
        vec.reset(options={"reset_mask": np.array([True, False, True])})
    vec.reset(seed=0)
    for _ in range(2):
        _, _, _, trunc, _ = vec.step(a)
    assert trunc.all() and np.all(vec._runner.st.steps == 2)


@pytest.mark.parametrize("backend", BACKENDS)
def test_interrupted_single_step_needs_a_reset(backend):
    env = PennyEnv(backend=backend)
    env.reset(seed=0)
    env_step = env._fns.env_step
    env._fns = env._fns._replace(env_step=_interrupting(env_step, lambda: None))
    with pytest.raises(KeyboardInterrupt):
        env.step(np.zeros(2, np.float32))
    env._fns = env._fns._replace(env_step=env_step)
    with pytest.raises(ResetNeeded, match="interrupted"):
        env.step(np.zeros(2, np.float32))
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))


def test_gym_make_passes_the_checks():
    with pytest.raises(ConfigError, match="arena"):
        gym.make("PennyReach-Plane-v0", arena=1e300)
