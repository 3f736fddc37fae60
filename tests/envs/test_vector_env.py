"""PennyVectorEnv: equivalence with PennyEnv, autoreset modes, seeding, errors, make_vec."""
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from penny_env import PennyEnv, PennyVectorEnv
from penny_env.envs.registration import env_presets

PRESETS = env_presets()


@pytest.mark.parametrize("backend", ["numba", "python"])
@pytest.mark.parametrize("env_id", list(PRESETS))
def test_equivalence_with_single_env(env_id, backend):
    kw = PRESETS[env_id]
    N, T = 5, 500
    venv = PennyVectorEnv(N, max_episode_steps=120, backend=backend, **kw)
    assert venv.unwrapped._core.backend == backend
    singles = [PennyEnv(max_episode_steps=120, **kw) for _ in range(N)]
    k = venv.single_action_space.shape[0]
    acts = np.random.default_rng(1).uniform(-1.3, 1.3, size=(T, N, k)).astype(np.float32)
    ov, _ = venv.reset(seed=100)
    for i, s in enumerate(singles):
        o, _ = s.reset(seed=100 + i)
        assert np.array_equal(o, ov[i])
    impacts = 0
    exact = backend == "numba"
    for t in range(T):
        ov, rv, tv, trv, iv = venv.step(acts[t])
        for i, s in enumerate(singles):
            if s._done:  # NEXT_STEP autoreset
                o, info = s.reset()
                r, te, tr, n_imp = 0.0, False, False, 0
            else:
                o, r, te, tr, info = s.step(acts[t, i])
                n_imp = info["impacts"]
                if n_imp:  # both infos hold the first 8 impacts (max_impacts_in_info)
                    m = min(n_imp, 8)
                    assert np.allclose(info["impact_times"][:m], iv["impact_times"][i, :m], rtol=1e-12, atol=0)
                    assert np.array_equal(info["impact_ends"], iv["impact_ends"][i])
                    if exact:
                        assert np.array_equal(info["impact_times"][:m], iv["impact_times"][i, :m])
            S1, S2 = s.state, venv.states[i]
            assert np.all(np.abs(S1 - S2) <= 1e-12 * np.maximum(np.abs(S1), 1e-300)), (t, i)
            assert n_imp == iv["impacts"][i]
            assert te == tv[i] and tr == trv[i]
            assert r == pytest.approx(rv[i], rel=1e-12, abs=1e-12)
            assert np.allclose(o, ov[i], rtol=0, atol=2e-7)
            for key in ("kinetic_energy", "time", "distance"):
                assert info[key] == pytest.approx(iv[key][i], rel=1e-12, abs=1e-15), (t, i, key)
            if exact:  # the compiled step runs PennyEnv's operations: bitwise, observations and info included
                assert np.array_equal(S1, S2) and r == rv[i] and np.array_equal(o, ov[i]), (t, i)
                assert info["kinetic_energy"] == iv["kinetic_energy"][i] and info["distance"] == iv["distance"][i]
            impacts += n_imp
    if PRESETS[env_id]["scene"] != "plane":
        assert impacts > 0


def test_make_vec_uses_native_env_and_checks():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        venv = gym.make_vec("PennyImpacts-Ellipse-v0", num_envs=8)
    assert isinstance(venv.unwrapped, PennyVectorEnv)
    assert venv.unwrapped.task.max_episode_steps == 400
    venv = gym.make_vec("PennyReach-Ellipse-v0", num_envs=3, max_episode_steps=7)
    obs, info = venv.reset(seed=0)
    assert obs.shape == (3, 10) and obs.dtype == np.float32 and venv.observation_space.contains(obs)
    for t in range(7):
        obs, r, term, trunc, info = venv.step(venv.action_space.sample())
    assert trunc.all() and "is_success" in info and info["_is_success"].all()
    sync = gym.make_vec("PennyReach-Ellipse-v0", num_envs=2, vectorization_mode="sync")
    sync.reset(seed=0)
    sync.step(sync.action_space.sample())


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_autoreset_modes(mode):
    venv = PennyVectorEnv(4, "circle", "reach", max_episode_steps=5, autoreset_mode=mode)
    assert venv.metadata["autoreset_mode"] == mode
    obs, _ = venv.reset(seed=0)
    first = obs.copy()
    zero = np.zeros((4, 2), np.float32)
    for t in range(5):
        obs, r, term, trunc, info = venv.step(zero)
    assert trunc.all()
    single = PennyEnv("circle", "reach", max_episode_steps=5)
    single.reset(seed=0)
    for t in range(5):
        o, *_ = single.step(zero[0])
    o2, _ = single.reset()
    if mode == AutoresetMode.SAME_STEP:
        assert info["_final_obs"].all()
        assert np.array_equal(info["final_obs"][0], o)
        assert np.array_equal(obs[0], o2)  # already the next episode's first obs
    else:
        assert np.array_equal(obs[0], o)
        obs, r, term, trunc, info = venv.step(zero)
        assert np.array_equal(obs[0], o2) and (r == 0).all() and not term.any() and not trunc.any()
        assert (info["impacts"] == 0).all() and (info["time"] == 0).all()
    assert not np.array_equal(first, obs)


