"""T8 of docs/controllability_theory.md: steer only on the tables with parallel flat sides (the stadium, the rounded
rectangle), and T6.1's aim with turns up to 2 pi.

Each theorem's construction (penny_env/analysis/flat_sides.py) runs as episodes of the steer-only probe's own
environment (gymnasium.make of the probe id with the table's scene and the law, the time limit raised: "given enough
time") from the probe's own seeded starts that meet the theorem's hypothesis, and must end with is_success; on the
way the formulas the proof uses are checked against the simulator (the head-on ladder theta_dot0 (-e0)^k, the full
stop at beta*, the release after the flat free angle pi - 2 beta*, every stop on a flat piece). Each has a mutation
that makes its check fail. The table-level inequalities of T8.2 are recomputed in interval arithmetic (mpmath.iv).
"""
import math

import gymnasium as gym
import numpy as np
import pytest

import penny_env  # noqa: F401  (registers the ids)
from penny_env import Circle, Ellipse, PennyParams, RoundedRectangle, Stadium
from penny_env.analysis import flat_sides as fs
from penny_env.analysis import impact_geometry as ig
from penny_env.analysis.controllability_theorems import wall_distance_lower
from penny_env.analysis import one_input as oi
from penny_env.analysis.one_input import head_on_coefficient

P = PennyParams()
LAW_IDS = {"elastic": "Elastic", "plastic": "Plastic", 0.5: "E05"}


def _env(table, law, steps=40000):
    """The steer-only probe on the table (its preset scene) and law, with a long time limit."""
    if table == "stadium" and law in LAW_IDS:
        return gym.make(f"PennyProbeSteer-Stadium-{LAW_IDS[law]}-v0", max_episode_steps=steps, backend="python")
    return gym.make("PennyProbeSteer-Ellipse-Elastic-v0", scene=table, law=law, max_episode_steps=steps,
                    backend="python")


def _episode(env):
    """An fs.Episode on a gymnasium env (counts the impacts of every step, keeps the last info)."""
    u = env.unwrapped
    box = {"info": {}, "impacts": 0}

    def step(a):
        _, _, term, trunc, info = env.step(np.array([a]))
        box["info"], box["impacts"] = info, box["impacts"] + info["impacts"]
        return term or trunc
    return fs.Episode(step, lambda: u.state, lambda: box["impacts"], lambda: bool(box["info"].get("is_success")))


def _starts(env, law, theorem, n, seeds=range(400)):
    """(seed, start, target, pair, choice) of the first n probe pairs (env.reset(seed)) that T8 decides."""
    u = env.unwrapped
    st = fs.Steering.of_scene(u.scene)
    out = []
    for seed in seeds:
        env.reset(seed=seed)
        s, g = u.state.copy(), u.target.copy()
        found = fs.steer_park_theorem(st.table, law, st.params, st.a1, st.dt, s, g)
        if found is not None and found[0] == theorem:
            out.append((seed, s, g, found[1], found[2]))
            if len(out) == n:
                return out
    raise AssertionError(f"fewer than {n} starts with room")


# -- the geometry ---------------------------------------------------------------------------------------------
def pair_violations(table, pair, n=41):
    """Where a FlatPair is not what T8 needs of the table: a wall point (s, +-b) with |s| <= X off the wall or with a
    normal other than +-n, a corner of the rectangle |s| <= X, |y| <= b outside the table."""
    bad = []
    n_vec = np.array(pair.normal)
    for s in np.linspace(-pair.X, pair.X, n):
        for side in (1, -1):
            p = pair.vector(s, side * pair.b)
            g = np.array(table.grad(*p), float)
            if abs(float(table.h(*p))) > 1e-12 or np.linalg.norm(g / np.linalg.norm(g) - side * n_vec) > 1e-12:
                bad.append((s, side))
    for cs in (1, -1):
        for cy in (1, -1):
            if float(table.h(*pair.vector(cs * pair.X, cy * pair.b))) > 1e-12:
                bad.append(("corner", cs, cy))
    return bad


