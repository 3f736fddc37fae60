"""training.ppo_torch: the compact PPO in torch over the native vector env (devtools.ppo_speed times it beside
SB3's PPO)."""
import csv
import json
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed (the penny-env[train] extra)")
pytest.importorskip("torch.utils.tensorboard", reason="tensorboard is not installed (the penny-env[train] extra)")
from gymnasium import spaces  # noqa: E402

from training import ppo_torch  # noqa: E402
from training.ppo_torch import Args, compute_gae, env_actions, env_outputs_torch, to_tensor  # noqa: E402


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_quick_run_writes_its_files(tmp_path, capsys):
    out = tmp_path / "run"
    agent, res = ppo_torch.main(["--quick", "--out", str(out), "--device", "cpu"])
    for name in ("progress.csv", "model.pt", "config.json", "results.json"):
        assert (out / name).is_file(), name
    assert list(out.glob("events.out.tfevents.*")), "no TensorBoard events"
    rows = _rows(out / "progress.csv")
    assert rows and list(rows[0]) == ppo_torch.CSV_COLUMNS
    assert int(rows[-1]["global_step"]) >= 4096 and res["timesteps"] == int(rows[-1]["global_step"])
    for r in rows:
        for key in ("policy_loss", "value_loss", "entropy", "approx_kl", "wall_time_s", "steps_per_s"):
            assert math.isfinite(float(r[key])), (key, r)
    succ = [float(r["success_rate"]) for r in rows if r["success_rate"] != "nan"]
    assert succ and all(0.0 <= s <= 1.0 for s in succ)
    walls = [float(r["wall_time_s"]) for r in rows]
    assert walls == sorted(walls)
    for r in rows:  # the host seconds in env.step and in the updates are parts of the wall time
        assert 0 < float(r["env_time_s"]) and 0 < float(r["update_time_s"])
        assert float(r["env_time_s"]) + float(r["update_time_s"]) < float(r["wall_time_s"])
    ev = res["eval"]
    assert 0.0 <= ev["success_rate"] <= 1.0 and ev["episodes"] == 8
    assert json.loads((out / "results.json").read_text())["eval"] == ev
    printed = capsys.readouterr().out
    assert str(out.resolve()) in printed and "evaluation: success" in printed
    # the saved model loads and acts as the trained one
    loaded = ppo_torch.load_agent(out)
    x = torch.randn(5, loaded.critic[0].in_features)
    assert torch.equal(loaded.act(x), agent.act(x).cpu())


@pytest.mark.fast
@pytest.mark.parametrize("argv, field", [
    (["--num-envs", "0"], "num_envs"),
    (["--num-envs", "-3"], "num_envs"),
    (["--device", "tpu"], "device"),
    (["--env-id", "PennyNope-v0"], "env_id"),
    (["--total-timesteps", "0"], "total_timesteps"),
    (["--seed", "-1"], "seed"),
])
def test_bad_input_is_refused_naming_the_field(argv, field, capsys):
    with pytest.raises(SystemExit) as exc:
        ppo_torch.parse_args(argv)
    assert exc.value.code == 2
    assert field in capsys.readouterr().err


@pytest.mark.fast
def test_check_args_errors_name_the_field():
    with pytest.raises(ValueError, match="num_envs"):
        ppo_torch.check_args(Args(num_envs=0))
    with pytest.raises(ValueError, match="device"):
        ppo_torch.check_args(Args(device="gpu"))
    with pytest.raises(ValueError, match="env_id 'CartPole-v1'"):  # registered with gymnasium, not a penny id
        ppo_torch.check_args(Args(env_id="CartPole-v1"))
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="cuda"):
            ppo_torch.check_args(Args(device="cuda"))


def test_quick_never_writes_into_the_working_directory(reports_untouched):
    _, res = ppo_torch.main(["--quick", "--eval-episodes", "2"])
    assert not (reports_untouched / "runs").exists()


@pytest.mark.fast
def test_config_maps_sb3_hyperparameters():
    from training.train import load_config
    args = ppo_torch.args_from_config(load_config(ppo_torch.ROOT / "configs/train/ppo_reach_ellipse.yaml"))
    assert (args.env_id, args.num_envs, args.num_steps, args.minibatch_size, args.update_epochs) == \
        ("PennyReach-Ellipse-v0", 32, 128, 1024, 10)
    assert args.hidden == (64, 64) and args.total_timesteps == 1_000_000
    with pytest.raises(ValueError, match="use_sde"):
        ppo_torch.args_from_config({"algo_kwargs": {"use_sde": True}})


# -- the env <-> torch boundary ----------------------------------------------------------------
def test_to_tensor_passes_tensors_through_and_converts_numpy():
    t = torch.zeros(3, 2)
    assert to_tensor(t, t.device) is t  # already there: no copy
    a = np.arange(6, dtype=np.float64).reshape(3, 2)
    x = to_tensor(a, "cpu")
    assert x.dtype == torch.float32 and x.shape == (3, 2) and torch.equal(x, torch.arange(6.0).reshape(3, 2))
    b = to_tensor(np.array([True, False]), "cpu", torch.bool)
    assert b.dtype == torch.bool and b.tolist() == [True, False]


