"""The boundary map and its tangent dynamics (penny_env.analysis.boundary_map) and the billiards report:
log-determinants per impact against each law's formula, the elastic map's invariant measure, the sum of
the Lyapunov exponents against the log-determinant, the circle's integrals, and the --quick report."""
import importlib.util
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest

import penny_env as pe
from studies import billiards as bl
from penny_env.analysis import boundary_map as bm
from penny_env.physics import PennyParams, make_table

P = PennyParams()
RHO = float(bm.metric_speed(bl.PAPER_STATE, P))


def orbits(table, law, n=3, impacts=12, seed=0, rescale=None):
    tab = make_table(bl.TABLES[table])
    S, *_ = bm.sample_invariant(n, tab, np.random.default_rng(seed), P, RHO)
    rescale = law != "elastic" if rescale is None else rescale
    return bm.iterate(S, np.ones(n), impacts, table=tab, law=law, params=P, rescale=rescale)


def test_plastic_coefficient_is_the_thin_penny_formula():
    b = np.linspace(-np.pi / 2, np.pi / 2, 101)
    thin = (np.cos(b) ** 2 / 3 + 3 * np.sin(b) ** 2) / (1 + 4 * np.sin(b) ** 2)
    assert np.allclose(bl.plastic_coefficient(b, P), thin, rtol=1e-13)


@pytest.mark.parametrize("law", ["elastic", 0.9, 0.5, "plastic"])
def test_flow_log_det_per_impact_is_two_ln_e(law):
    orb = orbits("ellipse", law)
    _, beta, _, _ = bm.coordinates(orb)
    for i in range(2):
        tm = bm.tangent_maps(orb, i)
        K = len(tm.flow)
        assert K >= 5
        e_eff = orb.restitution[:K, i]
        formula = (bl.plastic_coefficient(beta[1:K + 1, i], P) if law == "plastic" else
                   np.ones(K) if law == "elastic" else np.full(K, law))
        assert np.allclose(e_eff, formula, rtol=1e-9, atol=1e-12)  # the simulator's law is the formula
        logdet = np.log(np.abs(np.linalg.det(tm.flow)))
        assert np.allclose(logdet, 2 * np.log(formula), atol=1e-8)


def test_flow_tangent_maps_agree_with_simulate_sensitivities():
    orb = orbits("stadium", "elastic", n=1, impacts=4)
    tm = bm.tangent_maps(orb, 0)
    t_n = tm.flight[:3].sum()
    extra = 0.5 * tm.flight[3]
    tr = pe.simulate(orb.post[0, 0], params=P, table=make_table(bl.TABLES["stadium"]), law="elastic", t_final=t_n + extra,
                     sensitivities=True)
    assert tr.n_impacts == 3 and tr.jacobian_valid
    from penny_env.physics.sensitivity import flow_jacobian

    Phi, _ = flow_jacobian(tr.impact_states[-1], 0.0, 0.0, tr.final_time - tr.impact_times[-1], P.R)
    mine = Phi[np.ix_(bm.REDUCED, bm.REDUCED)] @ tm.flow[2] @ tm.flow[1] @ tm.flow[0]
    assert np.allclose(mine, tr.jacobian[np.ix_(bm.REDUCED, bm.REDUCED)], rtol=1e-7, atol=1e-7 * np.abs(mine).max())


@pytest.mark.parametrize("table", ["ellipse", "stadium", "rounded rectangle"])
def test_elastic_map_preserves_the_flux_measure_pointwise(table):
    orb = orbits(table, "elastic", n=4, impacts=30)
    _, _, _, nu = bm.coordinates(orb)
    residual, lebesgue = [], []
    for i in range(4):
        tm = bm.tangent_maps(orb, i)
        K = len(tm.section3)
        logdet = np.log(np.abs(np.linalg.det(tm.section3)))
        residual.append(np.abs(logdet + np.log(np.abs(nu[1:K + 1, i] / nu[:K, i]))).max())
        lebesgue.append(np.abs(logdet).max())
    assert max(residual) < 1e-8  # invariant: |nu| ds dbeta dpsi
    assert max(lebesgue) > 1e3 * max(max(residual), 1e-13)  # Lebesgue measure in (s, beta, psi) is not


@pytest.mark.parametrize("law", [0.5, "plastic"])
def test_dissipative_section_log_det_follows_the_flux_formula(law):
    orb = orbits("stadium", law, n=2, impacts=10)
    _, _, _, nu = bm.coordinates(orb)
    tm = bm.tangent_maps(orb, 0)
    K = len(tm.section3)
    lhs = np.log(np.abs(np.linalg.det(tm.section3))) + np.log(np.abs(nu[1:K + 1, 0] / nu[:K, 0]))
    rhs = 2 * np.log(orb.restitution[:K, 0]) - 3 * np.log(orb.speed_ratio[:K, 0])
    assert np.abs(lhs - rhs).max() < 1e-7
    assert np.all(rhs < 0) or law == "plastic"


