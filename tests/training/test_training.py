"""The training and baseline commands run end to end in --quick mode; configs are checked."""
import importlib.util
import json
from pathlib import Path

import pytest

from studies import baselines
from training import train

REPO = Path(__file__).parents[2]

# training.train and studies.baselines run Stable-Baselines3 (the penny-env[train] extra, with torch)
needs_sb3 = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                               reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")


@needs_sb3
@pytest.mark.parametrize("config", ["configs/train/ppo_reach_ellipse.yaml", "configs/train/sac_park_circle.yaml"])
def test_train_quick(reports_untouched, config):
    tmp_path = reports_untouched / "run"
    results = train.main(["--config", str(REPO / config), "--quick", "--out", "run"])
    assert (tmp_path / "model.zip").exists()
    saved = json.loads((tmp_path / "results.json").read_text())
    for policy in ("trained", "random", "zero"):
        assert 0.0 <= saved[policy]["success_rate"] <= 1.0
        assert saved[policy]["episodes"] == 8
    assert results["timesteps"] == 2048
    assert "| trained |" in (tmp_path / "results.md").read_text()


def test_config_errors_name_the_field(tmp_path):
    bad = tmp_path / "bad.yaml"
    for text, named in (("env_id: PennyReach-Ellipse-v0\nalgo: ppo\nlearning_rat: 0.1\n", "learning_rat"),
                        ("env_id: NoSuchEnv-v0\nalgo: ppo\n", "env_id"),
                        ("env_id: PennyReach-Ellipse-v0\nalgo: dqn\n", "algo"),
                        ("env_id: PennyReach-Ellipse-v0\nalgo: ppo\nnum_envs: 0\n", "num_envs"),
                        ("env_id: [unclosed\n", "invalid YAML")):
        bad.write_text(text)
        with pytest.raises(ValueError, match=named):
            train.load_config(bad)


@needs_sb3
def test_baselines_quick(reports_untouched):
    out = reports_untouched / "baselines.md"
    baselines.main(["--quick", "--out", "baselines.md"])
    text = out.read_text()
    assert text.count("| Penny") == 2 and "zero: success" in text
