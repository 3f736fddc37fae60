"""Config files and command-line overrides with errors that name the file, the field or the item and say what to do
(issue 40, item 9): the training config, the scene YAML, the study config and ppo_torch's --set, each of which was
a bare RecursionError, a silently lost key, an unhashable-type error, IsADirectoryError, UnicodeDecodeError,
FileNotFoundError or yaml's ParserError."""
import pytest

from penny_env import PennyEnv
from penny_env.step.config import ConfigError
from training import train

GOOD = "env_id: PennyReach-Ellipse-v0\nalgo: ppo\nalgo_kwargs:\n  n_steps: 64\n"


@pytest.fixture
def config(tmp_path):
    path = tmp_path / "cfg.yaml"
    path.write_text(GOOD)
    return path


@pytest.mark.parametrize("text, match", [
    ("env_id: " + "[" * 100_000 + "]" * 100_000 + "\n", r"invalid YAML: nested thousands of levels deep; a "
                                                        r"configuration nests at most 64 levels"),
    ("algo_kwargs: " + "{a: " * 80 + "1" + "}" * 80 + "\nenv_id: PennyReach-Ellipse-v0\nalgo: ppo\n",
     r"nested more than 64 levels deep"),
    (GOOD + "env_id: PennyPark-Circle-v0\n", r"found the key 'env_id' twice \(first on line 1\)"),
    ("env_id: [PennyReach-Ellipse-v0]\nalgo: ppo\n", r"env_id must be a string, got list"),
    ("env_id: PennyReach-Ellipse-v0\nalgo: {ppo: 1}\n", r"algo must be a string, got dict"),
    ("env_id: PennyReach-Ellipse-v0\nalgo: ppo\nalgo_kwargs: [1, 2]\n", r"algo_kwargs must be a mapping"),
])
def test_a_bad_training_config_is_named(config, text, match):
    config.write_text(text)
    with pytest.raises(ValueError, match=match):
        train.load_config(config)


def test_a_config_file_that_cannot_be_read_is_named(tmp_path, capsys):
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    latin = tmp_path / "latin.yaml"
    latin.write_bytes(GOOD.encode() + b"# caf\xe9\n")
    for path, match in ((folder, "is a folder, not a YAML file"), (latin, r"is not UTF-8 text \(byte 0xe9 on line 5\)"),
                        (tmp_path / "missing.yaml", "no such file")):
        with pytest.raises(ValueError, match=f"training config .*{match}"):
            train.load_config(path)
    # the command: one usage line and the message, exit status 2 (a FileNotFoundError traceback before)
    with pytest.raises(SystemExit) as exit_:
        train.main(["--config", str(tmp_path / "missing.yaml"), "--quick"])
    assert exit_.value.code == 2 and "missing.yaml: no such file" in capsys.readouterr().err


@pytest.mark.parametrize("item, match", [
    ("net_arch=[64,", r"--set 'net_arch=\[64,': the value '\[64,' is not valid YAML .*quote it"),
    ("seed", r"--set 'seed': give KEY=VALUE"),
    ("=3", r"--set '=3': give KEY=VALUE"),
    ("learning_rate=1e-3", r"unknown field 'learning_rate'.*--set algo_kwargs.learning_rate=1e-3"),
    ("seed.x=1", r"seed is not a mapping; dotted keys go into algo_kwargs or policy_kwargs"),
    ("algo_kwargs.n_steps.x=1", r"algo_kwargs.n_steps is 64, not a mapping"),
])
def test_a_malformed_set_is_named(config, item, match):
    with pytest.raises(ValueError, match=match):
        train.load_config(config, [item])


def test_a_dotted_set_changes_one_hyperparameter(config):
    # --set algo_kwargs.learning_rate=1e-3 was "unknown field", with no word on how to set one hyperparameter
    cfg = train.load_config(config, ["algo_kwargs.learning_rate=1e-3", "policy_kwargs.net_arch=[32, 32]", "seed=4"])
    assert cfg["algo_kwargs"] == {"n_steps": 64, "learning_rate": 1e-3}
    assert cfg["policy_kwargs"] == {"net_arch": [32, 32]} and cfg["seed"] == 4
    # a later --set wins, whole mappings still work
    cfg = train.load_config(config, ["algo_kwargs={gamma: 0.9}", "algo_kwargs.gamma=0.95"])
    assert cfg["algo_kwargs"] == {"gamma": 0.95}


def test_a_scene_file_that_cannot_be_read_is_named(tmp_path):
    folder = tmp_path / "scene.yaml"
    folder.mkdir()
    with pytest.raises(ConfigError, match="is a folder, not a YAML file"):
        PennyEnv(scene=str(folder))
    latin = tmp_path / "latin.yaml"
    latin.write_bytes(b"control_dt: 0.05\n# caf\xe9\n")
    with pytest.raises(ConfigError, match=r"is not UTF-8 text \(byte 0xe9 on line 2\)"):
        PennyEnv(scene=str(latin))
    twice = tmp_path / "twice.yaml"
    twice.write_text("control_dt: 0.05\ncontrol_dt: 0.1\n")
    with pytest.raises(ConfigError, match=r"found the key 'control_dt' twice"):
        PennyEnv(scene=str(twice))


def test_the_ladder_config_and_ppo_torch_sets_are_named_too(tmp_path):
    from studies import ladder
    from training import ppo_torch
    latin = tmp_path / "ladder.yaml"
    latin.write_bytes(b"cells: all\n# \xff\n")
    with pytest.raises(ValueError, match=r"ladder config .*is not UTF-8 text"):
        ladder.load_config(latin)
    with pytest.raises(ValueError, match=r"--set 'table=\{kind: circle': the value .* is not valid YAML"):
        ppo_torch.parse_sets(["table={kind: circle"])