def test_per_env_seeding_and_reset_mask():
    venv = PennyVectorEnv(3, "ellipse", "reach")
    o, _ = venv.reset(seed=[5, None, 7])
    assert np.array_equal(o[0], PennyEnv().reset(seed=5)[0])
    assert np.array_equal(o[2], PennyEnv().reset(seed=7)[0])
    o_again, _ = venv.reset(seed=[5, 6, 7])
    before = venv.states
    venv.reset(options={"reset_mask": np.array([False, True, False])})
    after = venv.states
    assert np.array_equal(before[[0, 2]], after[[0, 2]]) and not np.array_equal(before[1], after[1])


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_returned_observations_are_the_callers(mode):
    """A step returns a new array: a later step or a partial reset does not change the one a caller
    kept, and a caller writing into it does not change the envs (obs of a partial reset included)."""
    venv = PennyVectorEnv(4, "stadium", "reach", max_episode_steps=3, autoreset_mode=mode)
    o0, _ = venv.reset(seed=3)
    kept = [o0, o0.copy()]
    a = np.full((4, 2), 0.7, np.float32)
    for t in range(7):
        o, *_ = venv.step(a)
        kept += [o, o.copy()]
    o_mask, _ = venv.reset(options={"reset_mask": np.array([True, False, False, False])})
    for got, copy in zip(kept[::2], kept[1::2]):
        assert np.array_equal(got, copy)
    o[:] = 99.0  # the caller's own array now
    twin = PennyVectorEnv(4, "stadium", "reach", max_episode_steps=3, autoreset_mode=mode)
    twin.reset(seed=3)
    for t in range(7):
        twin.step(a)
    o_twin, _ = twin.reset(options={"reset_mask": np.array([True, False, False, False])})
    assert np.array_equal(o_mask, o_twin)
    assert np.array_equal(venv.step(a)[0], twin.step(a)[0])


@pytest.mark.fast
def test_bad_actions_name_the_sub_env_and_keep_states():
    venv = PennyVectorEnv(4, "stadium", "impacts")
    with pytest.raises(gym.error.ResetNeeded):
        venv.step(np.zeros((4, 2)))
    venv.reset(seed=0)
    before = venv.states
    a = np.zeros((4, 2), np.float32)
    a[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"sub-env\(s\) \[2\]"):
        venv.step(a)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 2)))
    assert np.array_equal(before, venv.states)
    venv.step(np.zeros((4, 2)))
    assert not np.array_equal(before, venv.states)


def test_pickle_and_async_vector():
    venv = PennyVectorEnv(3, "circle", "park")
    venv.reset(seed=1)
    clone = pickle.loads(pickle.dumps(venv))
    a = np.full((3, 2), 0.3, np.float32)
    assert np.array_equal(venv.step(a)[0], clone.step(a)[0])
    env = gym.make_vec("PennyPark-Circle-v0", num_envs=2, vectorization_mode="async")
    try:
        obs, _ = env.reset(seed=3)
        assert np.array_equal(obs[1], PennyEnv("circle", "park", law="plastic").reset(seed=4)[0])
        env.step(env.action_space.sample())
    finally:
        env.close()
