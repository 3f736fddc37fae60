"""Compare a method's impacts with the reference: matched / missed / spurious, and errors.

Impacts are matched by time and end with an order-preserving alignment (dynamic programming:
most matches first, then the smallest total time error), so a missed or spurious impact does not
shift the comparison of all later ones. A computed impact can match a reference impact only if
their ends agree and |t - t_ref| <= tol, where tol is ``match_tol`` (default: 0.45 times the
smallest gap between neighbouring reference impacts, capped at 0.05 s, and never below 1e-9 s).

The comparison window: reference impacts up to the method's last simulated time (``t_end``) and
computed impacts up to the last reference time (plus tol) take part; later ones are neither
missed nor spurious (the reference simply does not extend that far).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Match:
    n_ref: int          # reference impacts in the window
    n_found: int        # computed impacts in the window
    matched: int
    missed: int
    spurious: int
    max_abs_err: float  # over matched impacts (nan if none)
    first_divergence: int | None  # index of the first reference impact not matched (None if all)
    pairs: list         # (i_ref, j_found)
    missed_unresolvable: int = 0  # missed reference impacts that float64 cannot resolve (see below)

    @property
    def missed_resolvable(self) -> int:
        return self.missed - self.missed_unresolvable

    def summary(self) -> str:
        extra = f" ({self.missed_unresolvable} below float64 resolution)" if self.missed_unresolvable else ""
        return f"{self.matched}/{self.n_ref} found, {self.missed} missed{extra}, {self.spurious} spurious"


def default_tol(t_ref: np.ndarray) -> float:
    if t_ref.size < 2:
        return 0.05
    gap = float(np.min(np.diff(t_ref)))
    return float(min(0.05, max(1e-9, 0.45 * gap)))


def match_impacts(t_ref, e_ref, t, e, *, t_end=np.inf, n_ref_max=None, match_tol=None, unresolvable=None) -> Match:
    """unresolvable: optional boolean mask over the reference impacts that float64 cannot resolve
    (reference.wall_excursions(scene) <= contact tolerance); their misses are counted apart."""
    t_ref = np.asarray(t_ref, float)
    e_ref = np.asarray(e_ref)
    if n_ref_max is not None:
        t_ref, e_ref = t_ref[:n_ref_max], e_ref[:n_ref_max]
    t = np.asarray(t, float)
    e = np.asarray(e)
    tol = default_tol(t_ref) if match_tol is None else match_tol
    ref_keep = t_ref <= t_end + tol
    t_ref, e_ref = t_ref[ref_keep], e_ref[ref_keep]
    last = t_ref[-1] if t_ref.size else -np.inf
    found_keep = t <= last + tol
    t, e = t[found_keep], e[found_keep]
    n, m = t_ref.size, t.size
    # DP over (i, j): best (matches, -error)
    best_m = np.zeros((n + 1, m + 1), dtype=np.int64)
    best_e = np.zeros((n + 1, m + 1))
    choice = np.zeros((n + 1, m + 1), dtype=np.int8)  # 0 skip ref, 1 skip found, 2 match
    for i in range(n + 1):
        for j in range(m + 1):
            if i == 0 and j == 0:
                continue
            cand = []
            if i > 0:
                cand.append((best_m[i - 1, j], -best_e[i - 1, j], 0))
            if j > 0:
                cand.append((best_m[i, j - 1], -best_e[i, j - 1], 1))
            if i > 0 and j > 0 and e_ref[i - 1] == e[j - 1]:
                d = abs(t_ref[i - 1] - t[j - 1])
                if d <= tol:
                    cand.append((best_m[i - 1, j - 1] + 1, -(best_e[i - 1, j - 1] + d), 2))
            bm, be, c = max(cand)
            best_m[i, j], best_e[i, j], choice[i, j] = bm, -be, c
    pairs = []
    i, j = n, m
    while i > 0 or j > 0:
        c = choice[i, j]
        if c == 2:
            pairs.append((i - 1, j - 1))
            i, j = i - 1, j - 1
        elif c == 0:
            i -= 1
        else:
            j -= 1
    pairs.reverse()
    errs = [abs(t_ref[a] - t[b]) for a, b in pairs]
    matched_ref = {a for a, _ in pairs}
    first_div = next((k for k in range(n) if k not in matched_ref), None)
    n_unres = 0
    if unresolvable is not None:
        unres = np.asarray(unresolvable, bool)
        n_unres = sum(1 for k in range(n) if k not in matched_ref and k < unres.size and unres[k])
    return Match(n, m, len(pairs), n - len(pairs), m - len(pairs), max(errs) if errs else float("nan"),
                 first_div, pairs, n_unres)


def state_error(s, s_ref) -> float:
    """Max abs difference over the 6 components (m, rad, rad/s): nan if s is None."""
    if s is None:
        return float("nan")
    return float(np.max(np.abs(np.asarray(s, float) - np.asarray(s_ref, float))))


def unresolvable_mask(sc) -> np.ndarray:
    """Reference impacts of a scene whose wall excursion is within penny_env's contact tolerance."""
    from penny_env.physics import SolverSettings
    from studies.reference import wall_excursions
    ex = wall_excursions(sc)
    return np.nan_to_num(ex, nan=np.inf) <= SolverSettings().contact_tol * sc.table.size
