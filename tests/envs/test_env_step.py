"""The one env step (penny_env/step/functional.py): its transition is the physics' event loop (a
certified period a plain flow), it ends the episode where the event loop's cap stops it, and its compiled and
plain-Python runs (single env and vector env) agree bitwise."""
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from penny_env import PennyEnv, PennyVectorEnv
from penny_env.backends import packing
from penny_env.step import functional
from penny_env.envs.core import Core
from penny_env.envs.scene import resolve
from penny_env.physics import scalar
from penny_env.backends.choice import available
from penny_env.physics.scalar import scalar_model
from penny_env.physics.params import PennyParams

needs_numba = pytest.mark.skipif(not available(), reason="numba is not installed")
P = PennyParams()
TABLES = [{"kind": "ellipse", "a": 0.15, "b": 0.2}, {"kind": "circle", "radius": 0.12},
          {"kind": "stadium", "radius": 0.1, "length": 0.15}]


def _bits(a):
    return np.asarray(a, dtype=float).view(np.int64)


def _random_inside(rng, table, n):
    out = []
    while len(out) < n:
        x, y = rng.uniform(-0.2, 0.2, 2)
        ph = rng.uniform(-np.pi, np.pi)
        c, s = math.cos(ph), math.sin(ph)
        if table.h(x + P.R * c, y + P.R * s) < 0 and table.h(x - P.R * c, y - P.R * s) < 0:
            out.append((x, y, rng.normal(), ph, rng.normal() * 20, rng.normal() * 8))
    return out


def _step_setup(table_cfg, law, dt):
    scene, task = resolve("ellipse", "impacts", table=table_cfg, law=law, control_dt=dt, init={"spawn_fraction": 0.05})
    core = Core(scene, task, backend="python")
    return core, functional.env_params(core), scalar_model(core.params, core.table, core.law, core.settings)


@pytest.mark.parametrize("ti", range(3))
@pytest.mark.parametrize("law", ["elastic", "plastic", 0.5])
def test_transition_is_the_event_loop_and_certified_periods_are_flows(ti, law):
    # the env step's interval (scalar.run_interval, one call, as env_step drives it) is the event loop's
    # call, and a period the certificate shows free is one flow
    core, p, m = _step_setup(TABLES[ti], law, 0.05)
    rng = np.random.default_rng(10 + ti)
    states = _random_inside(rng, core.table, 150)
    certified = impacts = 0
    for s in states:
        acc1 = 0.0 if rng.random() < 0.5 else rng.normal() * 40
        acc2 = rng.normal() * 20
        buf = scalar.impact_buffers(1, 64)
        s1, elapsed1 = scalar.run_interval(s, math.cos(s[3]), math.sin(s[3]), acc1, acc2, p.dt, m, False, False, 0, buf,
                                           0, scalar.NO_ARC)
        n = int(buf.count[0])
        times, ends = buf.time[:, 0], buf.end[:, 0]
        ref, imps, _, elapsed = scalar.advance_listing(s, acc1, acc2, p.dt, m, 0)
        assert np.array_equal(_bits(s1), _bits(ref)) and n == len(imps) and elapsed == p.dt == elapsed1
        assert np.array_equal(_bits(times[:n]), _bits([i[0] for i in imps])) and list(ends[:n]) == [i[1] for i in imps]
        if scalar.period_is_free(s, math.cos(s[3]), math.sin(s[3]), acc1, acc2, p.dt, m):
            certified += 1
            assert n == 0 and np.array_equal(_bits(s1), _bits(scalar.flow_penny(s, acc1, acc2, p.dt, m.R)))
        impacts += n
    assert 0 < certified < len(states) and impacts > 5


def _penny_state(s, target=(0.01, 0.0)):
    return functional.PennyState(s, functional.angle_trig(s), target, (1.0, 0.0), 0, 0.05, 0, 0.0)


def _step(entry, st, a0, a1, p, m, k, capacity):
    """One env step through an entry point (backends/env.py): (new PennyState, reward, terminated, truncated,
    energy, limit, buf)."""
    obs, buf = np.zeros((1, 11), np.float32), scalar.impact_buffers(1, capacity)
    out = entry.env_step(tuple(st), a0, a1, packing.pack(p, m, k), obs, tuple(buf))
    s1, trig1, count, dist, steps, time = out[:6]
    assert out[6] == buf.count[0]
    new = functional.PennyState(s1, trig1, st[2], st[3], count, dist, steps, time)
    return (new,) + tuple(out[7:]) + (obs, buf)


