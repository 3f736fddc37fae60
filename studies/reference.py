"""The mpmath reference data (studies/reference_data/*.json) as float64 numpy structures.

The files ship with the package (package data) and are written by tests/reference/make_reference.py
(50-digit mpmath, independent of the simulator); numbers are decimal strings. This module only reads them:

* :func:`paper_scenes` / :func:`extra_scenes` -> list of :class:`Scene` (params, table object, law,
  initial state, impact times / ends / post-impact states, the state at a fixed time, controls);
* :func:`flow_cases` -> list of :class:`FlowCase` (open-plane flows with constant controls).

impact_map_cases.json (single impacts, three laws) is read by tests/physics/test_reference.py directly.

The data directory is ``reference_data`` next to this module, or ``$PENNY_REFERENCE_DIR``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import json
import os
from pathlib import Path

import numpy as np

from penny_env.physics import Circle, Ellipse, PennyParams, Stadium
from penny_env.physics.laws import ImpactLaw, make_law

def data_dir() -> Path:
    """Directory of the reference JSON files."""
    env = os.environ.get("PENNY_REFERENCE_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent / "reference_data"


def _f(x) -> float:
    return float(x) if x is not None else None


def _arr(v, shape=None) -> np.ndarray:
    a = np.array([float(x) for x in v] if not (len(v) and isinstance(v[0], list)) else
                 [[float(x) for x in row] for row in v], dtype=float)
    if shape is not None:
        a = a.reshape(shape)
    return a


def make_params(d: dict) -> PennyParams:
    return PennyParams(R=float(d["R"]), m=float(d["m"]), I=float(d["I"]), J=float(d["J"]))


def make_table(d: dict):
    """penny_env table from a reference table dict (the zero sets agree; h may differ by a positive factor)."""
    kind = d["type"]
    if kind == "ellipse":
        a, b = float(d["a"]), float(d["b"])
        return Circle(a) if a == b else Ellipse(a, b)
    if kind == "stadium":
        return Stadium(float(d["radius"]), float(d["length"]))
    raise ValueError(f"unknown reference table type {kind!r}")


def law_of(d: dict) -> ImpactLaw:
    kind = d["law"]
    if kind == "restitution":
        return make_law(float(d["restitution"]))
    return make_law(kind)


@dataclass
class Scene:
    """One reference scene: simulate from ``initial_state``; reference impacts and the state at ``t_final``."""

    name: str
    params: PennyParams
    table: object
    law: ImpactLaw
    initial_state: np.ndarray        # (6,)
    impact_times: np.ndarray         # (k,)
    impact_ends: np.ndarray          # (k,) +1 front / -1 back
    impact_states: np.ndarray        # (k, 6) state right after each impact
    t_final: float
    state_at_t_final: np.ndarray     # (6,)
    controls: np.ndarray | None = None   # (K, 2) rows (u1, u2)
    control_dt: float | None = None
    n_impacts_before_t_final: int | None = None
    rel_normal_speed: np.ndarray | None = None  # (dh/dt)/(|grad h||v_end|) before each impact
    raw: dict = field(default=None, repr=False)

    @property
    def n_impacts(self) -> int:
        return int(self.impact_times.shape[0])


def _scene(d: dict) -> Scene:
    final_key = next(k for k in d if k.startswith("state_at_"))
    controls = d.get("controls")
    diag = d.get("diagnostics") or {}
    rel = diag.get("impact_rel_normal_speed")
    return Scene(
        name=d["name"], params=make_params(d["params"]), table=make_table(d["table"]), law=law_of(d),
        initial_state=_arr(d["initial_state"]), impact_times=_arr(d["impact_times"]),
        impact_ends=np.array(d["impact_ends"], dtype=np.int8),
        impact_states=_arr(d["impact_states"]).reshape(-1, 6), t_final=float(d["t_final"]),
        state_at_t_final=_arr(d[final_key]),
        controls=None if controls is None else _arr(controls).reshape(-1, 2),
        control_dt=_f(d.get("control_interval")),
        n_impacts_before_t_final=d.get("n_impacts_before_t_final"),
        rel_normal_speed=None if rel is None else np.array([np.nan if v is None else v for v in rel], float),
        raw=d)


def load_json(name: str) -> dict:
    path = data_dir() / name
    if not path.exists():
        raise FileNotFoundError(f"reference file {path} is missing: run tests/reference/make_reference.py")
    with open(path) as f:
        return json.load(f)


def paper_scenes() -> list[Scene]:
    """The paper's four scenes (circle / ellipse x elastic / plastic)."""
    return [_scene(d) for d in load_json("paper_scenes.json")["scenes"]]


def extra_scenes() -> list[Scene]:
    """Stadium (elastic), ellipse with restitution 0.6, controlled ellipse (elastic)."""
    return [_scene(d) for d in load_json("extra_scenes.json")["scenes"]]


def scene(name: str) -> Scene:
    for s in paper_scenes() + extra_scenes():
        if s.name == name:
            return s
    raise KeyError(name)


@dataclass
class FlowCase:
    tag: str
    params: PennyParams
    state0: np.ndarray
    u1: float
    u2: float
    t: float
    state_t: np.ndarray


def flow_cases() -> list[FlowCase]:
    return [FlowCase(d["tag"], make_params(d["params"]), _arr(d["state0"]), float(d["u1"]), float(d["u2"]),
                     float(d["t"]), _arr(d["state_t"])) for d in load_json("flow_cases.json")["cases"]]


def wall_excursions(sc: Scene, window: float = 1e-2) -> np.ndarray:
    """For each reference impact of an uncontrolled scene: how far (h, metres in penny_env's table
    scaling) the hitting end would go past the wall if the impact did not happen, computed in
    float64 with penny_env's exact flow from the reference's previous post-impact state (the max
    of h along the free flight near the impact time, located by bisection on dh/dt). Impacts
    whose excursion is below SolverSettings().contact_tol x table size cannot be resolved in
    float64 (the whole grazing event is inside the round-off of h). nan for controlled scenes."""
    from penny_env.physics.params import SolverSettings
    from penny_env.physics.scalar import flow_penny, scalar_model, end_wall_gap
    out = np.full(sc.n_impacts, np.nan)
    if sc.controls is not None:
        return out
    P, T = sc.params, sc.table
    model = scalar_model(P, T, make_law("elastic"), SolverSettings())
    for i in range(sc.n_impacts):
        s = tuple(float(v) for v in (sc.impact_states[i - 1] if i > 0 else sc.initial_state))
        t0 = float(sc.impact_times[i - 1]) if i > 0 else 0.0
        sig = float(sc.impact_ends[i])
        tc = float(sc.impact_times[i]) - t0
        lo, hi = max(tc - window, 0.0), tc + window

        def g(t):
            v, d = end_wall_gap(flow_penny(s, 0.0, 0.0, t, P.R), sig, model)
            return float(v), float(d)
        if g(hi)[1] > 0:  # still rising at the window's end: a transversal impact, not grazing
            out[i] = np.inf
            continue
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if g(mid)[1] > 0:
                lo = mid
            else:
                hi = mid
        out[i] = g(lo)[0]
    return out
