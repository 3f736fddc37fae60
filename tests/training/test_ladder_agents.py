"""The ladder's unprivileged agents: training.ppo_torch (the ladder's configuration) and training.ppo_heading
follow training/protocol.py (checkpoints at the right env-step counts, a deterministic
Policy that training.protocol.evaluate runs, a success rate in [0, 1]), and none succeeds on the plane, where the
theorems say no agent can (the negative control). Tiny budgets: seconds each."""
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed (the penny-env[train] extra)")
pytest.importorskip("torch.utils.tensorboard", reason="tensorboard is not installed (the penny-env[train] extra)")

from training import agent_side as A  # noqa: E402
from training import ppo_heading, ppo_torch  # noqa: E402
from training.protocol import evaluate  # noqa: E402

STADIUM = "PennyProbeSteer-Stadium-Elastic-v0"
PLANE = "PennyProbeSteer-Plane-v0"
TINY = {"num_envs": 16, "num_steps": 8, "minibatch_size": 64, "total_timesteps": 3 * 16 * 8}  # 3 iterations


def _args(agent, env_id, tmp_path, **changes):
    fields = {**TINY, "env_id": env_id, "out": str(tmp_path / agent), **changes}
    if agent == "ppo":
        return ppo_torch.ladder_args(**fields)
    return ppo_heading.Args(**fields)


def _train(agent, args, **kw):
    return {"ppo": ppo_torch, "ppo_heading": ppo_heading}[agent].train(args, **kw)


@pytest.mark.parametrize("agent, env_id", [("ppo", STADIUM), ("ppo_heading", STADIUM),
                                           ("ppo_heading", "PennyProbeDrive-Stadium-Elastic-v0"),
                                           ("ppo_heading", "PennyProbeBoth-Stadium-Elastic-v0")])
def test_tiny_run_follows_the_protocol(agent, env_id, tmp_path):
    calls = []
    res = _train(agent, _args(agent, env_id, tmp_path), checkpoints=[100, 128, 200, 10_000],
                 on_checkpoint=lambda steps, policy: calls.append((steps, policy)), log=None)
    # 128 env steps per iteration: 100 and 128 are first reached at 128 (one call), 200 at 256, then the end
    assert [s for s, _ in calls] == [128, 256, 384]
    assert res["env_steps"] == 384 and res["wall_time_s"] > 0 and res["steps_per_s"] > 0
    for _, policy in calls[-1:] + calls[:1]:
        ev = evaluate(policy, env_id, {}, range(5))
        assert ev["episodes"] == 5 and 0.0 <= ev["successes"] / ev["episodes"] <= 1.0
        assert len(ev["impacts_to_success"]) == 5
    # deterministic: the same policy plays the same episodes twice
    a, b = (evaluate(calls[-1][1], env_id, {}, range(3)) for _ in range(2))
    assert a == b


@pytest.mark.parametrize("agent", ["ppo", "ppo_heading"])
def test_no_success_on_the_plane(agent, tmp_path):
    """The negative control: theta_dot is conserved on the plane under steering alone (T2.3), so no park can
    succeed there; a success would be a bug."""
    res = _train(agent, _args(agent, PLANE, tmp_path, total_timesteps=6 * 16 * 8), log=None)
    ev = evaluate(res["policy"], PLANE, {}, range(32))
    assert ev["successes"] == 0 and ev["episodes"] == 32
    train_success = res.get("train_success", res.get("train_success_rate"))
    assert train_success == 0 or (isinstance(train_success, float) and math.isnan(train_success))


def test_ppo_torch_ladder_configuration():
    args = ppo_torch.ladder_args(env_id=STADIUM, seed=3)
    assert (args.num_envs, args.num_steps, args.minibatch_size, args.update_epochs) == (4096, 32, 16384, 2)
    assert args.gamma == 0.999 and args.fair_reward and args.env_seed_base >= 10_000_000
    assert ppo_torch.reward_kwargs(args) == ppo_torch.FAIR_REWARD  # the park task has every reward field
    drive = ppo_torch.ladder_args(env_id="PennyProbeDrive-Ellipse-Elastic-v0")
    assert "speed_cost" not in ppo_torch.reward_kwargs(drive)  # (reach has none to zero)
    assert ppo_torch.reward_kwargs(ppo_torch.Args()) == {}  # the CLI's default run keeps the task's reward


def test_ppo_heading_policy_keeps_its_own_clock_and_impact_count():
    k = A.TaskConsts.of(A.make_vec(STADIUM, 2))
    assert (k.gain1 != 0, k.gain2 != 0) == (True, False) and k.park and k.max_steps == 400
    assert math.isclose(k.gain1, 10.0)
    agent = ppo_heading.Agent(k, 8, 0.5, 0.05, 1.0, layer_norm=True)
    policy = ppo_heading.HeadingPolicy(agent, k)
    policy.reset(2)
    obs = np.zeros((2, 10), np.float32)
    obs[:, 4] = 1.0
    policy(obs, {"impacts": np.array([0, 0])})  # the reset's info: no step behind it
    assert policy.mem.tolist() == [[0, 0], [0, 0]]
    policy(obs, {"impacts": np.array([1, 0])})
    policy(obs, {"impacts": np.array([2, 0])})
    assert policy.mem.tolist() == [[3, 2], [0, 2]]
    policy.reset(3)
    assert policy.mem.shape == (3, 2) and not policy.mem.any()


