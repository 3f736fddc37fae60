"""studies.scale_rl (issue 30 item 7): the learnability study's --quick run on the CPU, its budget, its report and
its intervals; bad cells and a --quick report into docs/ are refused."""
import csv

import pytest

pytest.importorskip("torch")

from studies import scale_rl  # noqa: E402


def test_quick_run_trains_its_budget_and_reports_every_cell(tmp_path):
    out = tmp_path / "scale_rl.md"
    assert scale_rl.main(["--quick", "--out", str(out)]) == 0
    rows = list(csv.DictReader(open(out.with_suffix(".csv"))))
    cells = {(r["probe"], r["table"], r["law"]) for r in rows}
    assert cells == {tuple(c.split(":")) for c in scale_rl.QUICK_CELLS}
    steps = [int(r["global_step"]) for r in rows]
    # the budget is --steps (2048 in --quick), rounded up to whole rollouts of 16 envs x 32 steps
    assert max(steps) == 2048 and min(steps) < 2048
    for r in rows:
        assert 0 <= int(r["successes"]) <= int(r["episodes"]) == 4
    text = out.read_text()
    assert "2 of 2 cells done" in text and "- command: `" in text and "- device: cpu" in text
    for c in scale_rl.QUICK_CELLS:
        assert " ".join(c.split(":")) in text
    # every row's interval contains its rate and stays in [0, 1] (exact Clopper-Pearson with one seed)
    for r in scale_rl.summarise([{**r, "seed": int(r["seed"]), "global_step": int(r["global_step"]),
                                  "successes": int(r["successes"]), "episodes": int(r["episodes"])} for r in rows]):
        assert 0.0 <= r["lo"] <= r["rate"] <= r["hi"] <= 1.0
        if r["successes"] == 0:
            assert r["lo"] == 0.0 and r["hi"] > 0.3  # honest at 0: 0 of 4 does not exclude rates near 1/2


@pytest.mark.fast
def test_seed_clustered_interval_with_several_seeds():
    rows = [{"probe": "Steer", "table": "stadium", "law": "elastic", "seed": s, "global_step": 100, "successes": k,
             "episodes": 10} for s, k in ((0, 10), (1, 0))]
    (r,) = scale_rl.summarise(rows)
    assert r["rate"] == 0.5 and r["seed_successes"] == "10 0" and r["lo"] < 0.2 and r["hi"] > 0.8


@pytest.mark.fast
def test_bad_cells_and_quick_reports_into_docs_are_refused(capsys):
    with pytest.raises(SystemExit):
        scale_rl.parse(["--quick", "--cells", "Steer:stadium"])
    assert "cell must be PROBE:TABLE:LAW" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        scale_rl.parse(["--quick", "--out", str(scale_rl.ROOT / "docs" / "scale_rl.md")])
    assert "--quick never writes into docs/" in capsys.readouterr().err
    with pytest.raises(ValueError, match="cell must be"):
        scale_rl.parse_cell("Hover:ellipse:elastic")