def test_t8_the_tables_flat_pairs():
    """The stadium has one pair of parallel flat sides, the rounded rectangle two, the ellipse and the circle none; on
    each pair the wall points (s, +-b), |s| <= X, lie on the wall with the normal +-n (every segment s = c across is a
    double normal) and the rectangle lies in the table. The mutation: X 1 % too long puts wall points on the caps."""
    stadium, rr = Stadium(0.1, 0.15), RoundedRectangle(0.3, 0.2, 0.04)
    assert len(fs.flat_pairs(stadium)) == 1 and len(fs.flat_pairs(rr)) == 2
    assert fs.flat_pairs(Ellipse(0.15, 0.2)) == () and fs.flat_pairs(Circle(0.15)) == ()
    for table in (stadium, rr):
        for pair in fs.flat_pairs(table):
            assert pair_violations(table, pair) == []
            longer = fs.FlatPair(pair.normal, pair.along, pair.b, 1.01 * pair.X)
            assert pair_violations(table, longer)


@pytest.mark.parametrize("table", [Stadium(0.1, 0.15), RoundedRectangle(0.3, 0.2, 0.04)], ids=["stadium", "rr"])
def test_t8_clearance_is_the_distance_to_the_wall(table):
    """fs.clearance against the distance to the wall from both sides: at least the proved lower bound of
    controllability_theorems (an inscribed polygon) and at most the distance to a dense sample of wall points."""
    rng = np.random.default_rng(5)
    wall = table.boundary(20000)
    pts = rng.uniform([table.extent[0], table.extent[2]], [table.extent[1], table.extent[3]], (300, 2))
    pts = pts[np.asarray(table.h(pts[:, 0], pts[:, 1])) < 0]
    lower = wall_distance_lower(table, pts)
    for p, lo in zip(pts, lower):
        c = fs.clearance(table, p)
        assert lo <= c + 1e-12 and c <= np.hypot(*(wall - p).T).min() + 1e-12


# -- T6.1 -----------------------------------------------------------------------------------------------------
def test_t6_1_targets_straight_behind_need_turns_beyond_a_half_turn():
    """T6.1 with turns up to 2 pi: a penny creeping at 0.004 m/s (phi_dot = 0) with the target straight behind it
    (3, 5 and 8 cm): no turn of at most pi aims at it (the old lemma's range: the scan finds no zero), a turn beyond pi
    does, and the plan parks in the probe's environment (is_success, no impact)."""
    env = _env("stadium", "elastic", 4000)
    st = fs.Steering.of_scene(env.unwrapped.scene)
    for dist, heading in ((0.03, 0.3), (0.05, 2.0), (0.08, -1.2)):
        start = np.array([0.0, 0.0, 0.0, heading, 0.4, 0.0])
        target = start[:2] - dist * np.array([math.cos(heading), math.sin(heading)])
        assert fs.aim_through(start, target, st, max_turn=math.pi) is None
        acts, delta = fs.aim_through(start, target, st)
        assert math.pi < abs(delta) <= 2 * math.pi
        env.reset(options={"state": start, "target": target})
        ep = _episode(env)
        with pytest.raises(fs.EpisodeEnded):
            ep.rows(acts)
            ep.coast_until(lambda: False)
        assert ep.success() and ep.impacts() == 0, dist
    env.close()


# -- T8.1: dissipative walls ------------------------------------------------------------------------------------
def _ladder_checks(recs, pair, start_td):
    for rec, td0 in zip(recs, start_td):
        assert rec.ladder, "no head-on impact"
        err = max(abs(got - want) for _, got, want in rec.ladder) / abs(td0)
        assert err < 1e-9, err
        assert all(abs(s) <= pair.X for s, _ in rec.impacts_at)  # every impact on the flat pieces


@pytest.mark.parametrize("table, law", [("stadium", "plastic"), ("stadium", 0.5), ("rounded_rectangle", "plastic"),
                                        ("rounded_rectangle", 0.9)], ids=str)
def test_t8_1_ladder_parks_in_the_probe_env(table, law):
    """T8.1 from the probe's own starts with room: aim along the double normals, head-on bounces with theta_dot
    after the k-th equal to theta_dot0 (-e0)^k to 1e-9, every impact on a flat piece, then the creep and T6.1:
    is_success. (On the way the penny may pass slowly through the target: that is a park too.)"""
    env = _env(table, law)
    st = fs.Steering.of_scene(env.unwrapped.scene)
    e0 = head_on_coefficient(law, P)
    recs, tds, phases = [], [], []
    for seed, s, g, pair, _ in _starts(env, law, "T8.1", 3):
        env.reset(options={"state": s, "target": g})
        rec = fs.ladder_park(_episode(env), st, pair, g, e0)
        assert rec.success, (seed, rec.phase)
        recs.append(rec)
        tds.append(s[4])
        phases.append(rec.phase)
        _ladder_checks([rec], pair, [s[4]])
    env.close()
    assert "park" in phases  # at least one went the whole way: ladder, creep, T6.1's turn, the park