def test_the_servo_laws_and_the_park_potential():
    k = A.TaskConsts.of(A.make_vec("PennyProbeBoth-Stadium-Elastic-v0", 1))
    obs = torch.zeros(3, 10)
    obs[:, 4] = 1.0  # heading phi = 0, at rest, on the target
    act = torch.tensor([[0.0, 0.0], [0.1, 0.0], [0.0, 0.5]])  # (heading psi, speed request / V_MAX)
    u = A.servo(obs, act, k)
    assert u[0].tolist() == [0.0, 0.0]
    assert math.isclose(float(u[1, 0]), A.KP * 0.1 / k.gain1, rel_tol=1e-6) and u[1, 1] == 0
    assert u[2, 0] == 0 and u[2, 1] == 1.0  # a speed request far above the current speed: full torque
    # park: at rest on the target the potential is its largest (0); far and fast it is its lowest
    assert float(A.potential(obs[:1], k, 0.5)) == 0.0
    far = obs[:1].clone()
    far[:, 6], far[:, 8] = 0.5, 1.5
    assert float(A.potential(far, k, 0.5)) < -3.0


def test_ppo_speed_quick(tmp_path, capsys):
    pytest.importorskip("stable_baselines3", reason="SB3 is not installed (the penny-env[train] extra)")
    from devtools import ppo_speed
    out = tmp_path / "speed.md"
    text = ppo_speed.main(["--quick", "--threads", "1", "--out", str(out)])
    assert out.read_text() == text
    assert "- date:" in text and "- machine:" in text
    rows = [line for line in text.splitlines() if line.startswith("| 1 |")]
    assert len(rows) == 2 and "ladder PPO" in rows[0] and "SB3 PPO" in rows[1]
    assert "Ratio of the medians" in text


def test_ppo_speed_quick_refuses_docs(capsys):
    from devtools import ppo_speed
    with pytest.raises(SystemExit):
        ppo_speed.main(["--quick", "--out", str(ppo_speed.ROOT / "docs" / "ppo_speed_quick.md")])
    assert not (ppo_speed.ROOT / "docs" / "ppo_speed_quick.md").exists()


def test_ppo_heading_hands_out_the_best_validated_snapshot(tmp_path, monkeypatch):
    """keep_best: each checkpoint gets the policy with the best validation success so far, frozen when validated."""
    scores = iter([0.5, 0.25, 0.75])  # the validations' success rates, in order
    monkeypatch.setattr(ppo_heading, "evaluate", lambda *a, **k: {"successes": int(100 * next(scores)),
                                                                  "episodes": 100})
    calls = []
    args = _args("ppo_heading", STADIUM, tmp_path, val_every=128, val_episodes=4)
    res = ppo_heading.train(args, checkpoints=[128, 256, 384], log=None,
                            on_checkpoint=lambda steps, policy: calls.append(policy))
    assert res["best_val"] == 0.75 and [v for _, v in res["val_curve"]] == [0.5, 0.25, 0.75]
    def same(a, b):
        return all(torch.equal(x, y) for x, y in zip(a.values(), b.values()))
    first, second, last = (p.agent.state_dict() for p in calls)
    assert same(second, first)  # (0.25 < 0.5: the first snapshot is still the best)
    assert not same(last, first) and same(last, torch.load(tmp_path / "ppo_heading" / "best_model.pt"))


def test_the_fair_reward_and_the_args_check_take_a_cell_that_replaces_the_scene():
    """The rounded rectangle and the circle are cells of a preset id with its scene replaced (studies/cells.py): the
    fair reward's fields and ppo_torch's check of env_kwargs resolved the id's scene and the override's both."""
    from studies.cells import cell_spec
    from training.protocol import FAIR_REWARD, fair_reward_kwargs
    for cell in [("Steer", "rounded_rectangle", "elastic"), ("Steer", "circle", "elastic")]:
        env_id, overrides = cell_spec(*cell)
        assert "scene" in overrides
        assert fair_reward_kwargs(env_id, overrides) == FAIR_REWARD
        args = ppo_torch.ladder_args(env_id=env_id, env_kwargs=overrides, total_timesteps=256, num_envs=16,
                                     num_steps=16, minibatch_size=64)
        ppo_torch.check_args(args)


def test_the_noise_floor_stays_wide_until_the_first_parks_and_never_widens_again():
    args = ppo_heading.Args(explore_until=0.1, std_init=0.5, std_min=0.15)
    floor = ppo_heading.noise_floor(args, 0.5, float("nan"))  # (no episode has ended yet)
    assert floor == 0.5
    assert ppo_heading.noise_floor(args, floor, 0.0) == 0.5
    half = ppo_heading.noise_floor(args, floor, 0.05)
    assert half == pytest.approx(0.325)
    assert ppo_heading.noise_floor(args, half, 0.0) == half  # (a success that falls does not widen it)
    assert ppo_heading.noise_floor(args, half, 0.4) == 0.15
    off = ppo_heading.Args()  # explore_until 0: the floor is std_min throughout
    assert ppo_heading.noise_floor(off, off.std_min, 0.0) == off.std_min


def test_a_run_with_the_wide_floor_logs_it_and_keeps_its_noise_above_it(tmp_path):
    args = _args("ppo_heading", STADIUM, tmp_path, explore_until=0.1)
    _train("ppo_heading", args, log=None)
    rows = (tmp_path / "ppo_heading" / "progress.csv").read_text().splitlines()
    head = rows[0].split(",")
    floor, std = head.index("std_floor"), head.index("std")
    for row in rows[1:]:  # (no park in 3 tiny updates: the floor stays at std_init, and the noise at or above it)
        cells = row.split(",")
        assert float(cells[floor]) == 0.5 and float(cells[std]) >= 0.5 * (1 - 1e-6)
