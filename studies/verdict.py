"""The verdict per (actuation, law, table): which actuations and which walls make the penny's probe tasks
solvable, from theorems and certified witnesses, never from a comparison of RL success rates.

* "impossible (theorem Tk)": the theory proves the probe's task unreachable from every start/target pair the
  cell can draw (docs/controllability_theory.md; penny_env.analysis.controllability_theorems.cell_theorem);
* "possible (witnessed k/N)": at least one of N start/target pairs was solved by an episode of the package's
  own environment that ended with is_success (studies/witness.py);
* "open": neither (no theorem, no witness).

Where a theorem excludes only some of the N pairs drawn (pair_theorem), the verdict says so:
"possible (witnessed k/N; m/N impossible, theorem Tk)" or "open (m/N impossible, theorem Tk)".

Where a theorem proves the task possible given enough time for some of the N pairs (T8.1, T8.2: steer only on the
tables with parallel flat sides, from starts with room; penny_env.analysis.flat_sides.steer_park_theorem, under the
probe's own control rows and torque limit), the verdict leads with it: "possible (theorem T8.2 for p/N pairs, given
enough time; witnessed k/N)". The witnesses stay beside it: they succeed within the probe's time limit, the theorem
without one.

A witnessed success in a cell that a theorem declares impossible is a contradiction (a bug in the
simulator, the witness or the theorem's premises) and raises, rather than letting either win silently.
The RL agents appear beside the verdict as learnability: their pooled success rate as a share of the
witnessed rate.
"""
from __future__ import annotations

import functools

from penny_env.analysis.controllability_theorems import ANCHORS as _THEOREM_ANCHORS

THEORY_DOC = "controllability_theory.md"
# GitHub's anchors of the theory page's headings ("## T2 Steer only" -> #t2-steer-only; a test checks them)
ANCHORS = {"T1": "t1-impact-laws-in-scaled-speeds", **_THEOREM_ANCHORS}

# what the theory says of the cells it does not declare impossible (cited beside the witnessed verdict)
CONTEXT = {"Steer": "T2", "Drive": "T3", "Both": "T4"}


@functools.lru_cache(maxsize=None)
def theorem_of(probe: str, table: str, law: str = "elastic"):
    """(theorem id, statement) where the theory proves every pair of the cell impossible, else None. The
    theory's own code decides (penny_env.analysis.controllability_theorems, which checks the theorem's
    hypotheses against the cell's scene and task: start speeds, tolerances, heading offset)."""
    from penny_env.analysis.controllability_theorems import theorem_for
    from studies.cells import cell_spec

    env_id, overrides = cell_spec(probe, table, "elastic" if law == "-" else law)  # "-": the plane's one cell
    found = theorem_for(env_id, **overrides)
    return None if found is None else (found.id, found.reason)


@functools.lru_cache(maxsize=None)
def possible_by_theorem(probe: str, table: str, law: str, seeds: tuple) -> tuple:
    """(p, ids): how many of the cell's pairs (the probe's reset with these seeds, as the witness study draws them) a
    theorem proves possible given enough time, and the theorems' ids ("T8.1", "T8.2"); (0, "") where none applies."""
    if probe != "Steer" or table == "plane":
        return 0, ""
    import gymnasium as gym

    from penny_env.analysis.flat_sides import Steering, flat_pairs, steer_park_theorem
    from studies.cells import cell_spec

    env_id, overrides = cell_spec(probe, table, law)
    env = gym.make(env_id, **overrides)
    try:
        u = env.unwrapped
        st = Steering.of_scene(u.scene)
        if not flat_pairs(st.table):
            return 0, ""
        ids = []
        for seed in seeds:
            env.reset(seed=int(seed))
            found = steer_park_theorem(st.table, st.law, st.params, st.a1, st.dt, u.state, u.target)
            if found is not None:
                ids.append(found[0])
    finally:
        env.close()
    return len(ids), ", ".join(sorted(set(ids)))


def anchor_of(theorem_id: str) -> str:
    """The theory page's anchor of a statement id ("T2.3" -> the T2 section's)."""
    return ANCHORS[theorem_id.split(".")[0]]


def cell_verdict(probe: str, table: str, witnessed: int, pairs: int, law: str = "elastic", excluded: int = 0,
                 excluded_by: str = "", possible: int = 0, possible_by: str = "") -> str:
    """The verdict of one cell from the theory and the witness counts (k witnessed of N pairs; `excluded` of the
    N pairs impossible by the pair theorems `excluded_by`, e.g. "T2.5"; a pair is never both; `possible` of them
    proved possible given enough time by the theorems `possible_by`, e.g. "T8.1")."""
    for name, v in (("witnessed", witnessed), ("pairs", pairs), ("excluded", excluded), ("possible", possible)):
        if isinstance(v, bool) or int(v) != v:
            raise TypeError(f"{name} must be an integer, got {v!r}")
    if pairs < 1:
        raise ValueError(f"pairs must be >= 1, got {pairs}")
    if not 0 <= witnessed <= pairs:
        raise ValueError(f"witnessed must be in [0, pairs = {pairs}], got {witnessed}")
    if not 0 <= excluded <= pairs - witnessed:
        raise ValueError(f"excluded must be in [0, pairs - witnessed = {pairs - witnessed}] (a witnessed pair that a "
                         f"theorem excludes is a contradiction), got {excluded}")
    thm = theorem_of(probe, table, law)
    if thm is not None:
        if witnessed:
            raise ValueError(f"{probe} on {table}: {witnessed} witnessed pair(s) contradict theorem {thm[0]} "
                             f"({thm[1]}); the simulator, the witness or the theorem's premises are wrong")
        return f"impossible (theorem {thm[0]})"
    if not 0 <= possible <= pairs:
        raise ValueError(f"possible must be in [0, pairs = {pairs}], got {possible}")
    some = f"{excluded}/{pairs} impossible, theorem {excluded_by or '?'}" if excluded else ""
    if possible:
        return (f"possible (theorem {possible_by or '?'} for {possible}/{pairs} pairs, given enough time; "
                f"witnessed {witnessed}/{pairs}{'; ' + some if some else ''})")
    if witnessed:
        return f"possible (witnessed {witnessed}/{pairs}{'; ' + some if some else ''})"
    return f"open ({some})" if some else "open"


def learnability(rl_successes: int, rl_episodes: int, witnessed: int, pairs: int):
    """(RL success rate, its exact 95 % interval, the rate as a share of the witnessed rate, the share's
    interval) or None where the witnessed rate is 0 (nothing to compare with)."""
    from lab.stats import clopper_pearson
    if witnessed == 0:
        return None
    rate = rl_successes / rl_episodes
    lo, hi = clopper_pearson(rl_successes, rl_episodes)
    w = witnessed / pairs
    return rate, (lo, hi), rate / w, (lo / w, hi / w)