def test_transition_stops_where_the_event_cap_stops_the_loop(monkeypatch):
    # the event loop's call (scalar.advance_into) stops after its per-call event cap (m.max_events impacts)
    # with elapsed < the time asked: the step does no more work (bounded work per step, issue 24.4), returns
    # that call's state and impacts, the motion up to there unaltered, the elapsed time, LIMIT_IMPACTS
    core, p, m = _step_setup({"kind": "ellipse", "a": 0.03, "b": 0.011}, "elastic", 0.5)
    p = p._replace(n_act=2, gain2=3.0)  # action (0, 1): acc1 = 0, acc2 = 3 exactly
    entry = core.entry_points("python")  # (its physics is scalar's own functions: the patch below reaches them)
    rng = np.random.default_rng(3)
    calls = []
    advance_into = scalar.advance_into

    def one_impact_per_call(s, acc1, acc2, dt, m, stop_after, buf, row, base, arc):
        calls.append(dt)
        return advance_into(s, acc1, acc2, dt, m, 1, buf, row, base, arc)

    checked = 0
    for s in _random_inside(rng, core.table, 20):
        s = s[:4] + (30.0, s[5])
        ref, imps, _, elapsed = scalar.advance_listing(s, 0.0, 3.0, p.dt, m, 1)
        with monkeypatch.context() as mp:
            mp.setattr(scalar, "advance_into", one_impact_per_call)
            calls.clear()
            new, _, _, truncated, _, limit, _, buf = _step(entry, _penny_state(s), 0.0, 1.0, p, m, core.k, 200)
        assert len(calls) == 1 and buf.count[0] == 1 and len(imps) == 1 and elapsed < p.dt
        assert np.array_equal(_bits(new.s), _bits(ref)) and new.time == elapsed
        assert truncated and limit == functional.LIMIT_IMPACTS
        assert buf.time[0, 0] == imps[0][0] and buf.end[0, 0] == imps[0][1]
        checked += 1
    assert checked == 20


# -- compiled and plain-Python steps agree (moved here from tests/backends/test_compiled.py) -----------------
@needs_numba
def test_compiled_step_truncates_a_capped_period_as_the_plain_step_does():
    # an event loop stopped by its per-call cap (m.max_events impacts) ends the episode, truncated with
    # info "limit" LIMIT_IMPACTS at the state right after the cap's impact, in the compiled step as in
    # the plain one (the same numbers, bitwise), and those impacts are the first of an uncapped period
    core, p, m = _step_setup({"kind": "ellipse", "a": 0.03, "b": 0.011}, "elastic", 0.5)
    capped = m._replace(max_events=2)
    entries = [core.entry_points(t) for t in ("cpu", "python")]
    rng = np.random.default_rng(5)
    checked = 0
    for s in _random_inside(rng, core.table, 20):
        s = s[:4] + (30.0, s[5])
        st = _penny_state(s)
        outs = [_step(e, st, 0.2, 0.9, p, model, core.k, 64) for e, model in
                ((entries[0], capped), (entries[1], capped), (entries[1], m))]
        (a, *ra, obs_a, buf_a), (b, *rb, obs_b, buf_b), (free, *rf, _, buf_f) = outs
        assert np.array_equal(_bits(a.s), _bits(b.s)) and a[1:] == b[1:] and ra == rb
        assert np.array_equal(obs_a, obs_b) and all(np.array_equal(x, y) for x, y in zip(buf_a, buf_b))
        assert buf_f.count[0] > 2 and rf[4] == functional.LIMIT_NONE and free.time == p.dt and not rf[2]
        assert buf_b.count[0] == 2 and rb[2] and rb[4] == functional.LIMIT_IMPACTS and b.time < p.dt
        assert b.time == buf_b.time[1, 0] and np.allclose(buf_b.time[:2, 0], buf_f.time[:2, 0], rtol=0, atol=1e-12)
        checked += 1
    assert checked == 20


def test_backend_choice_and_errors():
    v = PennyVectorEnv(3, backend="auto")
    assert v._core.backend == "numba" and PennyEnv()._core.backend == "numba"
    for cls in (PennyVectorEnv, PennyEnv):
        with pytest.raises(ValueError, match="backend"):
            cls(backend="cuda")
        with pytest.raises(ValueError, match="backend"):
            cls(backend="numpy")  # the numpy backend is gone


