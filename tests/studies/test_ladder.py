"""The agent ladder (studies/ladder.py): its config is checked before any job runs, its evaluations are log-spaced,
the report's intervals are honest at 0, a single-input success without an impact (or any success on the plane)
stops the report, and --quick runs end to end outside docs/ and the README."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("scipy")
from studies import ladder  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def test_checkpoints_are_half_decades_up_to_the_budget():
    assert ladder.checkpoints(100_000, 20_000_000) == [100_000, 316_228, 1_000_000, 3_162_278, 10_000_000, 20_000_000]
    assert ladder.checkpoints(1000, 1000) == [1000]


def _config(tmp_path, **changes):
    cfg = {"eval_seeds": 4, "seeds": [0], "first_checkpoint": 1000, "demos": {"pairs": 1},
           "cells": [["Steer", "stadium", "elastic"]],
           "agents": {"ppo": {"module": "training.ppo_torch", "privileged": False, "probes": ["Steer"],
                              "budget": {"Steer": 2000}}}}
    cfg.update(changes)
    path = tmp_path / "ladder.yaml"
    import yaml
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.mark.parametrize("changes, message", [
    ({"cells": [["Sideways", "stadium", "elastic"]]}, "a cell is"),
    ({"cells": [["Steer", "stadium", "0.7"]]}, "0.7"),
    ({"agents": {"x": {"module": "training.train", "privileged": False, "probes": ["Steer"], "budget": {"Steer": 1}}}},
     "does not follow training/protocol.py"),
    ({"agents": {"ppo": {"module": "training.ppo_torch", "privileged": False, "probes": ["Steer"],
                         "budget": {"Steer": 10}, "args": {"no_such_field": 1}}}}, "no_such_field"),
    ({"agents": {"ppo": {"module": "training.ppo_torch", "privileged": False, "probes": ["Drive"],
                         "budget": {"Steer": 10}}}}, "no budget for probe Drive"),
    ({"seeds": []}, "seeds"),
    ({"agents": {"ppo": {"module": "training.ppo_torch", "privileged": False, "probes": ["Steer"],
                         "budget": {"Steer": 10}, "seeds": [0, 0]}}}, "agents.ppo.seeds"),
    ({"agents": {"ppo": {"module": "training.ppo_torch", "privileged": False, "probes": ["Steer"],
                         "budget": {"Steer": 10}, "cells": [["Steer", "circle", "elastic"]]}}}, "agents.ppo.cells"),
    ({"agents": {"h": {"module": "training.ppo_heading", "privileged": False, "probes": ["Steer"],
                       "budget": {"Steer": 10}, "args": {"gamma": 1.5}}}}, r"agents.h.args: gamma must be in \[0, 1\]"),
    ({"agents": {"h": {"module": "training.ppo_heading", "privileged": False, "probes": ["Steer"],
                       "budget": {"Steer": 10}, "args": {"lr_schedule": "cosine"}}}}, "lr_schedule must be one of"),
    ({"agents": {"ppo": {"module": "training.ppo_torch", "privileged": False, "probes": ["Steer"],
                         "budget": {"Steer": 10}, "args": {"num_envs": 0}}}}, "num_envs must be a positive integer"),
])

def test_a_bad_config_is_refused_naming_the_field(tmp_path, changes, message):
    with pytest.raises((ValueError, KeyError), match=message):
        ladder.load_config(_config(tmp_path, **changes))


def _result(agent, cell, seed, impacts):
    return {"job": {"agent": agent, "cell": list(cell), "seed": seed}, "cpu_seconds": 1.0,
            "checkpoints": [{"env_steps": 1000, "successes": sum(k >= 0 for k in impacts), "episodes": len(impacts),
                             "impacts_to_success": impacts}]}


def test_the_summary_is_honest_at_zero_and_flags_impact_free_single_input_successes():
    cfg = {"eval_seeds": 4, "cells": [("Steer", "stadium", "elastic"), ("Steer", "plane", "-")],
           "agents": {"a": {"privileged": False}, "b": {"privileged": True}}}
    results = {("a", ("Steer", "stadium", "elastic")): [_result("a", ("Steer", "stadium", "elastic"), s, [-1] * 4)
                                                         for s in (0, 1)],
               ("b", ("Steer", "stadium", "elastic")): [_result("b", ("Steer", "stadium", "elastic"), 0, [2, 1, -1, 3])]}
    summary = ladder.summarize(cfg, results)
    zero = next(s for s in summary if s["agent"] == "a")
    assert zero["success"] == 0 and zero["ci"][0] == 0 and zero["ci"][1] > 0.3  # (8 episodes: an exact bound, not 0)
    some = next(s for s in summary if s["agent"] == "b")
    assert some["impacts_per_success"] == pytest.approx(2.0) and some["without_impact"] == 0
    ladder.check_theorems(summary)  # nothing to flag
    results[("b", ("Steer", "stadium", "elastic"))] = [_result("b", ("Steer", "stadium", "elastic"), 0, [0, -1, -1, -1])]
    with pytest.raises(RuntimeError, match="without an impact"):
        ladder.check_theorems(ladder.summarize(cfg, results))
    results[("a", ("Steer", "plane", "-"))] = [_result("a", ("Steer", "plane", "-"), 0, [1, -1, -1, -1])]
    del results[("b", ("Steer", "stadium", "elastic"))]
    with pytest.raises(RuntimeError, match="on the plane"):
        ladder.check_theorems(ladder.summarize(cfg, results))


def test_a_goal_is_met_only_where_every_seed_and_the_interval_clear_it():
    cell = ("Steer", "stadium", "elastic")
    cfg = {"eval_seeds": 200, "cells": [cell], "agents": {"a": {"privileged": False}}}

    def row(rates):
        res = [_result("a", cell, k, [1] * int(200 * r) + [-1] * (200 - int(200 * r))) for k, r in enumerate(rates)]
        return ladder.summarize(cfg, {("a", cell): res})[0]
    assert ladder.verdict(row([0.97, 0.95, 0.99, 0.96, 0.98]), 0.9, 5)[0] == "met"
    v, words = ladder.verdict(row([0.97, 0.95, 0.99, 0.96, 0.5]), 0.9, 5)  # one seed below: its minimum
    assert v == "not met" or v == "not established"
    assert "minimum 0.50" in words
    assert ladder.verdict(row([0.97, 0.95, 0.99]), 0.9, 5)[0] == "not established"  # too few seeds
    # the pooled rate clears it but the spread of the seeds leaves the interval's lower end below: not established
    v, words = ladder.verdict(row([1.0, 1.0, 1.0, 1.0, 0.6]), 0.9, 1)
    assert v == "not established" and "interval" in words
    lines = ladder.goals(cfg, [row([0.97, 0.95, 0.99, 0.96, 0.98])])
    assert any("Steer-stadium-elastic, without privileged information" in g and "**met**" in g for g in lines)
    assert any("Steer-stadium-elastic, witness-guided" in g and "**not run**" in g for g in lines)


def test_nothing_finished_is_said_and_never_met():
    cells = [("Steer", "stadium", "elastic"), ("Steer", "plane", "-")]
    cfg = {"eval_seeds": 200, "cells": cells, "agents": {"a": {"privileged": False}}}
    lines = ladder.goals(cfg, [])
    assert any("on the plane: **not run**" in g for g in lines)  # no row is not a met goal
    assert not any("**met**" in g for g in lines)
    answer = ladder.answer_sentences(cfg, [])
    assert len(answer) == 1 and "steer only, park" in answer[0] and "no job of this actuation has finished" in answer[0]


def test_the_fall_section_puts_the_recipes_diagnostics_side_by_side(tmp_path):
    cell = ("Steer", "stadium", "elastic")
    cfg = {"eval_seeds": 4, "cells": [cell], "fall": ["a", "b"],
           "agents": {"a": {"privileged": False}, "b": {"privileged": False}}}
    jobs, results = [], {}
    for agent, vals in (("a", [0.1, 0.5, 0.2]), ("b", [0.0, 0.5, 0.6])):
        job = {"agent": agent, "cell": list(cell), "seed": 0}
        jobs.append(job)
        folder = ladder.job_dir(tmp_path, job)
        folder.mkdir(parents=True)
        rows = ["global_step,val_success,train_success,std,lr,approx_kl,clip_frac,explained_variance,grad_norm"]
        rows += [f"{(i + 1) * 1000},{v},0.1,0.2,1e-4,0.01,0.1,0.9,0.5" for i, v in enumerate(vals)]
        rows.insert(2, "1500,nan,0.1,0.2,1e-4,0.01,0.1,0.9,0.5")  # (an update without a validation)
        (folder / "progress.csv").write_text("\n".join(rows) + "\n")
        (folder / "result.json").write_text(json.dumps({"job": job, "checkpoints": []}))
        results[(agent, cell)] = [{"job": job}]
    lines = ladder.fall_section(cfg, jobs, tmp_path, results, tmp_path / "r.md")
    text = "\n".join(lines)
    # the first parks (from which validation success stays at or above 0.01), the peak, then the fall after it
    assert "| a | 0 | 1e+03 (0.200) | 0.50 (2e+03) | 0.20, 0.20 | +0.30 |" in text
    assert "| b | 0 | 2e+03 (0.200) | 0.60 (3e+03) | 0.60, 0.60 | +0.00 |" in text


def test_the_fall_section_shows_the_kept_runs_with_their_commit(tmp_path, monkeypatch):
    cell = ("Steer", "stadium", "elastic")
    kept = ladder.archived_fall_runs(cell)  # docs/ladder_fall/runs.csv, committed
    assert len(kept) >= 2 and all("kept run" in label for label in kept)
    for runs in kept.values():
        for seed, p in runs:
            assert {"val_success", "std", "grad_norm", "lr"} <= set(p) and np.isfinite(p["val_success"]).any()
    assert ladder.archived_fall_runs(("Steer", "circle", "elastic")) == {}
    folder = tmp_path / "fall"
    folder.mkdir()
    (folder / "runs.csv").write_text("recipe,cell,seed,commit,date,env_steps,file,command\n"
                                     "r,Steer-stadium-elastic,0,abc,2026-01-01,1,missing.csv,x\n")
    with pytest.raises(ValueError, match="missing.csv has no rows"):
        ladder.archived_fall_runs(cell, folder / "runs.csv")
    # the section needs no job of the ladder's own while two kept recipes are there
    monkeypatch.setattr(ladder, "FALL_ARCHIVE", ladder.DOCS / "ladder_fall" / "runs.csv")
    cfg = {"eval_seeds": 4, "cells": [cell], "fall": ["a", "b"], "agents": {"a": {}, "b": {}}}
    text = "\n".join(ladder.fall_section(cfg, [], tmp_path, {}, tmp_path / "r.md"))
    assert text.count("kept run") >= 3  # the heading and one row per kept run


def test_the_witnessed_rate_comes_from_the_witness_studys_pairs():
    w = ladder.witnessed_by_seed(("Steer", "ellipse", "elastic"), 200)
    with open(ROOT / "docs" / "witnesses.csv") as f:
        row = next(r for r in csv.DictReader(f) if (r["probe"], r["table"], r["law"]) == ("Steer", "ellipse", "elastic"))
    assert int(w.sum()) == int(row["witnessed"]) and len(w) == int(row["pairs"])


@pytest.mark.slow
def test_quick_run_writes_its_report_outside_docs(reports_untouched):
    out = ladder.main(["--quick", "--workers", "1", "--runs", str(reports_untouched / "runs")])
    text = Path(out).read_text()
    assert "## Goals" in text and "### Steer-stadium-elastic" in text and "### Steer-plane--" in text
    rows = list(csv.DictReader(open(Path(out).with_suffix(".csv"))))
    assert {r["seed"] for r in rows} == {"0", "1"} and {r["probe"] for r in rows} == {"Steer"}
    assert set(rows[0]) == set(ladder.CSV_FIELDS)
    budgets = sorted({int(r["env_steps"]) for r in rows})
    assert budgets[0] >= 1000 and all(0 <= int(r["successes"]) <= int(r["episodes"]) == 8 for r in rows)
    plane = [r for r in rows if r["table"] == "plane"]
    assert plane and all(r["successes"] == "0" for r in plane)
    # resumable: a second run finds every job finished and only rewrites the report
    result = next((reports_untouched / "runs").rglob("result.json"))
    stamp = result.stat().st_mtime_ns
    ladder.main(["--quick", "--workers", "1", "--runs", str(reports_untouched / "runs")])
    assert result.stat().st_mtime_ns == stamp and json.loads(result.read_text())["checkpoints"]
    assert np.isfinite(float(rows[-1]["successes"]))
    # --report-only counts only the results made by this config's jobs: after a change they are stale, not reported
    runs = reports_untouched / "runs"
    changed = reports_untouched / "changed.yaml"
    changed.write_text(ladder.QUICK_CONFIG.read_text().replace("budget: {Steer: 4096}", "budget: {Steer: 100000}"))
    out2 = ladder.main(["--config", str(changed), "--quick", "--runs", str(runs), "--report-only",
                        "--out", str(reports_untouched / "changed.md")])
    text = Path(out2).read_text()
    assert "jobs: 0 of 6 finished" in text and "6 result(s)" in text and "### Steer-stadium-elastic" not in text
    # a damaged result.json stops the report, naming the file
    result.write_bytes(result.read_bytes()[:40])
    with pytest.raises(SystemExit, match=f"{result}.*damaged.*delete it"):
        ladder.main(["--quick", "--runs", str(runs), "--report-only"])
    # two studies never run in one runs folder at once
    from filelock import FileLock
    with FileLock(str(runs / ".lock")):
        with pytest.raises(SystemExit, match="another training run is writing"):
            ladder.main(["--quick", "--workers", "1", "--runs", str(runs)])


@pytest.mark.parametrize("content", [b"", b"null", b"[1, 2]", b"\xff\xfe\x00garbage", b'{"checkpoints": []}'])
def test_a_damaged_result_is_named(tmp_path, content):
    from lab.jobs import DamagedResult, finished, read_result
    path = tmp_path / "result.json"
    path.write_bytes(content)
    with pytest.raises(DamagedResult, match=f"{path} is damaged"):
        read_result(path)
    assert not finished(tmp_path, {}, lambda runs, job: tmp_path)  # (a run reruns the job)


def test_an_agent_may_have_its_own_seeds_and_cells(tmp_path):
    import yaml
    cfg = yaml.safe_load(ladder.QUICK_CONFIG.read_text())
    cfg["agents"]["ppo"].update(seeds=[3], cells=[["Steer", "plane", "-"]])
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    jobs = ladder.make_jobs(ladder.load_config(path))
    assert [(j["cell"], j["seed"]) for j in jobs if j["agent"] == "ppo"] == [(["Steer", "plane", "-"], 3)]
