"""Which model a run calls its best: the best evaluation during training is a candidate, chosen
among a few noisy evaluations (32 episodes each by default: a checkpoint that scored 1.0 there scored 0.65 on more
episodes, where the final model scored 0.95). When training ends the candidate and the final model play the same
fresh episodes, enough of them (training.train: the config's eval_episodes), and the better one there is kept as
best_model.zip, the final model on a tie; best.json reports both, with 95 % Wilson intervals, and whether the
intervals overlap (then the two are not told apart at that many episodes)."""
from __future__ import annotations

import json
import math
from pathlib import Path


def wilson_interval(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k / n."""
    if n <= 0:
        raise ValueError(f"n must be positive, got {n}")
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def scores(result: dict) -> dict:
    """success rate, its Wilson interval, mean return and episodes of training.episodes.run_episodes' result."""
    n = len(result["success"])
    k = int(sum(bool(v) for v in result["success"]))
    return {"episodes": n, "successes": k, "success_rate": k / n, "ci95_wilson": list(wilson_interval(k, n)),
            "mean_return": float(sum(result["return"]) / n)}


def choose(candidate: dict, final: dict) -> str:
    """"checkpoint" when the candidate did better on the same episodes (success rate, then mean return), else
    "final" (the final model wins ties: it is what the whole budget made)."""
    better = (candidate["success_rate"], candidate["mean_return"]) > (final["success_rate"], final["mean_return"])
    return "checkpoint" if better else "final"


def overlap(a: dict, b: dict) -> bool:
    """The two 95 % intervals overlap: the difference is within what that many episodes can tell apart."""
    return a["ci95_wilson"][0] <= b["ci95_wilson"][1] and b["ci95_wilson"][0] <= a["ci95_wilson"][1]


def confirm_best(env_id: str, final_model, best_model: Path, best_json: Path, load, final_row: tuple,
                 episodes: int, seed: int, candidate_episodes: int) -> dict:
    """Play the candidate (best_model.zip, load(path)) and the final model on the same ``episodes`` episodes from
    ``seed``, keep the better one as best_model.zip, and write best.json: the chosen model's timesteps, success
    rate and mean return in the evaluations during training (final_row: the final model's (timesteps, success
    rate, mean return) there; what a resumed run compares its evaluations with), and "confirmed" with both
    models' scores on the confirmation episodes. Returns that record."""
    from training.episodes import run_episodes
    candidate_record = json.loads(Path(best_json).read_text())
    same = int(candidate_record["timesteps"]) == int(final_row[0])  # the last evaluation was the best: one model
    candidate = final_model if same else load(best_model)
    got = {name: scores(run_episodes(env_id, lambda o, m=m: m.predict(o, deterministic=True)[0], episodes, seed))
           for name, m in (("checkpoint", candidate), ("final", final_model)) if not (same and name == "final")}
    if same:
        got["final"] = got["checkpoint"]
    chosen = choose(got["checkpoint"], got["final"])
    during = {k: candidate_record.get(k) for k in ("timesteps", "success_rate", "mean_return")}
    during["episodes"] = candidate_episodes
    final_during = {"timesteps": int(final_row[0]), "success_rate": float(final_row[1]),
                    "mean_return": float(final_row[2]), "episodes": candidate_episodes}
    record = {**(final_during if chosen == "final" else during), "chosen": chosen,
              "confirmed": {"episodes": episodes, "seed": seed,
                            "checkpoint": {**got["checkpoint"], "timesteps": during["timesteps"],
                                           "during_training": during},
                            "final": {**got["final"], "timesteps": final_during["timesteps"],
                                      "during_training": final_during},
                            "intervals_overlap": overlap(got["checkpoint"], got["final"])}}
    record.pop("episodes")
    if chosen == "final":
        final_model.save(best_model)
    Path(best_json).write_text(json.dumps(record, indent=2))
    return record


def describe(record: dict) -> str:
    """One sentence on best.json's choice, for results.md and training.evaluate."""
    c = record.get("confirmed")
    if not c:
        return ""
    ck, fi = c["checkpoint"], c["final"]

    def fmt(s):
        return f"{s['success_rate']:.3f} [{s['ci95_wilson'][0]:.3f}, {s['ci95_wilson'][1]:.3f}]"
    which = "the final model" if record["chosen"] == "final" else f"the checkpoint at {ck['timesteps']:,} steps"
    noise = " (the intervals overlap: not told apart at that many episodes)" if c["intervals_overlap"] else ""
    return (f"best_model.zip is {which}: on the same {c['episodes']} episodes the best checkpoint during training "
            f"({ck['timesteps']:,} steps, {ck['during_training']['success_rate']:.3f} on "
            f"{ck['during_training']['episodes']} episodes then) scored {fmt(ck)}, the final model "
            f"({fi['timesteps']:,} steps) {fmt(fi)}{noise}")