def _assert_steps_agree(a, b, t):
    """Two vector-env step results equal: obs, rewards, flags and every info entry under its mask."""
    for x, y in zip(a[:4], b[:4]):
        assert x is None and y is None or np.array_equal(x, y), t
    ia, ib = a[4], b[4]
    assert set(ia) == set(ib), (t, set(ia) ^ set(ib))
    for key in ia:
        if key.startswith("_"):
            assert np.array_equal(ia[key], ib[key]), (t, key)
        elif key == "final_info":  # (Gymnasium's: a dict of arrays with their own masks)
            _assert_steps_agree((None,) * 4 + (ia[key],), (None,) * 4 + (ib[key],), t)
        elif ia[key].dtype == object:  # final_obs
            for i in np.flatnonzero(ia["_" + key]):
                assert np.array_equal(ia[key][i], ib[key][i]), (t, key)
        else:
            m = ia["_" + key]
            assert ia[key].shape == ib[key].shape, (t, key)
            assert np.array_equal(ia[key][m], ib[key][m], equal_nan=True), (t, key)


@needs_numba
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id", ["PennyImpacts-Stadium-v0", "PennyPark-Circle-v0", "PennySteer-Plane-v0"])
def test_vector_backends_agree(env_id, mode):
    envs = [gym.make_vec(env_id, num_envs=64, backend=b, autoreset_mode=mode, max_episode_steps=60).unwrapped
            for b in ("numba", "python")]
    obs = [e.reset(seed=7)[0] for e in envs]
    assert np.array_equal(obs[0], obs[1])
    acts = np.random.default_rng(0).uniform(-1.2, 1.2, (150,) + envs[0].action_space.shape)
    for t, a in enumerate(acts):
        out = [e.step(a) for e in envs]
        assert np.array_equal(envs[0].states, envs[1].states)
        _assert_steps_agree(*out, t)


@needs_numba
def test_vector_info_has_fixed_width_and_exact_counts():
    # a narrow table, long control periods and fast rolling: more impacts per env and step than the
    # info arrays' width (max_impacts_in_info); the count stays exact (the single env lists them all)
    kw = dict(scene="ellipse", task="impacts", table={"kind": "ellipse", "a": 0.03, "b": 0.011}, control_dt=2.0,
              init={"theta_dot": [20.0, 40.0], "spawn_fraction": 0.05}, max_episode_steps=20, impacts_goal=10**6)
    envs = [PennyVectorEnv(6, backend=b, max_impacts_in_info=5, **kw) for b in ("numba", "python")]
    singles = [PennyEnv(**kw) for _ in range(6)]
    for e in envs:
        e.reset(seed=1)
    for i, s in enumerate(singles):
        s.reset(seed=1 + i)
    acts = np.random.default_rng(2).uniform(-1, 1, (19, 6, 2))
    most = 0
    for t, a in enumerate(acts):
        out = [e.step(a) for e in envs]
        _assert_steps_agree(*out, t)
        info = out[0][4]
        assert info["impact_times"].shape == (6, 5) and info["impact_ends"].shape == (6, 5)
        for i, s in enumerate(singles):
            if s._done:  # (its episode ended: the vector env resets it, NEXT_STEP)
                continue
            si = s.step(a[i])[4]
            k = min(si["impacts"], 5)
            assert si["impacts"] == info["impacts"][i]
            assert np.array_equal(si["impact_times"][:k], info["impact_times"][i, :k])
            assert np.isnan(info["impact_times"][i, k:]).all() and (info["impact_ends"][i, k:] == 0).all()
        most = max(most, int(info["impacts"].max()))
    assert most > 16  # beyond the vector info's width and the single env's first buffer (PennyEnv reruns)


def test_auto_falls_back_to_python_without_numba(monkeypatch):
    from penny_env.backends import choice
    monkeypatch.setattr(choice, "available", lambda: False)
    for cls in (PennyVectorEnv, PennyEnv):
        with pytest.warns(UserWarning, match="python"):
            assert cls(backend="auto")._core.backend == "python"
        with pytest.raises(ValueError, match="numba"):
            cls(backend="numba")


@needs_numba
@pytest.mark.parametrize("kw", [dict(scene="stadium", task="impacts"), dict(scene="circle", task="park", law="plastic"),
                                dict(scene="ellipse", task="reach", law=0.5, actuation="steer"),
                                dict(scene="plane", task="reach"),
                                dict(scene="ellipse", task="impacts", table={"kind": "ellipse", "a": 0.03, "b": 0.011},
                                     control_dt=0.5, init={"theta_dot": [20.0, 40.0], "spawn_fraction": 0.05})])