def test_t8_1_fails_with_a_wrong_head_on_coefficient():
    """The mutation: the plastic coefficient sideways (3/5) instead of head-on (1/3) mispredicts the ladder."""
    env = _env("stadium", "plastic")
    st = fs.Steering.of_scene(env.unwrapped.scene)
    seed, s, g, pair, _ = _starts(env, "plastic", "T8.1", 1)[0]
    env.reset(options={"state": s, "target": g})
    rec = fs.ladder_park(_episode(env), st, pair, g, 0.6)
    env.close()
    with pytest.raises(AssertionError):
        _ladder_checks([rec], pair, [s[4]])


def test_t8_1_fails_when_the_room_is_too_generous():
    """The mutation of the hypothesis: with the stadium's flat sides taken 40 % longer, the room check accepts a start
    whose aimed line meets a cap; the first impact is then oblique, turns the heading and the ladder check fails."""
    env = _env("stadium", 0.5)
    st = fs.Steering.of_scene(env.unwrapped.scene)
    true = fs.flat_pairs(st.table)[0]
    wide = fs.FlatPair(true.normal, true.along, true.b, 1.4 * true.X)
    start = np.array([0.085, 0.0, 0.0, 0.5 * math.pi - 0.1, 4.0, 0.0])
    assert fs.ladder_room(st.table, wide, start, st.a1, P.R, st.dt)[0]
    assert not fs.ladder_room(st.table, true, start, st.a1, P.R, st.dt)[0]
    env.reset(options={"state": start, "target": np.array([-0.05, 0.02])})
    rec = fs.ladder_park(_episode(env), st, wide, np.array([-0.05, 0.02]), 0.5)
    env.close()
    with pytest.raises(AssertionError):
        _ladder_checks([rec], true, [start[4]])


# -- T8.2: elastic walls ------------------------------------------------------------------------------------------
def _zigzag_checks(rec, table, pair):
    """The proof's formulas on the record of stop_release_park: each stop leaves theta_dot = 0 and
    |phi_dot| = sqrt((I + m R^2) / J) |theta_dot-|; each release comes after the heading turned pi - 2 beta* and
    turns the spin into |theta_dot| = sqrt(J / (I + m R^2)) |phi_dot| (the last one: the chosen slow speed); every
    stop's contact point at |s| <= X - R (its spin circle and the mirror point on the flat piece)."""
    ratio = math.sqrt(P.rolling_inertia / P.J)
    free = math.pi - 2.0 * ig.full_conversion_angle(P)
    assert rec.stops and rec.releases
    for before, after, spin, s in rec.stops:
        assert abs(after) <= 1e-9 * abs(before), (before, after)
        assert abs(abs(spin) - ratio * abs(before)) <= 1e-9 * ratio * abs(before)
        assert abs(s) <= pair.X - P.R
    for want, got, turned, final in rec.releases:
        assert abs(got - want) <= 1e-9 * want, (want, got)
        if not final:
            assert abs(turned - free) <= 1e-9, turned
    assert rec.releases[-1][3], "the last release is the slow one"
    c = fs.zigzag_constants(table, pair, P, 6.25e-7 / P.J, 0.05, 0.05)
    assert all(abs(s) <= c.xi + 0.05 * 0.05 for s in rec.crossings)  # the invariant: crossings within xi (+ a row)


@pytest.mark.parametrize("table", ["stadium", "rounded_rectangle"])
def test_t8_2_stop_and_release_parks_in_the_probe_env(table):
    """T8.2 from the probe's own elastic starts with room: full stops at beta* on the flat sides, releases after the
    flat free angle along the mirror lines, re-aimed toward the centre at the mid-line, a last release at 0.004 m/s,
    the creep and T6.1: is_success, with every formula of the proof holding on the simulator to 1e-9."""
    env = _env(table, "elastic")
    st = fs.Steering.of_scene(env.unwrapped.scene)
    phases = []
    for seed, s, g, pair, choice in _starts(env, "elastic", "T8.2", 3):
        env.reset(options={"state": s, "target": g})
        rec = fs.stop_release_park(_episode(env), st, pair, g, choice)
        assert rec.success, (seed, rec.phase)
        _zigzag_checks(rec, st.table, pair)
        phases.append(rec.phase)
    env.close()
    assert "park" in phases


