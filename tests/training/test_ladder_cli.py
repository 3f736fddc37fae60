"""Every ladder agent has the same command line (training/agent_cli.py): env fields by --set, Args fields by --hp
(an unknown one refused, naming the fields), --quick, --eval, and --out with its results.json."""
import json

import pytest

pytest.importorskip("torch", reason="torch is not installed (the penny-env[train] extra)")

from training import her_sac, ppo_heading  # noqa: E402

AGENTS = {"ppo_heading": ppo_heading, "her_sac": her_sac}


@pytest.mark.parametrize("name", ["ppo_heading", "her_sac"])
def test_quick_run_with_env_fields_writes_its_results(name, tmp_path):
    out = tmp_path / name
    res = AGENTS[name].main(["--quick", "--env-id", "PennyProbeSteer-Stadium-Elastic-v0", "--set", "law=plastic",
                             "--hp", "torch_threads=1", "--eval", "--out", str(out)])
    assert res["env_steps"] > 0 and 0 <= res["eval"]["successes"] <= res["eval"]["episodes"] == 200
    saved = json.loads((out / "results.json").read_text())
    assert saved["args"]["env_kwargs"] == {"law": "plastic"} and saved["args"]["torch_threads"] == 1
    assert saved["eval"] == res["eval"]


@pytest.mark.parametrize("name", sorted(AGENTS))
def test_an_unknown_hyperparameter_is_refused_naming_the_fields(name, capsys):
    with pytest.raises(SystemExit):
        AGENTS[name].main(["--hp", "learning_rat=1e-3"])
    err = capsys.readouterr().err
    assert "learning_rat" in err and "fields:" in err and "env_id" in err