@needs_numba
def test_single_env_backends_agree(kw):
    # the single env's compiled step (backend "numba") and the same functions uncompiled ("python"): bitwise
    envs = [PennyEnv(backend=b, max_episode_steps=60, **kw) for b in ("numba", "python")]
    assert [e._core.backend for e in envs] == ["numba", "python"]
    obs = [e.reset(seed=11)[0] for e in envs]
    assert np.array_equal(obs[0], obs[1])
    acts = np.random.default_rng(4).uniform(-1.2, 1.2, (150,) + envs[0].action_space.shape).astype(np.float32)
    impacts = 0
    for t, a in enumerate(acts):
        out = [e.step(a) for e in envs]
        assert np.array_equal(out[0][0], out[1][0]) and out[0][1:4] == out[1][1:4], t
        i0, i1 = out[0][4], out[1][4]  # info: impact times and ends (arrays), energy, time, distance
        assert i0.keys() == i1.keys() and all(np.array_equal(i0[k], i1[k]) for k in i0), t
        assert np.array_equal(envs[0].state, envs[1].state)
        impacts += out[0][4]["impacts"]
        if out[0][2] or out[0][3]:
            for e in envs:
                e.reset()
    assert impacts > 0 or kw["task"] != "impacts"




# -- the entry points' packing of the constants, and the CPU loop's source --------------------------------
def test_pack_round_trips_every_field_exactly():
    """pack() holds the constants in one float64 array (ints and bools as int64 bits): the generated unpack()
    gives back the very records, the int64 range included (the single env's max_steps is int64's max)."""
    core = Core(*resolve("stadium", "impacts"), backend="python")
    p = functional.env_params(core, np.iinfo(np.int64).max)
    m = scalar_model(core.params, core.table, core.law, core.settings)
    c = packing.pack(p, m, core.k)
    assert c.dtype == np.float64 and c.shape == (len(p) + len(m) + len(core.k),)
    p2, m2, k2 = packing.unpacker((type(p), type(m), type(core.k)))(c)
    assert (p2, m2, k2) == (p, m, core.k)
    assert p2.max_steps == np.iinfo(np.int64).max and type(p2.max_steps) is int and type(p2.plane) is bool
    for rec, back in ((p, p2), (m, m2), (core.k, k2)):
        for name in rec._fields:  # the same type, and the same bits for floats
            a, b = getattr(rec, name), getattr(back, name)
            assert type(a) is type(b), name
            if isinstance(a, float):
                assert _bits(a) == _bits(b), name


def test_pack_refuses_a_field_it_cannot_hold():
    from typing import NamedTuple

    class Named(NamedTuple):
        x: float
        name: str
    with pytest.raises(TypeError, match="Named.name"):
        packing.field_kinds((Named,))


def test_unpack_is_defined_from_a_real_file():
    """Nothing is defined by exec where a reader cannot find it: the unpacker's code comes from a generated file
    on disk that holds its source."""
    core = Core(*resolve("ellipse", "reach"), backend="python")
    m = scalar_model(core.params, core.table, core.law, core.settings)
    unpack = packing.unpacker((functional.EnvParams, type(m), type(core.k)))
    path = unpack.__code__.co_filename
    with open(path) as f:
        assert "def unpack(c):" in f.read()