@pytest.mark.parametrize("mutation", ["stopping angle", "free angle"])
def test_t8_2_fails_with_a_wrong_formula(mutation):
    """The mutations: the stopping angle of restitution 0.5 (16.1 deg) instead of beta* leaves the penny rolling after
    the first stop; the circle's free angle of T7.4 instead of the flat side's pi - 2 beta* mispredicts the last
    release."""
    env = _env("stadium", "elastic", 3000)
    st = fs.Steering.of_scene(env.unwrapped.scene)
    seed, s, g, pair, choice = _starts(env, "elastic", "T8.2", 1)[0]
    env.reset(options={"state": s, "target": g})
    circle = oi.circle_free_angle(0.15, P.R, oi.stop_chord_distance(0.15, ig.full_conversion_angle(P)))
    kw = {"beta": ig.stopping_angle(0.5, P)} if mutation == "stopping angle" else {"free_angle": circle}
    rec = fs.stop_release_park(_episode(env), st, pair, g, choice, **kw)
    env.close()
    with pytest.raises(AssertionError):
        _zigzag_checks(rec, st.table, pair)


def test_t8_2_table_constants_in_interval_arithmetic():
    """T8.2's inequalities on each pair of flat sides (X - R - D > 0, 2 D - d1 > 0, xi - 2 D > 0 at the probes' fastest start,
    0.05 m/s, and rows of 0.05 s), recomputed here in mpmath interval arithmetic from the definitions (beta* =
    atan(sqrt(J / (I + m R^2))), L = b - R cos beta*, D = L tan beta*, the re-aim's rows k: (k/2)^2 a1 dt^2 >= 2 beta*,
    d1 = v (k dt tan beta* + 2 dt sin beta*), xi = X - R + D - d1 where the re-aim has room there): every lower end
    positive, and the module's float values inside the intervals."""
    mpmath = pytest.importorskip("mpmath")
    iv = mpmath.iv
    iv.dps = 30
    v, dt, a1 = iv.mpf("0.05"), iv.mpf("0.05"), iv.mpf(6.25e-7) / iv.mpf(P.J)
    holds = []
    for table in (Stadium(0.1, 0.15), RoundedRectangle(0.3, 0.2, 0.04)):
        for pair in fs.flat_pairs(table):
            c = fs.zigzag_constants(table, pair, P, 6.25e-7 / P.J, 0.05, 0.05)
            q = iv.sqrt(iv.mpf(P.J) / iv.mpf(P.rolling_inertia))  # tan beta*
            mpmath.mp.dps = 30  # (iv has no atan: mpmath's at 30 digits, widened by 1e-25 >> its error)
            beta = iv.mpf([mpmath.atan(q.a) - mpmath.mpf("1e-25"), mpmath.atan(q.b) + mpmath.mpf("1e-25")])
            sin_b, cos_b = q / iv.sqrt(1 + q * q), 1 / iv.sqrt(1 + q * q)
            R, X, b = iv.mpf(P.R), iv.mpf(pair.X), iv.mpf(pair.b)
            L = b - R * cos_b
            D = L * q
            k = 2
            while (iv.mpf(k // 2) ** 2 * a1 * dt * dt - 2 * beta).a < 0:
                k += 2
            d1 = v * (k * dt * q + 2 * dt * sin_b)
            xi = iv.mpf(c.xi)  # (the room part of xi is a bisection on the exact clearance; its bound follows)
            assert xi.a <= (X - R + D - d1).b
            for got, want in ((c.beta, beta), (c.L, L), (c.D, D), (c.d1, d1)):
                assert want.a - 1e-15 <= got <= want.b + 1e-15
            margins = (X - R - D, 2 * D - d1, xi - 2 * D)
            holds.append(c.holds)
            if not c.holds:  # (then zigzag_room never accepts a start on this pair)
                assert any(m.b < 0 for m in margins)
                continue
            for m in margins:
                assert m.a > 0, (table, pair, m)
            # the re-aim after the largest mid-line crossing has room: clearance at the corners of the box where it
            # starts (|s| <= xi + v dt, |y| <= v dt) > R + v k dt
            for cs in (1, -1):
                for cy in (1, -1):
                    corner = pair.vector(cs * (c.xi + 0.05 * 0.05), cy * 0.05 * 0.05)
                    assert iv.mpf(fs.clearance(table, corner)).a - 1e-15 > (R + v * k * dt).b
    # the stadium's sides and the rounded rectangle's long sides; its short sides (X = 0.06 m) are too short for the
    # zigzag across the long way (2 D = 0.115 m)
    assert holds == [True, True, False]


def test_t8_decides_the_probe_pairs():
    """Which probe pairs T8 decides: starts with room and targets with clearance > R on the stadium and the rounded
    rectangle, none on the ellipse or the circle, none with e = 0 (the first head-on impact stops the penny at the
    wall, T2.7)."""
    for table, law in (("stadium", "plastic"), ("rounded_rectangle", "elastic")):
        env = _env(table, law)
        u = env.unwrapped
        st = fs.Steering.of_scene(u.scene)
        found = []
        for seed in range(40):
            env.reset(seed=seed)
            found.append(fs.steer_park_theorem(st.table, law, st.params, st.a1, st.dt, u.state, u.target))
            assert fs.steer_park_theorem(st.table, 0.0, st.params, st.a1, st.dt, u.state, u.target) is None
        env.close()
        decided = sum(f is not None for f in found)
        assert (0 < decided < 40) if table == "stadium" else decided >= 30, (table, decided)
    for law in ("elastic", "plastic"):
        env = gym.make(f"PennyProbeSteer-Ellipse-{LAW_IDS[law]}-v0", backend="python")
        u = env.unwrapped
        st = fs.Steering.of_scene(u.scene)
        env.reset(seed=0)
        assert fs.steer_park_theorem(st.table, law, st.params, st.a1, st.dt, u.state, u.target) is None
        env.close()


def test_t8_numbers_on_the_theory_page():
    """The numbers docs/controllability_theory.md quotes for T8 and for T7.4's worked example are the formulas' values
    (penny_env.analysis.flat_sides and one_input), formatted as the page writes them."""
    import pathlib

    page = " ".join((pathlib.Path(__file__).resolve().parents[2] / "docs" / "controllability_theory.md").read_text()
                    .split())
    a1 = 6.25e-7 / P.J
    beta = ig.full_conversion_angle(P)
    st, rr = Stadium(0.1, 0.15), RoundedRectangle(0.3, 0.2, 0.04)
    cs = fs.zigzag_constants(st, fs.flat_pairs(st)[0], P, a1, 0.05, 0.05)
    cl, cshort = (fs.zigzag_constants(rr, pair, P, a1, 0.05, 0.05) for pair in fs.flat_pairs(rr))
    want = [f"beta* = {math.degrees(beta):.1f} deg", f"Delta_flat = {cs.free_angle:.3f} rad",
            f"{cs.D:.4f} m for `b = 0.1 m`", f"({2 * math.sqrt(2 * beta / a1):.2f} s; 12 rows",
            f"`d1 = {cs.d1:.4f} m`", f"`xi = {cs.xi:.4f} m` and the margins of the table condition "
            + ", ".join(f"{m:.4f}" for m in cs.margins) + " m",
            f"`xi = {cl.xi:.4f} m`, margins " + ", ".join(f"{m:.4f}" for m in cl.margins) + " m",
            f"`X - R - D = {cshort.margins[0]:.4f} m`", f"`2 D = {2 * cshort.D:.3f} m`",
            f"`tau = 2 sqrt(2 pi / a1)` ({fs.aim_time(a1):.2f} s", f"rows of 0.05 s, {fs.aim_time(a1, dt=0.05):.1f} s"]
    tau0 = oi.circle_aim_time(0.5, a1, math.pi / 2)
    ok, (clear, _, _) = oi.circle_stop_room(0.25, (0.1, -0.12), 0.04, tau0, P.R, beta)
    z = math.hypot(0.1, -0.12)
    want += [f"`d* = {oi.stop_chord_distance(0.25, beta):.4f} m`", f"`rho = {0.04 * tau0:.3f} m < d* < |z0| - rho = "
             f"{z - 0.04 * tau0:.3f} m`", f"clearance {clear + P.R:.3f} m > R",
             f"`tau0 = {oi.circle_aim_time(0.5, a1, math.pi):.2f} s`"]
    missing = [w for w in want if w not in page]
    assert ok and not missing, missing


def test_the_readme_says_what_the_theory_page_says():
    """The README's sentence on one input (T7, T8) is the theory page's, word for word."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[2]

    def sentence(text):
        flat = " ".join(text.split())
        return re.search(r"a drive-only penny at rest on any convex table.*?the step that fails named there\.", flat).group(0)
    assert sentence((root / "README.md").read_text()) == sentence((root / "docs" / "controllability_theory.md").read_text())
