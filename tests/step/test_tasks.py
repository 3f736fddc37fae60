"""Tasks are records in a registry (penny_env/step/tasks/): a task from outside the package is one module and a
preset (tests/step/example_task.py), checked when it is registered, run by the single and the vector env on every
backend, and trainable; the built-in tasks' draws equal the numpy implementation they replaced."""
import math
import re
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import gymnasium as gym
import numpy as np
import pytest

from penny_env import PennyEnv, PennyVectorEnv
from penny_env.backends.choice import available
from penny_env import register_task
from penny_env.step.tasks import TASKS, Task, TaskRecord
from penny_env.step.tasks import reach

needs_numba = pytest.mark.skipif(not available(), reason="numba is not installed")
HURRY = {"kind": "hurry", "max_episode_steps": 50, "tolerance": 0.02, "time_cost": 0.05}


@pytest.fixture(scope="module")
def hurry():
    import tests.step.example_task  # noqa: F401  (registers "hurry")
    yield TASKS["hurry"]


def test_an_outside_task_runs_in_every_env_and_backend(hurry):
    envs = [PennyEnv("ellipse", HURRY, backend=b) for b in ("python", "numba")]
    vec = [PennyVectorEnv(3, "ellipse", HURRY, backend=b) for b in ("python", "numba")]
    for e in envs + vec:
        assert e.observation_space.shape[-1] == 11 and e.observation_space.low[..., 10].max() == 0.0
    obs = [e.reset(seed=4)[0] for e in envs] + [v.reset(seed=4)[0][0] for v in vec]
    assert all(np.array_equal(obs[0], o) for o in obs)
    rng = np.random.default_rng(0)
    for t in range(1, 30):
        a = rng.uniform(-1, 1, 2)
        outs = [e.step(a) for e in envs] + [v.step(np.tile(a, (3, 1))) for v in vec]
        for o in outs[1:2]:
            assert np.array_equal(o[0], outs[0][0]) and o[1] == outs[0][1]
        for o in outs[2:]:
            assert np.array_equal(o[0][0], outs[0][0]) and o[1][0] == outs[0][1]
        if outs[0][2]:
            break
        assert outs[0][0][10] == np.float32(t / 50)  # the task's own observation entry: its clock


def test_an_outside_task_trains_for_a_few_steps(hurry):
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    from penny_env.sb3 import PennySB3VecEnv
    torch.set_num_threads(1)
    venv = PennySB3VecEnv("PennyReach-Ellipse-v0", num_envs=4, task=HURRY)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0).learn(256)
    assert model.num_timesteps >= 256 and venv.observation_space.shape == (11,)
    from gymnasium.utils.env_checker import check_env
    check_env(gym.make("penny_env:PennyReach-Ellipse-v0", task=HURRY).unwrapped, skip_render_check=True)


def test_the_reward_stage_is_the_tasks_own(hurry):
    e = PennyEnv("ellipse", HURRY, backend="python")
    r = PennyEnv("ellipse", {"kind": "reach", "max_episode_steps": 50, "tolerance": 0.02}, backend="python")
    e.reset(seed=9)
    r.reset(seed=9)
    for _ in range(10):
        a = np.array([0.3, 0.8])
        (_, re, te, tu, _), (_, rr, _, _, _) = e.step(a), r.step(a)
        assert math.isclose(re, rr - 0.05, rel_tol=0, abs_tol=1e-12)
        if te or tu:
            break


def _stage(k, before, after, ctrl, n_arc, xp):
    return 0.0, False


class _K(NamedTuple):
    x: float


@pytest.mark.fast
def test_a_task_is_checked_when_it_is_registered():
    @dataclass(frozen=True)
    class Cfg(Task):
        kind: str = "t1"

    with pytest.raises(TypeError, match="register_task takes a TaskRecord"):
        register_task("t1")
    with pytest.raises(ValueError, match="identifier"):
        register_task(TaskRecord("t 1", Cfg, lambda s, t, L: _K(1.0), _stage, reach.target))
    with pytest.raises(TypeError, match=r"reward must take \(k, before, after, ctrl, n_arc, xp\)"):
        register_task(TaskRecord("t1", Cfg, lambda s, t, L: _K(1.0), lambda k, a: (0.0, False), reach.target))
    with pytest.raises(TypeError, match="config must be a dataclass derived from"):
        register_task(TaskRecord("t1", dict, lambda s, t, L: _K(1.0), _stage, reach.target))
    with pytest.raises(ValueError, match=r"extra_obs\[0\]"):
        register_task(TaskRecord("t1", Cfg, lambda s, t, L: _K(1.0), _stage, reach.target, lambda k, st, obs, i: None,
                                 ((1.0, 0.0),)))
    with pytest.raises(ValueError, match="give both or neither"):
        register_task(TaskRecord("t1", Cfg, lambda s, t, L: _K(1.0), _stage, reach.target, None, ((0.0, 1.0),)))
    assert "t1" not in TASKS


