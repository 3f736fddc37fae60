"""The verdict per (actuation, law, table): which actuations and which walls make the penny's probe tasks
solvable, from theorems and certified witnesses, never from a comparison of RL success rates.

* "impossible (theorem Tk)": the theory proves the probe's task unreachable from every start of the cell
  (docs/controllability_theory.md, ids below);
* "possible (witnessed k/N)": at least one of N start/target pairs was solved by an episode of the package's
  own environment that ended with is_success (training/witness.py);
* "open": neither (no theorem, no witness).

A witnessed success in a cell that a theorem declares impossible is a contradiction (a bug in the
simulator, the witness or the theorem's premises) and raises, rather than letting either win silently.
The RL agents appear beside the verdict as learnability: their pooled success rate as a share of the
witnessed rate.
"""
from __future__ import annotations

THEORY_DOC = "controllability_theory.md"
# GitHub's anchors of the theory page's headings ("## T2 Steer only" -> #t2-steer-only; a test checks them)
ANCHORS = {"T1": "t1-impact-laws-in-scaled-speeds", "T2": "t2-steer-only", "T3": "t3-drive-only",
           "T4": "t4-both-controls"}

# (probe, table) -> theorem id; the probe's task is impossible there on every law (the plane has no walls)
THEOREMS = {
    ("Steer", "plane"): ("T2", "on the open plane theta_dot is conserved with steering alone, and the probe starts "
                               "with |R theta_dot| >= 0.03 m/s above the 0.01 m/s park tolerance"),
    ("Drive", "plane"): ("T3", "on the open plane phi_dot = 0 is conserved with rolling alone, so the contact point "
                               "stays on its heading line; the targets lie >= 3 cm off it (tolerance 1.5 cm)"),
}
# what the theory says of the cells it does not declare impossible (cited beside the witnessed verdict)
CONTEXT = {"Steer": "T2", "Drive": "T3", "Both": "T4"}


def theorem_of(probe: str, table: str):
    """(theorem id, statement) where the theory proves the cell impossible, else None."""
    return THEOREMS.get((probe, table))


def cell_verdict(probe: str, table: str, witnessed: int, pairs: int) -> str:
    """The verdict of one cell from the theory and the witness counts (k witnessed of N pairs)."""
    for name, v in (("witnessed", witnessed), ("pairs", pairs)):
        if isinstance(v, bool) or int(v) != v:
            raise TypeError(f"{name} must be an integer, got {v!r}")
    if pairs < 1:
        raise ValueError(f"pairs must be >= 1, got {pairs}")
    if not 0 <= witnessed <= pairs:
        raise ValueError(f"witnessed must be in [0, pairs = {pairs}], got {witnessed}")
    thm = theorem_of(probe, table)
    if thm is not None:
        if witnessed:
            raise ValueError(f"{probe} on {table}: {witnessed} witnessed pair(s) contradict theorem {thm[0]} "
                             f"({thm[1]}); the simulator, the witness or the theorem's premises are wrong")
        return f"impossible (theorem {thm[0]})"
    if witnessed:
        return f"possible (witnessed {witnessed}/{pairs})"
    return "open"


def learnability(rl_successes: int, rl_episodes: int, witnessed: int, pairs: int):
    """(RL success rate, its exact 95 % interval, the rate as a share of the witnessed rate, the share's
    interval) or None where the witnessed rate is 0 (nothing to compare with)."""
    from training.study_report import clopper_pearson
    if witnessed == 0:
        return None
    rate = rl_successes / rl_episodes
    lo, hi = clopper_pearson(rl_successes, rl_episodes)
    w = witnessed / pairs
    return rate, (lo, hi), rate / w, (lo / w, hi / w)
