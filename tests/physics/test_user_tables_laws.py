"""Users' own tables and laws (issue 24.5): a ConvexTable's inradius is estimated tightly (the
scene's spawn region then fits it), and a registered law is a record (map, Jacobian or None,
energy conservation) that the sensitivities and the event loop read, never the law's name."""
import math

import gymnasium as gym
import numpy as np
import pytest

import penny_env as pe
from penny_env.physics import laws
from penny_env.physics.scalar import scalar_model
from penny_env.physics import PennyParams, SolverSettings
from penny_env.physics.tables import Circle, ConvexTable

A, B = 0.2, 0.14  # the quartic table (x / A)^4 + (y / B)^4 < 1: its inradius is B


def _quartic(extent=(-0.25, 0.25, -0.2, 0.2), shift=0.0):
    def h(x, y):
        return ((((x - shift) / A) ** 4 + (y / B) ** 4) - 1.0) * B / 4

    def grad(x, y):
        return ((x - shift) ** 3 / A ** 4 * B, y ** 3 / B ** 3)

    return ConvexTable(h, grad, grad_bound=3.0, hessian_bound=30.0, extent=extent, name="quartic")


def test_convex_table_inradius_is_tight_and_a_lower_bound():
    # the grid's Lipschitz bound gave 0.0117 m (0.025 m in the units) for a true 0.14 m
    t = _quartic()
    assert B * (1 - 1e-6) < t.inradius <= B
    c = ConvexTable(lambda x, y: (x * x + y * y - 0.1 ** 2) / 0.2, lambda x, y: (x / 0.1, y / 0.1), grad_bound=1.5,
                    hessian_bound=10.0, extent=(-0.12, 0.12, -0.12, 0.12))
    assert 0.1 * (1 - 1e-4) < c.inradius <= 0.1  # (a 720-gon inscribed in the circle)
    # the disk of that radius about the origin is inside the table (the spawn ellipse's centre)
    ang = np.linspace(0, 2 * np.pi, 4000)
    for tab in (t, c):
        assert np.all(tab.h(tab.inradius * np.cos(ang), tab.inradius * np.sin(ang)) <= 0)


def test_off_centre_table_keeps_a_safe_inradius():
    # the origin outside the table: the origin-centred bound is 0 and the grid's bound remains
    t = _quartic(extent=(0.05, 0.55, -0.2, 0.2), shift=0.3)
    assert 0 < t.inradius < B


def test_user_table_in_a_preset_scene():
    # gym.make("PennyReach-Ellipse-v0", table=ConvexTable(...)) was refused: spawn region "does not fit"
    t = _quartic()
    with pytest.warns(UserWarning, match="plain-Python"):
        env = gym.make("PennyReach-Ellipse-v0", table=t)
    for seed in range(5):
        env.reset(seed=seed)
        s = env.unwrapped.state
        for sign in (1, -1):
            assert t.h(s[0] + sign * 0.01 * math.cos(s[3]), s[1] + sign * 0.01 * math.sin(s[3])) < 0
    env.step(env.action_space.sample())


def half_restitution(W, w, a, b, grad2, e, Itot, J, m):
    k = (1.0 + 0.5 * e) * (a * W + b * w) / (a * a / Itot + b * b / J)
    return W - k * a / Itot, w - k * b / J


def half_jacobian(W, w, a, b, grad2, e, Itot, J, m):
    return laws.restitution_jacobian(W, w, a, b, grad2, 0.5 * e, Itot, J, m)


@pytest.fixture
def registered():
    n = len(laws.COMPILED_LAWS)
    names = []

    def register(name, *args, **kw):
        pe.register_law(name, *args, **kw)
        names.append(name)

    yield register
    for name in names:
        del laws.LAW_KINDS[name]
    del laws.COMPILED_LAWS[n:]


S0 = [0.0, 0.0, 0.0, 0.3, 10.0, 0.7]


def test_law_without_jacobian_gives_no_derivative(registered):
    # sensitivity.py applied the built-in restitution Jacobian with the law's e; jacobian_valid stayed True
    registered("half_nojac", half_restitution, e=0.8)
    tr = pe.simulate(S0, table=Circle(0.15), law="half_nojac", n_impacts=3, t_final=5.0, sensitivities=True)
    assert tr.n_impacts == 3 and tr.jacobian_valid is False and "without a Jacobian" in tr.jacobian_reason
    assert np.isnan(tr.jacobian).all()
    # a run without impacts needs no law derivative
    free = pe.simulate(S0, table=Circle(0.15), law="half_nojac", t_final=1e-3, sensitivities=True)
    assert free.n_impacts == 0 and free.jacobian_valid


