"""The ladder's goal-conditioned agent (training/her_sac.py) and its witness-guided PRIVILEGED agents (training/
ppo_heading.py with a guide, training/guides.py): each tiny run follows the protocol (training/protocol.py:
checkpoints at the first env-step count that reaches each, a deterministic Policy that evaluate() runs, success in
[0, 1]) and never draws the evaluation's seeds; a guided episode replays its witness bit for bit until the hand-over;
the schedules move the hand-over back as the learner succeeds."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from penny_env.envs.vector_env import PennyVectorEnv
from training import agent_side as A
from training import guides, her_sac, ppo_heading
from training.protocol import evaluate, load_demos, save_demos

STEER = "PennyProbeSteer-Stadium-Elastic-v0"
DRIVE = "PennyProbeDrive-Ellipse-Plastic-v0"
VAL = range(50_000, 50_006)  # (a few validation seeds: never the evaluation's 0..199)

TINY_HER = dict(num_envs=16, batch_size=64, hidden=32, learning_starts=256, buffer_per_env=64, torch_threads=1)
TINY_GUIDED = dict(num_envs=16, num_steps=8, minibatch_size=64, update_epochs=1, torch_threads=1, val_every=0,
                   guide_min_episodes=2)


@pytest.fixture
def seeds_drawn(monkeypatch):
    """Every seed a PennyVectorEnv.reset is given while the fixture is active."""
    seen = []
    orig = PennyVectorEnv.reset

    def spy(self, *, seed=None, options=None):
        if seed is not None:
            seen.extend([seed] if np.ndim(seed) == 0 else [s for s in seed if s is not None])
        return orig(self, seed=seed, options=options)
    monkeypatch.setattr(PennyVectorEnv, "reset", spy)
    return seen


def _protocol_run(train, args, checkpoints, step_of_iteration):
    """train(args, checkpoints, on_checkpoint) with a recorder: returns (result, [(env_steps, evaluate() of the
    policy)]), checking the calls: ascending, one at the first count >= each checkpoint, and one at the end."""
    calls = []

    def on_cp(n, policy):
        assert hasattr(policy, "reset") and callable(policy)
        calls.append((n, evaluate(policy, args.env_id, args.env_kwargs, seeds=VAL)))

    res = train(args, checkpoints=checkpoints, on_checkpoint=on_cp)
    ns = [n for n, _ in calls]
    assert ns == sorted(ns) and len(set(ns)) == len(ns)
    for c in checkpoints:
        first = [n for n in ns if n >= c][0]
        assert first - c < step_of_iteration, (c, ns)
    assert ns[-1] == res["env_steps"] >= args.total_timesteps
    for _, ev in calls:
        assert ev["episodes"] == len(VAL) and 0 <= ev["successes"] <= ev["episodes"]
    for key in ("env_steps", "wall_time_s", "steps_per_s"):
        assert res[key] > 0
    return res, calls


def test_her_protocol_and_goal_test(seeds_drawn):
    args = her_sac.Args(env_id=STEER, total_timesteps=1500, **TINY_HER)
    res, calls = _protocol_run(her_sac.train, args, [300, 800], args.num_envs)
    assert all(s >= 10_000_000 for s in seeds_drawn if s not in VAL)
    # the park goal: the env's own success test, from the published tolerances, on the decoded observation
    vec = A.make_vec(STEER, 4)
    k = A.TaskConsts.of(vec)
    import torch
    obs = torch.tensor(vec.reset(seed=10_000_000)[0])
    g = her_sac.desired(obs, k)
    ag = her_sac.achieved(obs, k)
    assert g.shape == (4, 4) and torch.all(g[:, 2:] == 0)
    near = ag.clone()
    near[:, 0] = g[:, 0] + 0.019
    near[:, 1] = g[:, 1]
    near[:, 2] = 0.0099
    near[:, 3] = -0.49
    assert her_sac.success(near, g, k).all()
    for col, val in ((0, 0.021), (2, 0.011), (3, 0.51)):
        far = near.clone()
        far[:, col] = (g[:, 0] if col == 0 else 0) + val
        assert not her_sac.success(far, g, k).any()


def test_her_buffer_relabels_within_the_episode():
    import torch
    k = A.TaskConsts.of(A.make_vec(DRIVE, 1))
    buf = her_sac.HerBuffer(2, 8, 10, 1, 2)
    rows = torch.arange(2)
    for t in range(12):  # env 0: episodes of 3 steps; env 1: one open episode
        ag = torch.tensor([[t, 0.0], [100 + t, 0.0]])
        buf.add(rows, torch.zeros(2, 10), torch.zeros(2, 2), torch.zeros(2, 1), torch.zeros(2, 10), torch.zeros(2, 2),
                torch.full((2, 2), -1.0), ag, torch.tensor([t % 3 == 2, False]))
    o, m, a, no, nm, g, done = buf.sample(4000, 4, k)
    relabelled = g[:, 0] >= 0
    assert 0.7 < relabelled.float().mean() < 0.9
    # a relabelled goal is an achieved goal of the same env, no earlier than the sampled step
    assert ((g[relabelled, 0] >= 100) | (g[relabelled, 0] < 12)).all()


def _tiny_demos(tmp_path, env_id, n=2):
    from studies.witness_demos import witness_demos
    eps = witness_demos(env_id, {}, range(100_000, 100_000 + n))
    path = tmp_path / "demos.npz"
    save_demos(path, eps)
    return path, eps


def test_witness_demos_refuse_evaluation_seeds():
    from studies.witness_demos import witness_demos
    with pytest.raises(ValueError, match="100,000"):
        witness_demos(DRIVE, {}, [199])


@pytest.mark.parametrize("schedule", guides.SCHEDULES)
def test_guided_ppo_follows_the_protocol_and_never_draws_evaluation_seeds(tmp_path, seeds_drawn, schedule):
    path, eps = _tiny_demos(tmp_path, DRIVE)
    assert len(eps) >= 1
    d = load_demos(path)
    assert d["length"].sum() + len(d["length"]) == len(d["states"])
    args = ppo_heading.Args(env_id=DRIVE, demos=str(path), guide=schedule, total_timesteps=1200, **TINY_GUIDED)
    seeds_drawn.clear()
    res, _ = _protocol_run(ppo_heading.train, args, [100, 600], args.num_envs * args.num_steps)
    assert 0 <= res["guide_frac"] <= 1
    assert seeds_drawn and all(s >= 10_000_000 for s in seeds_drawn if s not in VAL)
    with pytest.raises(ValueError, match="needs demos"):
        ppo_heading.train(dataclasses.replace(args, demos=None))


def test_a_guided_episode_is_its_witness_until_the_hand_over(tmp_path):
    _, eps = _tiny_demos(tmp_path, DRIVE)
    path = tmp_path / "demos.npz"
    demos = load_demos(path)
    vec = A.make_vec(DRIVE, 3)
    vec.reset(seed=10_000_000)
    g = guides.Guide(demos, 3, np.random.default_rng(0), "curriculum", step=0.0, p_own=0.0)
    g.frac[:] = 1.0  # hand over at the last step
    rows = np.arange(3)
    S, G, guided = g.start(rows)
    assert guided.all()
    vec.reset(options={"state": S, "target": G, "reset_mask": np.ones(3, bool)})
    h = g.left.copy()
    assert (h == [len(eps[j][2]) - 1 for j in g.demo]).all()
    for t in range(int(h.max())):
        act = np.zeros((3, 1))
        on = g.actions(act)
        assert (on == (t < h)).all()
        vec.step(act)
        g.advance()
        for i in np.flatnonzero(on):
            assert np.array_equal(vec.states[i], eps[g.demo[i]][0][t + 1])  # (bit for bit: float64 actions)


def test_the_jsrl_schedule_moves_the_hand_over_back_for_every_demonstration():
    demos = {"states": np.zeros((12, 6)), "targets": np.zeros((12, 2)), "episode": np.repeat([0, 1], [5, 7]),
             "step": np.r_[np.arange(5), np.arange(7)], "length": np.array([4, 6]), "actions": np.zeros((10, 1))}
    g = guides.Guide(demos, 4, np.random.default_rng(0), "jsrl", step=0.5, threshold=0.5, min_episodes=4, p_own=0.0)
    g.start(np.arange(4))
    assert ((0 <= g.left) & (g.left <= np.round(0.5 * g.T[g.demo]))).all()  # (random switching up to f T)
    g.record(np.arange(4), np.array([1, 1, 0, 0], bool))  # 2 of 4 at f = 0.5: the hand-over moves to f = 0
    assert (g.frac == 0).all() and (g.stage == 1).all()
    g.start(np.arange(2))
    g.record(np.arange(2), np.ones(2, bool))  # (episodes of stage 1, too few yet)
    assert not g.finished()
    g.demo[2:] = 0
    g.demo_stage[2:] = 0
    g.record(np.arange(2, 4), np.ones(2, bool))  # outcomes of an older stage: ignored
    assert not g.finished()
    g.start(np.arange(4))
    assert (g.left == 0).all()  # at f = 0 the demonstration only picks the start
    g.record(np.arange(4), np.ones(4, bool))
    assert g.finished() and g.start(np.arange(4))[2].sum() == 0  # the final stage: the task's own starts


def test_the_curriculum_moves_each_start_back_and_drops_the_unsolved():
    demos = {"states": np.zeros((12, 6)), "targets": np.zeros((12, 2)), "episode": np.repeat([0, 1], [5, 7]),
             "step": np.r_[np.arange(5), np.arange(7)], "length": np.array([4, 6]), "actions": np.zeros((10, 1))}
    g = guides.Guide(demos, 2, np.random.default_rng(0), "curriculum", step=0.5, threshold=0.5, min_episodes=2,
                     p_own=0.0, give_up=3)
    for _ in range(3):  # demonstration 1 never solved: dropped after give_up episodes
        g.demo[:], g.demo_stage[:] = [1, 1], 0
        g.record(np.arange(2), np.zeros(2, bool))
    assert g.dropped.tolist() == [False, True] and g.frac[1] == 0.5
    g.demo[:], g.demo_stage[:] = [0, 0], 0
    g.record(np.arange(2), np.array([1, 0], bool))  # half of two: moves back
    assert g.frac[0] == 0.0 and g.stage[0] == 1
    g.demo[:], g.demo_stage[:] = [0, 0], 1
    g.record(np.arange(2), np.ones(2, bool))  # solved from its start: done
    assert g.done[0] and g.finished()
