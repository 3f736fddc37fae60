"""Pure RL retrained fairly on the single-input probes (studies/fair_pure_rl.py, issue 20 item 4): the --quick
run's report and CSVs, the seeds of the evaluation, the witness transitions in SAC's buffer, the goal arithmetic
and the command's errors."""
import csv
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy")
pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")
gym = pytest.importorskip("gymnasium")

import penny_env  # noqa: E402,F401
from studies import fair_pure_rl as fp  # noqa: E402
from studies.stats import clopper_pearson, seed_clustered_ci  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fair_pure") / "fair_pure_rl.md"
    rows = fp.main(["--quick", "--out", str(out)])
    return out, rows


def test_quick_run_writes_report_and_csvs(quick_run):
    out, rows = quick_run
    text = out.read_text()
    for heading in ("## Fairness settings", "## Results", "## Verdict per cell", "## Curves: validation success",
                    "## What works", "## Item 4's goal, counting every learned agent"):
        assert heading in text, heading
    assert re.search(r"^- command: `python -m studies\.fair_pure_rl --quick --out .*fair_pure_rl\.md` \(\d+ s wall",
                     text, re.M)
    assert re.search(r"^- machine: ", text, re.M) and re.search(r"^- date: ", text, re.M)
    assert "- sources: sha256" not in text  # only the committed report carries the provenance line
    with open(out.with_name("fair_pure_rl.csv")) as f:
        got = list(csv.DictReader(f))
    assert list(got[0]) == fp.FIELDS
    assert {(r["probe"], r["table"], r["law"]) for r in got} == set(fp.QUICK_CELLS)
    for cell in fp.QUICK_CELLS:
        assert [r["agent"] for r in got if (r["probe"], r["table"], r["law"]) == cell] == ["witness", *fp.AGENTS]
    with open(out.with_name("fair_pure_rl_curves.csv")) as f:
        curves = list(csv.DictReader(f))
    assert list(curves[0]) == fp.CURVE_FIELDS
    assert {(c["probe"], c["table"], c["law"], c["agent"]) for c in curves} == {
        (*cell, a) for cell in fp.QUICK_CELLS for a in fp.AGENTS}
    for c in curves:
        assert 0.0 <= float(c["val_success"]) <= 1.0
    meta = json.loads(out.with_name("fair_pure_rl_run.json").read_text())
    assert meta["config"] == json.loads(json.dumps(fp.QUICK)) and meta["sources"] is None
    assert meta["gamma"] == fp.GAMMA == 0.999 and meta["reward"]["progress_weight"] == 0.0
    # one results line per row, one curves line per (cell, agent)
    results = [ln for ln in text.split("## Verdict")[0].splitlines() if ln.startswith(("| steer only", "| drive only"))]
    assert len(results) == len(got)


def test_quick_rows_are_consistent(quick_run):
    _, rows = quick_run
    n = fp.QUICK["eval_episodes"]
    for r in rows:
        seeds = r["seeds"]
        assert r["episodes"] == seeds * n
        assert 0 <= r["success"] <= r["episodes"]
        assert r["ci_low"] <= r["rate"] <= r["ci_high"]
        if seeds == 1:
            assert (r["ci_low"], r["ci_high"]) == pytest.approx(clopper_pearson(r["success"], r["episodes"]))
        if r["agent"] == "sac_witness":
            assert r["demo_transitions"] > 0
        if r["agent"] != "witness":
            assert r["goal_met"] == ("yes" if r["witnessed"] and 2 * r["rate"] >= r["witnessed"] / n else "no")


def test_report_only_rewrites_the_same_report(quick_run):
    out, _ = quick_run
    before = out.read_text()
    fp.main(["--quick", "--out", str(out), "--report-only"])
    assert out.read_text() == before


def test_goal_arithmetic_and_seed_clustered_interval():
    cell = ("Steer", "ellipse", "elastic")
    r = fp.agent_row(cell, "X", {}, "ppo", [50, 46], 190, 200, 1, 0, 0.0)  # 96/400 = 0.24 vs 0.95: ratio 0.25
    assert r["goal_met"] == "no" and r["ratio"] == pytest.approx(0.24 / 0.95)
    M = np.array([[1.0] * 50 + [0.0] * 150, [1.0] * 46 + [0.0] * 154])
    assert (r["ci_low"], r["ci_high"]) == pytest.approx(seed_clustered_ci(M))
    assert fp.agent_row(cell, "X", {}, "sac", [95, 96], 190, 200, 1, 0, 0.0)["goal_met"] == "yes"  # 191/400 >= 0.475
    r = fp.agent_row(cell, "X", {}, "sac", [0], 0, 200, 1, 0, 0.0)  # nothing witnessed: no ratio
    assert r["goal_met"] == "no" and math.isnan(r["ratio"])
    r = fp.agent_row(cell, "X", {}, "ppo", [0, 0], 200, 200, 1, 0, 0.0)  # zero successes: an honest upper bound
    assert r["ci_low"] == 0.0 and r["ci_high"] == pytest.approx(clopper_pearson(0, 400)[1]) and r["ratio_high"] > 0