def _loop_extractions(source):
    """The statements NAME = ARG[INT] inside and before the loop of a hoisted loop's source."""
    import ast
    fn = ast.parse(source).body[0]
    params = {a.arg for a in fn.args.args}
    loop = next(s for s in fn.body if isinstance(s, ast.For))

    def is_extraction(n):
        return (isinstance(n, ast.Assign) and isinstance(n.value, ast.Subscript) and isinstance(n.value.value, ast.Name)
                and n.value.value.id in params and isinstance(n.value.slice, ast.Constant))
    before = [s for s in fn.body[:fn.body.index(loop)] if is_extraction(s)]
    inside = [n for n in ast.walk(loop) if is_extraction(n)]
    calls = {n.func.id for n in ast.walk(loop) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
    return before, inside, calls, loop


def test_cpu_loop_takes_the_record_arrays_once_before_the_loop():
    """builder.hoisted_source: the vector step's CPU loop has step_env's statements in place, and every array
    taken from the records (also by the functions pasted in, in any branch) is taken before the loop (numba
    counts references per extraction and penny otherwise); the loop calls none of the pasted functions."""
    from penny_env.backends.builder import hoisted_source
    from penny_env.backends.env import STEP_PASTED
    src = hoisted_source(functional.step_envs, functional.step_env, STEP_PASTED)
    before, inside, calls, loop = _loop_extractions(src)
    assert len(before) >= 14 and inside == []
    assert loop.iter.func.id == "prange" and loop.target.id == "i"
    assert calls.isdisjoint({f.__name__ for f in STEP_PASTED}) and "advance_into" in calls and "step_env" not in calls


def _double_and_count(v, out, j):
    """(test helper for the source inliner) one return, at the end."""
    w = v * 2.0
    if w > 1.0:
        out[j] = w
    else:
        w = -w
    return w, j + 1


def _note(out, j, v):
    """(test helper) a procedure: no return, its array taken from a record."""
    arr = out[0]
    arr[j] = v


def _two_returns(v, out, j):
    if v > 0:
        return v
    return -v


def _loop_body(i, X, out, total):
    v = X[i]
    w, n = _double_and_count(v, out[1], i)
    if w > 0.0:
        _note(out, i, w + n)
    total[i] = w + n


def _loop(X, out, total):
    for i in prange(X.shape[0]):  # noqa: F821 (range in the scope the test runs it in)
        _loop_body(i, X, out, total)


def test_source_inliner_pastes_calls_and_the_pasted_loop_computes_the_same():
    """builder.inline_source: functions pasted in (with one final return, or none at all), their array arguments
    under the caller's own names, their extractions hoisted; the pasted loop computes what the original
    computes; a function that cannot be pasted, or one that is never called, is a BuildError naming it."""
    import ast

    from penny_env.backends.builder import BuildError, hoisted_source, inline_source
    inlined = hoisted_source(_loop, _loop_body, (_double_and_count, _note))
    before, inside, calls, _ = _loop_extractions(inlined)
    assert calls.isdisjoint({"_double_and_count", "_note"}) and inside == [] and len(before) == 2  # out[1], out[0]
    scope = {"prange": range}
    exec(compile(inlined, "<test>", "exec"), scope)  # noqa: S102
    X = np.array([0.2, 0.7, -1.5, 3.0])
    ref = ([np.zeros(4), np.zeros(4)], np.zeros(4))
    got = ([np.zeros(4), np.zeros(4)], np.zeros(4))
    for i in range(4):
        _loop_body(i, X, *ref)
    scope["_loop"](X, *got)
    assert all(np.array_equal(a, b) for a, b in zip(ref[0] + [ref[1]], got[0] + [got[1]]))
    with pytest.raises(BuildError, match="_two_returns cannot be pasted in: it must end in its one return"):
        inline_source(ast.parse("y = _two_returns(v, out, i)").body, (_two_returns,), set())
    with pytest.raises(BuildError, match="keyword"):
        inline_source(ast.parse("y = _double_and_count(v, out, j=i)").body, (_double_and_count,), set())
    with pytest.raises(BuildError, match=r"no call of \['_two_returns'\]"):
        hoisted_source(_loop, _loop_body, (_two_returns,))


def test_a_loop_that_does_not_fit_is_refused_loudly():
    """A loop whose body cannot be placed in the CPU loop raises, naming the loop and the reason (a silent
    fallback would run the slow path unnoticed)."""
    from penny_env.backends.builder import BuildError, hoisted_loop, hoisted_source

    def body_returns(i, a):
        x = a[0]
        if i:
            return
        x[i] = 1.0

    def loop_returns(a):
        for i in prange(a.shape[0]):  # noqa: F821
            body_returns(i, a)

    def body_renamed(j, b):
        x = b[0]
        x[j] = 1.0

    def loop_renamed(a):
        for i in prange(a.shape[0]):  # noqa: F821
            body_renamed(i, a)
    with pytest.raises(BuildError, match="loop_returns: the body body_returns has a return statement"):
        hoisted_source(loop_returns, body_returns)
    with pytest.raises(BuildError, match=r"loop_renamed: the body body_renamed must take \(index, a\)"):
        hoisted_source(loop_renamed, body_renamed)
    with pytest.raises(BuildError, match="not a plain function"):
        hoisted_loop(loop_returns, {})


@needs_numba
@pytest.mark.parametrize("n", [3, 600])
def test_hoisted_loop_steps_like_the_plain_step(n):
    """The compiled vector step (hoisted loop; serial below threads.SERIAL_BELOW, parallel above) equals
    the plain-Python one bitwise, impacts included."""
    out = []
    for backend in ("python", "numba"):
        env = gym.make_vec("PennyImpacts-Stadium-v0", num_envs=n, backend=backend).unwrapped
        env.reset(seed=5)
        rng = np.random.default_rng(1)
        rows = []
        for _ in range(300 if n < 100 else 30):
            obs, rew, term, trunc, info = env.step(rng.uniform(-1, 1, (n, 2)).astype(np.float32))
            rows.append((obs, rew, term, trunc, info["impacts"], info["impact_times"], env.states))
        out.append(rows)
    assert sum(int(r[4].sum()) for r in out[0]) > 0
    for a, b in zip(*out):
        for x, y in zip(a, b):
            assert np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