def test_sum_of_exponents_is_the_log_det_and_elastic_sum_is_zero():
    cfg = dict(bl.CONFIGS["quick"], orbits=2, impacts=60, tangent=2)
    case = bl.run_case("stadium", "elastic", cfg, P, RHO, seed=3)
    assert len(case.section_runs) == 2
    assert np.abs(case.sum_residual).max() < 1e-8
    for run in case.flow_runs:  # the flow preserves volume: its five exponents sum to 0
        assert abs(run[-1].sum()) < 1e-9
    case = bl.run_case("stadium", "e = 0.5", cfg, P, RHO, seed=3)
    # near grazing (where restitution drives every orbit) the tangent maps are ill-conditioned (1 / v_n)
    total = max(np.abs(ld).sum() for ld in case.section_logdet)
    assert np.abs(case.sum_residual).max() < 1e-5 * total


def test_invariant_sample_is_pushed_onto_itself():
    pushed, noise, uniform = bl.pushforward_distance("stadium", 20000, 6, P, RHO, seed=1)
    assert pushed < 1.5 * noise + 0.01
    assert uniform > 3 * pushed  # the histograms resolve the invariant density from a uniform one


def test_circle_reduced_map_is_an_involution_and_keeps_abs_beta():
    for law in ["elastic", 0.9, "plastic"]:
        _, beta, psi, nu = bm.coordinates(orbits("circle", law, impacts=10))
        assert np.nanmax(np.ptp(np.abs(beta), axis=0)) < 1e-9, law
        if law == "elastic":
            assert np.nanmax(np.abs(np.angle(np.exp(1j * (psi[2:] - psi[:-2]))))) < 1e-9
            assert np.nanmax(np.ptp(np.abs(nu), axis=0) / np.abs(nu).max(0)) < 1e-9
    _, beta, _, _ = bm.coordinates(orbits("ellipse", "elastic", impacts=10))
    assert np.nanmax(np.ptp(np.abs(beta), axis=0)) > 1e-3  # not on the ellipse


def test_boundary_coordinates_do_not_depend_on_which_end_is_called_front():
    orb = orbits("ellipse", "elastic", n=4, impacts=3)
    S, ends = orb.post[2], orb.ends[2]
    flipped = S.copy()
    flipped[:, 3] += np.pi
    flipped[:, 4] *= -1
    a = bm.boundary_coordinates(S, ends, orb.table, P)
    b = bm.boundary_coordinates(flipped, -ends, orb.table, P)
    for x, y in zip(a, b):
        assert np.allclose(x, y, atol=1e-12)


@pytest.mark.skipif(importlib.util.find_spec("matplotlib") is None, reason="matplotlib (the plot extra) is not installed")
def test_quick_report_writes_to_a_temporary_directory(reports_untouched, capsys):
    bl.main(["--quick"])
    wrote = re.findall(r"^wrote (\S+?\.md)", capsys.readouterr().out, re.M)
    assert len(wrote) == 1
    out = Path(wrote[0])
    assert Path(tempfile.gettempdir()).resolve() in out.resolve().parents
    text = out.read_text()
    for section in ("## 1. Boundary maps", "## 2. Lyapunov spectra", "## 3. Volume", "## 4. Ergodicity", "## 5."):
        assert section in text
    for png in re.findall(r"\]\((\S+\.png)\)", text):
        assert (out.parent / png).stat().st_size > 0
    assert list(reports_untouched.iterdir()) == []


def test_clopper_pearson_bounds_are_the_binomial_tails_and_honest_at_the_ends():
    """The exact interval's ends solve the binomial tail equations (from math.comb, not from scipy's beta
    quantiles, which lab.stats uses): P(X >= k | lo) = P(X <= k | hi) = 0.025, and 0 or 1 at the ends."""
    pytest.importorskip("scipy.stats")
    from math import comb

    from lab.stats import clopper_pearson

    def cdf(p, m, n):
        return sum(comb(n, j) * p ** j * (1 - p) ** (n - j) for j in range(m + 1))
    for k, n in [(0, 8), (3, 8), (8, 8), (1, 32)]:
        lo, hi = clopper_pearson(k, n)
        assert lo == 0.0 if k == 0 else 1 - cdf(lo, k - 1, n) == pytest.approx(0.025, abs=1e-9)
        assert hi == 1.0 if k == n else cdf(hi, k, n) == pytest.approx(0.025, abs=1e-9)
