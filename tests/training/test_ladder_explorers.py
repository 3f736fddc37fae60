"""The ladder's goal-conditioned and privileged agents of issue 36 (training/her_sac.py, start_curriculum.py,
go_explore.py): each tiny run follows the protocol (training/protocol.py: checkpoints at the first env-step count
that reaches each, a deterministic Policy that evaluate() runs, success in [0, 1]), the privileged ones never draw
the evaluation's or the validation's seeds, and nothing succeeds on the plane (theorems T2.3, T3.2)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from penny_env.envs.vector_env import PennyVectorEnv
from training import agent_side as A
from training import go_explore, her_sac, start_curriculum
from training.protocol import evaluate, load_demos, save_demos

STEER = "PennyProbeSteer-Stadium-Elastic-v0"
DRIVE = "PennyProbeDrive-Ellipse-Plastic-v0"
VAL = range(50_000, 50_006)  # (a few validation seeds: never the evaluation's 0..199)

TINY_HER = dict(num_envs=16, batch_size=64, hidden=32, learning_starts=256, buffer_per_env=64, torch_threads=1)
TINY_CUR = dict(num_envs=16, num_steps=8, minibatch=64, epochs=1, torch_threads=1)


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


def test_curriculum_protocol_and_seeds(tmp_path, seeds_drawn):
    path, eps = _tiny_demos(tmp_path, DRIVE)
    assert len(eps) >= 1
    d = load_demos(path)
    assert d["length"].sum() + len(d["length"]) == len(d["states"])
    args = start_curriculum.Args(env_id=DRIVE, demos=str(path), total_timesteps=1200, **TINY_CUR)
    seeds_drawn.clear()
    res, _ = _protocol_run(start_curriculum.train, args, [100, 600], args.num_envs * args.num_steps)
    assert res["demos"] == len(eps) and res["demos_replayed_exactly"] == len(eps)
    assert seeds_drawn and all(s >= 10_000_000 for s in seeds_drawn if s not in VAL)


def test_curriculum_moves_starts_back():
    rng = np.random.default_rng(0)
    cur = start_curriculum.Curriculum([20, 9], back=4, threshold=0.2, min_episodes=5, rng=rng)
    assert list(cur.k) == [16, 5]
    j, start, stage = cur.draw(100)
    assert set(j) == {0, 1} and (start <= cur.k[j]).all() and (start > cur.k[j] - 4).all()
    cur.record(np.zeros(5, int), np.zeros(5, int), np.array([1, 0, 0, 0, 0], bool))  # 20 %: move back
    assert cur.k[0] == 12 and cur.stage[0] == 1
    cur.record(np.zeros(5, int), np.zeros(5, int), np.ones(5, bool))  # an older stage's outcomes: ignored
    assert cur.k[0] == 12
    cur.record(np.ones(5, int), np.zeros(5, int), np.array([0, 0, 0, 0, 1], bool))
    cur.record(np.ones(5, int), np.ones(5, int), np.array([1, 1, 0, 0, 0], bool))
    assert cur.k[1] == 0 and not cur.done[1]
    cur.record(np.ones(5, int), np.full(5, 2), np.ones(5, bool))
    assert cur.done[1]


def test_go_explore_protocol_and_seeds(seeds_drawn):
    args = go_explore.Args(env_id=DRIVE, total_timesteps=3000, explore_steps=1000, pairs=4, num_envs=16, segment=8,
                           curriculum=TINY_CUR)
    args = dataclasses.replace(args, num_envs=16)
    res, calls = _protocol_run(go_explore.train, args, [500, 1500], 16 * 8)
    assert calls[0][0] == 500  # (passed by the exploration: the initial policy)
    assert res["explore_steps"] >= 1000 and res["cells"] >= 4
    assert all(s >= 10_000_000 for s in seeds_drawn if s not in VAL)
    with pytest.raises(ValueError, match="go_seed"):
        go_explore.train(dataclasses.replace(args, go_seed=7))


def test_go_explore_certifies_its_trajectories():
    """The archive's successes replay to success from the pair's start (drive reach: easy to hit by chance)."""
    args = go_explore.Args(env_id="PennyProbeDrive-Stadium-Elastic-v0", explore_steps=6000, pairs=3, num_envs=32,
                           segment=20)
    arch, solved, starts, steps, stats = go_explore.explore(args, log=lambda s: None)
    eps = go_explore.certify(args.env_id, {}, arch, solved, starts, args.go_seed)
    assert len(eps) == len(solved)
    for states, target, actions in eps:
        assert len(states) == len(actions) + 1
        assert np.hypot(*(states[-1][:2] - target)) < 0.015


@pytest.mark.parametrize("env_id", ["PennyProbeSteer-Plane-v0", "PennyProbeDrive-Plane-v0"])
def test_plane_negative_control(env_id):
    """No success on the plane (theorems T2.3, T3.2): in training, in exploration, in the evaluation."""
    res = her_sac.train(her_sac.Args(env_id=env_id, total_timesteps=1500, **TINY_HER))
    assert res["train_successes"] == 0
    args = go_explore.Args(env_id=env_id, total_timesteps=2500, explore_steps=1500, pairs=4, num_envs=16, segment=8,
                           curriculum=TINY_CUR)
    seen = []
    res = go_explore.train(args, checkpoints=[2000], on_checkpoint=lambda n, p: seen.append(
        evaluate(p, env_id, seeds=VAL)["successes"]))
    assert res["solved"] == 0 and res["demos"] == 0 and seen == [0, 0]