# reach's constants and an int
_BigK = NamedTuple("_BigK", [*reach.ReachConstants.__annotations__.items(), ("budget", int)])


def _big_constants(scene, task, L):
    return _BigK(*reach.constants(scene, task, L), 2 ** 70)


def _reward3(k, before, after, ctrl, n_arc, xp):
    return 1.0, True, 0


def _reward_array(k, before, after, ctrl, n_arc, xp):
    return np.array([1.0, 2.0]), True


def _constants_raise(scene, task, L):
    return 1 / 0


@pytest.mark.parametrize("stages, error, match", [
    ((reach.constants, _reward3), TypeError, r"register_task\('t9'\): reward must return \(reward, success\), got 3"),
    ((reach.constants, _reward_array), TypeError, r"register_task\('t9'\): reward must return real numbers.*ndarray"),
    ((_big_constants, reach.reward), ValueError, r"task 't9': constants field budget = 1180591620717411303424 does "
                                                 r"not fit the int64"),
    ((_constants_raise, reach.reward), ValueError, r"register_task\('t9'\): constants .*ZeroDivisionError"),
])
def test_a_stage_that_cannot_run_is_refused_naming_the_task_and_the_stage(stages, error, match):
    # issue 40, item 9: each was a bare error (too many values to unpack, only 0-dimensional arrays ...,
    # OverflowError, ZeroDivisionError) at env build, naming neither the task nor the stage
    @dataclass(frozen=True)
    class Cfg(reach.ReachTask):
        kind: str = "t9"

    constants, reward = stages
    with pytest.raises(error, match=match):
        register_task(TaskRecord("t9", Cfg, constants, reward, reach.target))
    assert "t9" not in TASKS


@pytest.mark.fast
def test_a_task_field_of_another_kind_is_refused_naming_it():
    from penny_env.step.config import UnknownFieldError
    with pytest.raises(UnknownFieldError, match="impacts_goal"):
        PennyEnv("ellipse", "reach", impacts_goal=3)
    with pytest.raises(ValueError, match="task.kind must be one of"):
        PennyEnv("ellipse", {"kind": "sprint"})


@pytest.mark.fast
def test_draws_equal_the_numpy_implementation_they_replaced():
    """The per-env reset stage (functional.initial_state and the tasks' target stages) draws, on every
    registered id, the very bits penny_env's vectorised numpy sampler drew (tests/reference/numpy_draws.py)."""
    from penny_env.envs.registration import env_ids
    from penny_env.envs.scene import env_presets
    from tests.reference import numpy_draws
    presets = env_presets()
    n = 64
    for env_id in env_ids():
        spec = dict(presets[env_id])
        scene, task = spec.pop("scene"), spec.pop("task")
        v = PennyVectorEnv(n, scene, task, backend="python", **spec)
        v.reset(seed=123)
        keys = numpy_draws.seed_keys(np.arange(123, 123 + n))
        for episode in (0, 3):
            S, target, arc = numpy_draws.sample(v._core, keys, np.full(n, episode, dtype=np.uint64))
            if episode:
                v.reset(seed=[123 + i for i in range(n)])
                for _ in range(episode):
                    v.reset()
            host = v._runner.state_to_host()
            assert np.array_equal(host.S, S), env_id
            assert np.array_equal(host.target, target) and np.array_equal(host.arc, arc), env_id


@needs_numba
def test_draws_are_the_same_bits_compiled_and_at_extreme_keys():
    from penny_env.step.draws import seed_keys
    envs = [PennyVectorEnv(4, "ellipse", {"kind": "reach", "heading_offset": 0.05}, backend=b) for b in ("python", "numba")]
    for seed in (0, 2**64 - 4, 2**63 - 1):
        obs = [e.reset(seed=seed)[0] for e in envs]
        assert np.array_equal(*obs) and np.array_equal(envs[0].states, envs[1].states)
    assert seed_keys([2**64 - 1]).dtype == np.uint64