def test_evaluation_seeds_are_the_single_envs_seeds():
    """Sub-env i of the evaluation's vector env reset with seed 0 starts where gymnasium.make(id).reset(seed=i)
    does: the witness study's pairs."""
    from training.episodes import make_vector_env
    from studies.cells import cell_spec
    env_id, ov = cell_spec("Steer", "rounded_rectangle", "elastic")
    v = make_vector_env(env_id, 3, **ov)
    v.reset(seed=0)
    e = gym.make(env_id, **ov)
    for i in range(3):
        e.reset(seed=i)
        assert np.array_equal(e.unwrapped.state, v.states[i]) and np.array_equal(e.unwrapped.target, v.targets[i])
    e.close()
    v.close()


def test_witness_transitions_fill_the_buffer():
    """The certified witness episodes replayed in the training env (the fair reward) succeed, carry the bonus
    only on their last step, and go into an SB3 replay buffer n_envs at a time."""
    from stable_baselines3.common.buffers import ReplayBuffer
    from studies.cells import cell_spec
    env_id, ov = cell_spec("Drive", "ellipse", "elastic")
    demo, n_ok = fp.witness_transitions(env_id, ov, [fp.DEMO_SEED, fp.DEMO_SEED + 1])
    assert n_ok == 2
    n = len(demo["obs"])
    assert demo["done"].sum() == 2 and not demo["timeout"].any()
    assert demo["reward"][demo["done"] > 0] == pytest.approx([fp.REWARD["success_bonus"]] * 2)
    assert not demo["reward"][demo["done"] == 0].any()  # no shaping: nothing but the success bonus
    env = gym.make(env_id, **ov)
    buf = ReplayBuffer(1000, env.observation_space, env.action_space, n_envs=4)
    added = fp.add_to_buffer(buf, demo, 4)
    assert added == n + (-n) % 4 and buf.pos * 4 == added
    env.close()


@pytest.mark.parametrize("argv, names", [
    (["--cells", "Both:ellipse:elastic"], "'Both'"),
    (["--cells", "Steer:moon:elastic"], "'moon'"),
    (["--cells", "Drive:ellipse:rubber"], "'rubber'"),
    (["--agents", "ppo", "dqn"], "'dqn'"),
    (["--seeds", "0"], "--seeds"),
    (["--seeds", "x"], "--seeds"),
])
def test_invalid_arguments_name_what_is_wrong(argv, names, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        fp.main(["--quick", "--out", str(tmp_path / "r.md"), *argv])
    assert exc.value.code == 2
    assert names in capsys.readouterr().err
    assert not (tmp_path / "r.md").exists()


@pytest.mark.parametrize("where", ["docs/fair_pure_rl.md", "docs/sub/fair_pure_rl.md"])
def test_quick_never_writes_into_docs(where, capsys):
    before = sorted(p.name for p in (ROOT / "docs").iterdir())
    with pytest.raises(SystemExit):
        fp.main(["--quick", "--out", str(ROOT / where)])
    assert "never writes into docs/" in capsys.readouterr().err
    assert sorted(p.name for p in (ROOT / "docs").iterdir()) == before


def test_quick_default_out_is_a_temporary_folder(monkeypatch):
    """Without --out, --quick writes into a fresh temporary folder (checked without training)."""
    seen = {}

    def fake_run_cell(cell, agents, cfg, log=print):
        raise RuntimeError("stop")

    monkeypatch.setattr(fp, "run_cell", fake_run_cell)
    import tempfile
    orig = tempfile.mkdtemp
    monkeypatch.setattr(tempfile, "mkdtemp", lambda **kw: seen.setdefault("dir", orig(**kw)))
    with pytest.raises(RuntimeError, match="stop"):
        fp.main(["--quick"])
    assert not Path(seen["dir"]).resolve().is_relative_to((ROOT / "docs").resolve())