def test_law_with_jacobian_uses_it(registered):
    # half_restitution with e = 0.8 is the built-in restitution law with e = 0.4: given its Jacobian,
    # the derivatives are those of that law (and without the fix, the built-in Jacobian with e = 0.8)
    registered("half_jac", half_restitution, e=0.8, jacobian=half_jacobian)
    kw = dict(table=Circle(0.15), t_final=4.0, sensitivities=True)
    tr = pe.simulate(S0, law="half_jac", **kw)
    ref = pe.simulate(S0, law=0.4, **kw)
    assert tr.n_impacts >= 2 and tr.jacobian_valid and ref.jacobian_valid
    assert np.allclose(tr.final_state, ref.final_state, rtol=1e-12, atol=1e-14)
    assert np.allclose(tr.jacobian, ref.jacobian, rtol=1e-9, atol=1e-12)
    wrong = pe.simulate(S0, law=0.8, **kw)  # (the Jacobian the law used to get differs)
    assert not np.allclose(wrong.jacobian, ref.jacobian, rtol=1e-3)


def test_energy_conservation_follows_the_record_not_the_name(registered):
    # Model.elastic (the Zeno rule: an accumulation of impacts is never brought to rest) was
    # law.kind == "elastic"; a user's elastic law was treated as dissipative, and any law named
    # "elastic" as conservative
    P, T, S = PennyParams(), Circle(0.15), SolverSettings()
    registered("my_elastic", laws.restitution_update, e=1.0, conserves_energy=True)
    registered("lossy", half_restitution, e=0.8)
    assert scalar_model(P, T, laws.make_law("my_elastic"), S).elastic
    assert not scalar_model(P, T, laws.make_law("lossy"), S).elastic
    assert scalar_model(P, T, laws.make_law("elastic"), S).elastic
    assert not scalar_model(P, T, laws.make_law("plastic"), S).elastic
    assert scalar_model(P, T, laws.ImpactLaw("restitution", 1.0), S).elastic
    assert not scalar_model(P, T, laws.make_law(0.5), S).elastic
    with pytest.raises(TypeError, match="conserves_energy"):
        pe.register_law("bad", half_restitution, conserves_energy=1)
    with pytest.raises(TypeError, match="jacobian"):
        pe.register_law("bad", half_restitution, jacobian="no")


def domain_error_law(W, w, a, b, grad2, e, Itot, J, m):
    """Restitution, except that it takes math.sqrt of a negative number for rolling speeds in (18, 22) rad/s: the
    registration's trial impacts miss that band, the run does not."""
    if 18.0 < abs(W) < 22.0:
        math.sqrt(-1.0)
    k = (1.0 + e) * (a * W + b * w) / (a * a / Itot + b * b / J)
    return W - k * a / Itot, w - k * b / J


def test_a_law_raising_at_run_time_is_named(registered):
    # issue 40, item 9: simulate() ended on a bare "ValueError: math domain error"
    import penny_env.batch as pb
    registered("domain", domain_error_law)
    s0 = [0.0, 0.0, 0.0, 0.0, 20.0, 0.3]
    named = r"law 'domain' \(its update function\) raised ValueError: math domain error.*register_law"
    with pytest.raises(ValueError, match=r"t = [0-9.]+ s: " + named):
        pe.simulate(s0, table=pe.Ellipse(0.15, 0.2), law="domain", t_final=3.0)
    with pytest.raises(ValueError, match=r"interval \d+ \(t = [0-9.]+ s\): " + named):
        pb.simulate(np.array([s0]), table=pe.Ellipse(0.15, 0.2), law="domain", t_final=3.0, backend="python")
    tr = pe.simulate(s0, table=pe.Ellipse(0.15, 0.2), t_final=3.0, n_impacts=1)
    pre = tr.states_at([tr.impact_times[0] * (1 - 1e-15)])[0]
    with pytest.raises(ValueError, match="impact_map: " + named):
        pb.impact_map(pre[None, :], [tr.impact_ends[0]], table=pe.Ellipse(0.15, 0.2), law="domain")
    env = pe.PennyEnv(scene="ellipse", law="domain", backend="python")
    env.reset(seed=0, options={"state": s0})
    with pytest.raises(ValueError, match=r"PennyEnv.step at t = [0-9.]+ s: " + named):
        for _ in range(200):
            env.step(np.zeros(2, np.float32))
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(2, np.float32))
    # an error of penny_env's own is not blamed on the law
    from penny_env.physics.faults import blame
    with pytest.raises(ValueError) as own:
        pe.Ellipse(-0.15, 0.2)
    assert blame(own.value, laws.make_law("domain"), pe.Ellipse(0.15, 0.2)) is None