# bounds at which float32 and float64 part: 0.1 and 1/3 are not float32 numbers (float32(0.1) > 0.1, float32(1/3) <
# 1/3), 1.5 is; 1e-40 is a float32 subnormal; 3e38 lies near the top of float32's range
GUARD_BOUNDS = ((0.0, 0.1), (-0.1, 1 / 3), (-1.5, 1.5), (-1e-40, 1e-40), (-3e38, 3e38), (0.7, 0.70000001))


def _float32_neighbours(v):
    """The float32 entries around bound v: its own float32, one step down and one up, and v's float64 itself."""
    f = np.float32(v)
    return [np.nextafter(f, np.float32(-np.inf)), f, np.nextafter(f, np.float32(np.inf)), np.float32(np.float64(v))]


@needs_numba
@pytest.mark.fast
def test_the_generated_task_output_guard_agrees_with_the_observation_space_bound_by_bound():
    # the compiled guard compared the float32 entry float32(0.1) = 0.10000000149 with the float64 literal 0.1 and ended
    # every numba episode of a task that writes its declared bound 0.1 (limit 8), which observation_space contains
    import numba
    from gymnasium import spaces

    from penny_env.backends.env import obs_bounds_check
    guard = obs_bounds_check(GUARD_BOUNDS)
    compiled = numba.njit(cache=False)(guard)
    lo = np.array([-1.0] * 10 + [b[0] for b in GUARD_BOUNDS], np.float32)
    hi = np.array([1.0] * 10 + [b[1] for b in GUARD_BOUNDS], np.float32)
    space = spaces.Box(lo, hi, dtype=np.float32)
    obs = np.zeros((1, len(lo)), np.float32)
    obs[0, 10:] = (lo[10:] + hi[10:]) / 2  # (every entry inside; each case below moves one)
    checked = 0
    for j, (a, b) in enumerate(GUARD_BOUNDS):
        for v in _float32_neighbours(a) + _float32_neighbours(b) + [np.float32(np.nan)]:
            row = obs.copy()
            row[0, 10 + j] = v
            inside = bool(space.contains(row[0]))
            assert bool(guard(row, 0)) is inside and bool(compiled(row, 0)) is inside, (j, float(v), inside)
            checked += inside
    assert checked >= 4 * len(GUARD_BOUNDS)  # (both bounds of every entry accepted: the comparisons are not all False)


@pytest.mark.fast
def test_extra_obs_bounds_beyond_float32_are_refused_naming_the_entry():
    @dataclass(frozen=True)
    class Cfg(Task):
        kind: str = "t10"

    with pytest.raises(ValueError, match=r"extra_obs\[1\] = \(0\.0, 1e\+39\) must be within the float32 range"):
        register_task(TaskRecord("t10", Cfg, lambda s, t, L: _K(1.0), _stage, reach.target, lambda k, st, obs, i: None,
                                 ((0.0, 1.0), (0.0, 1e39))))
    assert "t10" not in TASKS


def _far_target(k, p, m, s, trig, base, xp):
    return 1e6, -1e6, 1.0, 0.0


@pytest.mark.fast
def test_a_target_off_the_table_is_refused_when_the_task_is_registered():
    # it passed register_task, and the observations then left observation_space (5e6 where it says [-2, 2]), limit 0
    with pytest.raises(ValueError, match=r"register_task\('far'\): target returned the target \(1e\+06, -1e\+06\) m, "
                                         r"which puts the observation's target entries obs\[8:10\].*outside the "
                                         r"observation space's \[-2, 2\]"):
        register_task(TaskRecord("far", reach.ReachTask, reach.constants, reach.reward, _far_target))
    assert "far" not in TASKS


def _check_target_guard(obs, trunc, info, space):
    assert trunc[0] and info["limit"][0] == 8 and not space.contains(obs[0])
    assert not trunc[1] and info["limit"][1] == 0 and space.contains(obs[1])