def test_actions_go_back_in_the_envs_array_type():
    class Numpy:
        unwrapped = None

    class Torch:
        array_namespace = "torch"

        @property
        def unwrapped(self):
            return self

    Numpy.unwrapped = Numpy()
    act = torch.ones(4, 2)
    assert not env_outputs_torch(Numpy()) and env_outputs_torch(Torch())
    out = env_actions(act, env_outputs_torch(Numpy()))
    assert isinstance(out, np.ndarray) and out.dtype == np.float32 and out.shape == (4, 2)
    assert env_actions(act, env_outputs_torch(Torch())) is act


# -- advantages with NEXT_STEP autoreset --------------------------------------------------------
@pytest.mark.fast
def test_gae_masks_the_reset_step_and_bootstraps_truncation_on_the_last_obs():
    g, lam = 0.9, 0.8
    # one env, 5 steps: 0 ordinary, 1 truncated (returns its last obs), 2 the reset step (masked), 3
    # ordinary, 4 terminated
    rew = torch.tensor([[1.0], [2.0], [0.0], [3.0], [4.0]])
    val = torch.tensor([[0.5], [0.6], [7.0], [0.3], [0.2]])  # val[2]: the value of episode 1's last obs
    term = torch.tensor([[0.0], [0.0], [0.0], [0.0], [1.0]])
    done = torch.tensor([[0.0], [1.0], [0.0], [0.0], [1.0]])
    valid = torch.tensor([[1.0], [1.0], [0.0], [1.0], [1.0]])
    nxt = torch.tensor([9.0])  # value of the obs after the rollout (episode 2's last obs): not used (terminated)
    adv, ret = compute_gae(rew, val, term, done, valid, nxt, g, lam)
    a4 = 4.0 - 0.2  # terminated: no bootstrap
    a3 = 3.0 + g * 0.2 - 0.3 + g * lam * a4
    a1 = 2.0 + g * 7.0 - 0.6  # truncated: bootstrap on the last obs's value; the chain stops
    a0 = 1.0 + g * 0.6 - 0.5 + g * lam * a1
    expected = torch.tensor([[a0], [a1], [0.0], [a3], [a4]])
    assert torch.allclose(adv, expected, atol=1e-6)
    assert torch.allclose(ret, adv + val)


# -- it learns ------------------------------------------------------------------------------------
class BanditVectorEnv:
    """A one-step task in NEXT_STEP autoreset mode, as PennyVectorEnv: the step that ends an episode
    returns its last obs, the next step resets (reward 0, not done). Success: |action - obs * 0.8| < 0.2."""

    def __init__(self, num_envs=16, seed=0):
        self.num_envs = num_envs
        self.single_observation_space = spaces.Box(-1, 1, (1,), np.float32)
        self.single_action_space = spaces.Box(-1, 1, (1,), np.float32)
        self.unwrapped = self
        self.rng = np.random.default_rng(seed)
        self.ended = np.zeros(num_envs, bool)
        self.episodes = 0
        self.reset_steps_with_actions = 0

    def _draw(self):
        return self.rng.uniform(-1, 1, (self.num_envs, 1)).astype(np.float32)

    def reset(self, seed=None):
        self.obs = self._draw()
        return self.obs, {}

    def step(self, actions):
        assert isinstance(actions, np.ndarray) and actions.shape == (self.num_envs, 1)
        a = np.clip(actions[:, 0], -1, 1)
        err = np.abs(a - 0.8 * self.obs[:, 0])
        reset = self.ended
        success = (err < 0.2) & ~reset
        rew = np.where(reset, 0.0, 1.0 - err)
        term = ~reset
        new = self._draw()
        obs = np.where(reset[:, None], new, self.obs)  # the ending step returns the last obs
        self.obs = obs
        self.ended = term
        self.episodes += int(term.sum())
        return obs, rew, term, np.zeros(self.num_envs, bool), {"is_success": success}

    def close(self):
        pass


def test_it_learns_a_bandit_with_next_step_autoreset(tmp_path):
    env = BanditVectorEnv(16)
    args = Args(env_id="bandit", num_envs=16, total_timesteps=16 * 32 * 30, num_steps=32, minibatch_size=128,
                update_epochs=10, learning_rate=1e-2, success_window=200, device="cpu", out=str(tmp_path))
    rows = []
    _, res = ppo_torch.train_agent(args, env=env, log=None, on_update=rows.append)
    first, last = rows[0], rows[-1]
    # a random policy (std 1) succeeds about 15 % of the time; the trained one most of the time
    assert first["success_rate"] < 0.35
    assert last["success_rate"] > 0.8, [round(r["success_rate"], 2) for r in rows]
    assert last["value_loss"] < 0.1 * first["value_loss"]
    # every episode ended once in the env is counted once (the reset steps are no episodes)
    assert last["episodes"] == env.episodes
    assert res["eval"] is None  # a stand-in env has no id to evaluate on


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device (torch.cuda.is_available() is False)")
def test_quick_run_on_cuda(tmp_path):
    out = tmp_path / "run"
    agent, res = ppo_torch.main(["--quick", "--out", str(out), "--device", "cuda"])
    assert res["device"].startswith("cuda") and next(agent.parameters()).is_cuda
    assert json.loads((out / "config.json").read_text())["device_used"].startswith("cuda")
    rows = _rows(out / "progress.csv")
    assert all(math.isfinite(float(r["value_loss"])) for r in rows)


def test_auto_device_follows_cuda():
    assert ppo_torch.resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert ppo_torch.resolve_device("cpu").type == "cpu"


