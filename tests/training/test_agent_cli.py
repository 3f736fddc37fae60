"""The agents' command line (training/agent_cli.py): every value checked at parse time as a usage error naming its flag,
YAML 1.2 numbers, run folders that two runs cannot share or overwrite, a checkpoint (or "nothing was saved") on
Ctrl-C, and --resume going on from the checkpoint with the run's own settings."""
import dataclasses
import json

import pytest

pytest.importorskip("torch")
from training import agent_cli, ppo_heading  # noqa: E402


def usage_error(capsys, argv) -> str:
    with pytest.raises(SystemExit) as e:
        agent_cli.cli("training.ppo_heading", ppo_heading.Args, _never, argv, ppo_heading.quick_args,
                      ppo_heading.CHECKS)
    assert e.value.code == 2
    return capsys.readouterr().err


def _never(*a, **k):
    raise AssertionError("a refused command must not train")


@pytest.mark.fast
@pytest.mark.parametrize("argv, words", [
    (["--total-timesteps", "nan"], "--total-timesteps must be a finite whole number"),
    (["--total-timesteps", "inf"], "--total-timesteps must be a finite whole number"),
    (["--total-timesteps", "-5"], "--total-timesteps must be a finite whole number"),
    (["--total-timesteps", "0"], "--total-timesteps must be a finite whole number"),
    (["--total-timesteps", "1.5"], "--total-timesteps must be a finite whole number"),
    (["--env-id", "PennyNope-v0"], "'PennyNope-v0' is not a registered penny_env id"),
    (["--seed", "-1"], "seed must be non-negative"),
    (["--hp", "hidden=-5"], "hidden must be positive"),
    (["--hp", "gamma=.nan"], "gamma must be finite"),
    (["--hp", "gamma=1.5"], "gamma must be in [0, 1]"),
    (["--hp", "learning_rate=fast"], "learning_rate must be a number"),
    (["--hp", "num_envs=2.5"], "num_envs must be an integer"),
    (["--hp", "lr_schedule=cosine"], "lr_schedule must be one of"),
    (["--hp", "nope=1"], "['nope'] are not fields"),
    (["--hp", "gamma"], "expected NAME=VALUE"),
    (["--set", "control_dt=-1"], "control_dt"),
    (["--set", "nope=1"], "nope"),
    (["--demos", "/no/such.npz"], "--demos /no/such.npz: no such file"),
    (["--hp", "guide=jsrl"], "guide 'jsrl' needs demos"),
])
def test_a_bad_value_is_a_usage_error_naming_its_flag(capsys, argv, words):
    assert words in usage_error(capsys, argv)


@pytest.mark.fast
def test_numbers_are_read_as_yaml_1_2(capsys):
    ap = agent_cli.parser("training.ppo_heading", ppo_heading.Args)
    a = ap.parse_args(["--hp", "learning_rate=3e-4", "desired_kl=1e-2", "--set", "control_dt=5e-2",
                       "--total-timesteps", "1e8"])
    args = agent_cli.build_args(ap, a, ppo_heading.Args, ppo_heading.CHECKS, None)
    assert args.learning_rate == 3e-4 and args.desired_kl == 0.01 and args.env_kwargs == {"control_dt": 0.05}
    assert args.total_timesteps == 100_000_000 and isinstance(args.total_timesteps, int)


@pytest.mark.fast
def test_run_folders_are_refused_before_any_work(capsys, tmp_path):
    busy = tmp_path / "run"
    busy.mkdir()
    (busy / "model.pt").write_text("a finished run's")
    assert "is not empty (model.pt)" in usage_error(capsys, ["--out", str(busy)])
    f = tmp_path / "file"
    f.write_text("")
    assert "is a file" in usage_error(capsys, ["--out", str(f)])
    from filelock import FileLock
    with FileLock(str(tmp_path / "locked" / ".lock")):
        assert "another training run is writing" in usage_error(capsys, ["--out", str(tmp_path / "locked")])


@pytest.mark.fast
def test_ctrl_c_says_what_was_saved(capsys, tmp_path):
    def stopped(args, checkpoints=(), on_checkpoint=None, log=print, resume=None):
        raise agent_cli.Interrupted(1234, None)
    with pytest.raises(SystemExit) as e:
        agent_cli.cli("training.ppo_heading", ppo_heading.Args, stopped, [], None, ppo_heading.CHECKS)
    assert e.value.code == 130 and "interrupted at 1,234 env steps; nothing was saved" in capsys.readouterr().err


SMALL = ["--total-timesteps", "8192", "--hp", "num_envs=64", "minibatch_size=1024", "val_every=4096",
         "val_episodes=16"]


@pytest.mark.slow
def test_interrupt_then_resume_goes_on_from_the_checkpoint(capsys, tmp_path):
    out = tmp_path / "run"
    real = ppo_heading.train

    def stopped_at(steps_at, error):
        def train(args, checkpoints=(), on_checkpoint=None, log=print, resume=None):
            def stop(steps, policy):
                if steps >= steps_at:
                    raise error
            return real(dataclasses.replace(args, save_every=4096), checkpoints=[2048, 4096, 6144], on_checkpoint=stop,
                        log=log, resume=resume)
        return train

    # a process killed after its last save (not Ctrl-C): checkpoint.pt at 4096, progress.csv one row further
    with pytest.raises(RuntimeError, match="killed"):
        agent_cli.cli("training.ppo_heading", ppo_heading.Args, stopped_at(6144, RuntimeError("killed")),
                      SMALL + ["--out", str(out)], ppo_heading.quick_args, ppo_heading.CHECKS)
    assert (out / "checkpoint.pt").is_file() and "6144," in (out / "progress.csv").read_text()
    # Ctrl-C saves where it stopped and says how to go on
    with pytest.raises(SystemExit) as e:
        agent_cli.cli("training.ppo_heading", ppo_heading.Args, stopped_at(6144, KeyboardInterrupt()),
                      ["--resume", str(out)], ppo_heading.quick_args, ppo_heading.CHECKS)
    err = capsys.readouterr().err
    assert e.value.code == 130 and f"saved {out / 'checkpoint.pt'}" in err and f"--resume {out}" in err
    # a second run into the folder is refused; a resume may change the budget only
    assert "not empty" in usage_error(capsys, ["--quick", "--out", str(out)])
    assert "only --total-timesteps may change" in usage_error(capsys, ["--resume", str(out), "--hp", "gamma=0.9"])
    res = agent_cli.cli("training.ppo_heading", ppo_heading.Args, ppo_heading.train,
                        ["--resume", str(out), "--total-timesteps", "10240"], ppo_heading.quick_args, ppo_heading.CHECKS)
    assert "resumed from" in capsys.readouterr().out
    assert res["env_steps"] == 10240
    rows = (out / "progress.csv").read_text().splitlines()
    assert [int(r.split(",")[0]) for r in rows[1:]] == [2048, 4096, 6144, 8192, 10240]  # (each step once, in order)
    saved = json.loads((out / "results.json").read_text())
    assert saved["args"]["total_timesteps"] == 10240 and saved["env_steps"] == 10240
    assert dataclasses.asdict(ppo_heading.Args())["seed"] == saved["args"]["seed"]