@pytest.mark.parametrize("backend", ["python", pytest.param("numba", marks=needs_numba)])
def test_a_target_that_leaves_the_observation_space_ends_the_episode_with_limit_task_output(backend):
    # the run-time guard checked the target's finiteness only: a target off the table gave observations outside
    # observation_space with limit 0 and no warning, on every backend
    env = PennyVectorEnv(2, "ellipse", "reach", backend=backend)
    env.reset(seed=0)
    host = env._runner.state_to_host()
    host.target[:, 0] = (1e6, -1e6)  # (what a task's target stage that slipped past its trials could draw)
    env._runner.state_from_host(host)
    with pytest.warns(RuntimeWarning, match=r"task 'reach' drew a target off the table: the observation's target entry "
                                            r"obs\[8\] = 5e\+06 .* outside the observation space's \[-2, 2\]"):
        obs, _, _, trunc, info = env.step(np.zeros((2, 2), np.float32))
    _check_target_guard(obs, trunc, info, env.single_observation_space)
    single = PennyEnv("ellipse", "reach", backend=backend)
    single.reset(seed=0)
    single._target = (0.0, 0.399)  # (2 table sizes from the centre: obs[8] near 2, inside the space; then past it)
    o, _, _, tr, i = single.step(np.zeros(2, np.float32))
    assert single.observation_space.contains(o) and i["limit"] == 0 and not tr
    single._target = (0.0, 0.5)
    with pytest.warns(RuntimeWarning, match="task_output"):
        o, _, _, tr, i = single.step(np.zeros(2, np.float32))
    assert not single.observation_space.contains(o) and i["limit"] == 8 and tr


def _late_clock(k, st, obs, i):
    obs[i, 10] = st.steps / 20.0  # (within (0, 1) on the trials' steps, past it from step 21 on)


def _late_nan_reward(k, before, after, ctrl, n_arc, xp):
    r, success = reach.reward(k, before, after, ctrl, n_arc, xp)
    return (math.nan if after.steps > 17 else r), success


@pytest.mark.fast
@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP", "DISABLED"])
def test_the_task_output_warning_names_the_cause_found_at_the_step_that_ended_the_episode(mode):
    # the vector env warned one step after the limit, listing every possible cause (reward, target, own entries)
    from gymnasium.vector import AutoresetMode
    register_task(TaskRecord("late_clock", reach.ReachTask, reach.constants, reach.reward, reach.target, _late_clock,
                             ((0.0, 1.0),)))
    register_task(TaskRecord("late_nan", reach.ReachTask, reach.constants, _late_nan_reward, reach.target))
    for kind, steps, cause in (
            ("late_clock", 21, r"task 'late_clock' wrote obs\[10\] = 1\.05, outside its declared bounds extra_obs\[0\] = "
                               r"\(0\.0, 1\.0\) \(as the float32 observation space holds them: \[0\.0, 1\.0\]\)"),
            ("late_nan", 18, r"task 'late_nan' returned a reward that is not finite \(reported as 0\)")):
        env = PennyVectorEnv(2, "ellipse", {"kind": kind, "tolerance": 1e-9}, backend="python",
                             autoreset_mode=getattr(AutoresetMode, mode))
        env.reset(seed=0)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for step in range(1, steps + 1):
                trunc = env.step(np.zeros((2, 2), np.float32))[3]
                assert (not caught) == (step < steps) and trunc.all() == (step == steps), (kind, step)
        assert len(caught) == 1 and re.search(cause, str(caught[0].message)), str(caught[0].message)
        assert "drew a target" not in str(caught[0].message)  # (the cause found, not every possible one)


EDITABLE_TASK = '''
COLUMN = 10


def clock(k, st, obs, i):
    obs[i, COLUMN] = 0.5
'''


def test_a_task_edited_after_registration_is_tried_again_before_an_env_uses_it():
    # registered (its observation writes its own entry), its module constant then edited so that the observation
    # writes into the penny's entries: the step ran it untried (the run-time guard checks only the task's entries)
    module = {"__name__": "users_tasks"}
    exec(compile(EDITABLE_TASK, "users_tasks.py", "exec"), module)  # noqa: S102 (the test's own source)
    record = TaskRecord("edited_clock", reach.ReachTask, reach.constants, reach.reward, reach.target, module["clock"],
                        ((0.0, 1.0),))
    register_task(record)
    try:
        PennyEnv("ellipse", {"kind": "edited_clock"}, backend="python").reset(seed=0)
        module["COLUMN"] = 3
        with pytest.raises(ValueError, match=r"register_task\('edited_clock'\): observation wrote obs\[\+0 rows, 3\].*"
                                             r"\(tried again: a module global that task 'edited_clock'\'s stages read "
                                             r"changed since register_task; register it again after an edit\)"):
            PennyEnv("ellipse", {"kind": "edited_clock"}, backend="python")
        module["COLUMN"] = 10  # (put back: the trials pass again, and the env builds)
        PennyEnv("ellipse", {"kind": "edited_clock"}, backend="python").reset(seed=0)
    finally:
        TASKS.pop("edited_clock", None)
