"""An interrupted reset() leaves the env as before, or makes the next step() raise ResetNeeded, as an interrupted
step() does (issue 31, deliverable 3). The trial's half-reset envs stepped on without ResetNeeded: the seed
stream shifted, the first reward used the old distance, and once a new state was paired with the old target.
KeyboardInterrupt is injected at each stage of reset (monkeypatch), for PennyEnv and PennyVectorEnv."""
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

from penny_env import PennyEnv, PennyVectorEnv


def _interrupt(monkeypatch, obj, name):
    def boom(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(obj, name, boom)


def _snapshot_single(env):
    return (env.state.tolist(), env.target.tolist(), env._steps, env._episode, env._d, env._trig,
            env.np_random.bit_generator.state)


STAGES_SINGLE = [("initial_state", lambda env: (env._fns, "initial_state")),
                 ("observe_state", lambda env: (env._fns, "observe_state")),
                 ("info", lambda env: (env, "_info"))]


def _interrupt_entry(monkeypatch, env, name):
    """env's entry point ``name`` (backends/env.EnvEntryPoints, a record: the single env's, or the vector env's
    runner's) replaced by one that raises KeyboardInterrupt."""
    def boom(*args, **kwargs):
        raise KeyboardInterrupt
    holder, attr = (env._runner, "fns") if hasattr(env, "_runner") else (env, "_fns")
    monkeypatch.setattr(holder, attr, getattr(holder, attr)._replace(**{name: boom}))


@pytest.mark.parametrize("stage", [s for s, _ in STAGES_SINGLE])
@pytest.mark.parametrize("seeded", [True, False])
def test_an_interrupted_single_reset_makes_the_next_step_raise(monkeypatch, stage, seeded):
    env = PennyEnv("ellipse", "reach", backend="python")
    env.reset(seed=3)
    for _ in range(3):
        env.step(np.array([0.3, 0.8], np.float32))
    obj, name = dict(STAGES_SINGLE)[stage](env)
    options = {"target": [0.01, 0.02]} if stage == "observe_state" else None  # (the options' stage)
    with monkeypatch.context() as m:
        if obj is env._fns:
            _interrupt_entry(m, env, name)
        else:
            _interrupt(m, obj, name)
        with pytest.raises(KeyboardInterrupt):
            env.reset(seed=7 if seeded else None, options=options)
    with pytest.raises(ResetNeeded, match=r"previous step\(\) or reset\(\) was interrupted"):
        env.step(np.zeros(2, np.float32))
    # a reset then starts the episode as a fresh env does (the seed stream did not move)
    obs, _ = env.reset(seed=7)
    fresh = PennyEnv("ellipse", "reach", backend="python")
    ref, _ = fresh.reset(seed=7)
    assert np.array_equal(obs, ref)
    for _ in range(3):
        a = np.array([0.5, -0.2], np.float32)
        assert all(np.array_equal(x, y) for x, y in zip(env.step(a)[:4], fresh.step(a)[:4]))


def test_an_unseeded_reset_after_an_interrupted_one_draws_the_next_episode(monkeypatch):
    # the interrupted reset must not consume an episode of the stream
    env, ref = PennyEnv("ellipse", "reach", backend="python"), PennyEnv("ellipse", "reach", backend="python")
    env.reset(seed=11)
    ref.reset(seed=11)
    with monkeypatch.context() as m:
        _interrupt_entry(m, env, "initial_state")
        with pytest.raises(KeyboardInterrupt):
            env.reset()
    assert np.array_equal(env.reset()[0], ref.reset()[0])


def test_a_refused_reset_changes_nothing():
    # bad options used to raise after the episode counter and the seed key had moved
    env = PennyEnv("ellipse", "reach", backend="python")
    env.reset(seed=5)
    env.step(np.array([0.2, 0.2], np.float32))
    before = _snapshot_single(env)
    for options in ({"state": [9.0, 0, 0, 0, 0, 0]}, {"target": [np.nan, 0.0]}, {"bad": 1}):
        with pytest.raises(ValueError):
            env.reset(options=options)
        assert _snapshot_single(env) == before
    env.step(np.array([0.2, 0.2], np.float32))  # (the episode goes on)


@pytest.mark.parametrize("stage", ["reset_rows", "observe_rows", "info"])
@pytest.mark.parametrize("masked", [False, True])
def test_an_interrupted_vector_reset_makes_the_next_step_raise(monkeypatch, stage, masked):
    n = 4
    env = PennyVectorEnv(n, "ellipse", "reach", backend="python")
    env.reset(seed=3)
    for _ in range(2):
        env.step(np.full((n, 2), 0.4))
    options = {"reset_mask": np.array([True, False, True, False])} if masked else None
    if stage == "observe_rows" and not masked:  # (observe_rows runs for reset options, and the rows outside a mask)
        options = {"target": [0.01, 0.02]}
    with monkeypatch.context() as m:
        if stage == "info":
            _interrupt(m, env, "_info")
        else:
            _interrupt_entry(m, env, stage)
        with pytest.raises(KeyboardInterrupt):
            env.reset(seed=9, options=options)
    with pytest.raises(ResetNeeded, match=r"previous step\(\) or reset\(\) was interrupted"):
        env.step(np.zeros((n, 2)))
    with pytest.raises(ResetNeeded, match="reset every env"):
        env.reset(options={"reset_mask": np.array([True, False, False, False])})
    obs, _ = env.reset(seed=9)
    fresh = PennyVectorEnv(n, "ellipse", "reach", backend="python")
    assert np.array_equal(obs, fresh.reset(seed=9)[0])
    a = np.full((n, 2), -0.3)
    assert all(np.array_equal(x, y) for x, y in zip(env.step(a)[:4], fresh.step(a)[:4]))


def test_a_refused_vector_reset_changes_nothing():
    n = 3
    env = PennyVectorEnv(n, "ellipse", "reach", backend="python")
    env.reset(seed=1)
    env.step(np.full((n, 2), 0.4))
    before = (env.states.tolist(), env.targets.tolist(), env._runner.st.episode.tolist(), env._runner.st.key.tolist(),
              env.np_random.bit_generator.state)
    for kwargs in ({"seed": [1, 2]}, {"options": {"state": np.full(6, 9.0)}},
                   {"options": {"reset_mask": np.array([1, 0, 1])}}, {"seed": 2, "options": {"bad": 0}}):
        with pytest.raises((ValueError, TypeError)):
            env.reset(**kwargs)
        assert (env.states.tolist(), env.targets.tolist(), env._runner.st.episode.tolist(), env._runner.st.key.tolist(),
                env.np_random.bit_generator.state) == before
    env.step(np.full((n, 2), 0.4))


def test_the_reset_flag_is_cleared_only_when_every_row_is_whole(monkeypatch):
    # (the rows' state, trig and observation, which the step's impact certificate reads, are written by reset_rows)
    env = PennyVectorEnv(2, "circle", "reach", backend="python")
    calls = []
    real = env._runner.fns.reset_rows

    def spy(*args):
        calls.append(env._in_step)
        return real(*args)
    monkeypatch.setattr(env._runner, "fns", env._runner.fns._replace(reset_rows=spy))
    env.reset(seed=0)
    assert calls == [True] and env._in_step is False
