"""The event loop's run-time guard (issue 31, deliverable 2; physics/scalar.py advance_into, physics/faults.py):
a law that slipped past registration (it misbehaves only away from the trial impacts) or a table whose
declared bounds are false between the points of its grid check. simulate() and the batch API raise a
ValueError naming the law or the table and the bound; the environments end the episode, truncated, with a
named info["limit"] and finite observations. The same on every backend: plain Python, numba, and the CUDA
backend under numba's simulator (in a subprocess, tests/physics/cuda_sim_guard_check.py)."""
import json
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import penny_env as pe
import penny_env.batch as pb
from penny_env.step import functional
from penny_env.physics import laws
from penny_env.physics.tables import ConvexTable

ROOT = Path(__file__).resolve().parents[2]
S_NAN = [0.1, 0, 0, 0, 20.0, 0.5]     # first impact at theta_dot = 20: sneaky gives NaN
S_PUMP = [-0.1, 0, 0, 0, -20.0, 0.5]  # theta_dot = -20: sneaky pumps energy in
TARGET = [0.0, 0.1]


def sneaky(W, w, a, b, grad2, e, Itot, J, m):
    """Elastic at the registration's trial speeds (|theta_dot| in 0.05 .. 7 and 40, 200), but NaN for theta_dot in
    (17, 30) and 3 times the elastic impulse for theta_dot in (-30, -17)."""
    factor = 3.0 if -30.0 < W < -17.0 else 2.0
    k = factor * (a * W + b * w) / (a * a / Itot + b * b / J)
    if 17.0 < W < 30.0:
        return math.nan, w
    return W - k * a / Itot, w - k * b / J


@pytest.fixture(scope="module")
def sneaky_law():
    n = len(laws.COMPILED_LAWS)
    pe.register_law("sneaky", sneaky)  # (registration's trials do not meet its bad speeds)
    yield "sneaky"
    laws.LAW_KINDS.pop("sneaky", None)
    del laws.COMPILED_LAWS[n:]


@pytest.mark.parametrize("start, what", [(S_NAN, "returned a non-finite velocity"), (S_PUMP, "added kinetic energy")])
def test_simulate_raises_naming_the_law(sneaky_law, start, what):
    with pytest.raises(ValueError, match=rf"t = 0\.\d+ s: law 'sneaky' {what} at an impact"):
        pe.simulate(start, table=pe.Ellipse(0.15, 0.2), law=sneaky_law, t_final=1.0)


@pytest.mark.parametrize("backend", ["python", pytest.param("numba", marks=pytest.mark.slow)])
@pytest.mark.parametrize("start, what", [(S_NAN, "returned a non-finite velocity"), (S_PUMP, "added kinetic energy")])
def test_the_batch_raises_naming_the_law_and_the_penny(sneaky_law, backend, start, what):
    if backend == "numba":
        pytest.importorskip("numba")
    fine = [0.0, 0.0, 0.0, 1.0, 5.0, 0.2]
    with pytest.raises(ValueError, match=rf"penny 1, [0-9.e-]+ s into its interval: law 'sneaky' {what}"):
        pb.simulate(np.array([fine, start]), table=pe.Ellipse(0.15, 0.2), law=sneaky_law, t_final=1.0, backend=backend)


def test_impact_map_applies_the_guard_too(sneaky_law):
    # the batch API's and simulate's impact_map apply the law outside the event loop
    table = pe.Ellipse(0.15, 0.2)
    on_wall = [0.15 - 0.01, 0.0, 0.0, 0.0, 20.0, 0.0]  # front end on the wall, moving outward at theta_dot = 20
    with pytest.raises(ValueError, match="state: law 'sneaky' returned a non-finite velocity"):
        pe.impact_map(on_wall, table=table, end=1, law=sneaky_law)
    pumped = [-0.15 + 0.01, 0.0, 0.0, 0.0, -20.0, 0.0]  # back end, theta_dot = -20
    with pytest.raises(ValueError, match=r"states\[1\]: law 'sneaky' added kinetic energy"):
        pb.impact_map(np.array([[0.14, 0.0, 0.0, 0.0, 5.0, 0.0], pumped]), [1, -1], table=table, law=sneaky_law)
    fine = pe.impact_map([0.14, 0.0, 0.0, 0.0, 5.0, 0.3], table=table, end=1, law=sneaky_law)
    assert np.all(np.isfinite(fine))


def _episode(env, start):
    env.reset(seed=0, options={"state": start, "target": TARGET})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for k in range(100):
            out = env.step(np.zeros(env.action_space.shape, np.float32))
            if np.any(out[2]) or np.any(out[3]):
                return k, out, [str(w.message) for w in caught]
    raise AssertionError("the episode did not end")


@pytest.mark.parametrize("backend", ["python", pytest.param("numba", marks=pytest.mark.slow)])
def test_the_single_env_ends_the_episode_with_a_named_limit(sneaky_law, backend):
    # repro_law_nan: observations and rewards became NaN from the next impact on, with no info["limit"]
    if backend == "numba":
        pytest.importorskip("numba")
    for start, code, name in ((S_NAN, functional.LIMIT_LAW_NONFINITE, "law_nonfinite"),
                              (S_PUMP, functional.LIMIT_LAW_ENERGY, "law_energy")):
        env = pe.PennyEnv("ellipse", "reach", law=sneaky_law, backend=backend)
        k, (obs, reward, term, trunc, info), caught = _episode(env, start)
        assert trunc and not term and info["limit"] == code and functional.LIMIT_NAMES[code] == name
        assert np.all(np.isfinite(obs)) and math.isfinite(reward) and np.all(np.isfinite(env.state))
        assert 0 < info["time"] - k * env.scene.control_dt < env.scene.control_dt  # stopped at the impact, inside the step
        assert any(f"info['limit'] = {name!r}" in m and "law 'sneaky'" in m for m in caught)


@pytest.mark.parametrize("backend", ["python", pytest.param("numba", marks=pytest.mark.slow)])
def test_the_vector_env_ends_those_episodes_only(sneaky_law, backend):
    if backend == "numba":
        pytest.importorskip("numba")
    env = pe.PennyVectorEnv(3, "ellipse", "reach", law=sneaky_law, backend=backend)
    starts = np.array([S_NAN, S_PUMP, [0.0, 0.0, 0.0, 1.0, 0.5, 0.1]])
    env.reset(seed=0, options={"state": starts, "target": TARGET})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(100):
            obs, reward, term, trunc, info = env.step(np.zeros((3, 2)))
            if trunc.any():
                break
            assert not caught  # (reported at the step whose info["limit"] shows it, not one step later)
        states = env.states
    assert list(trunc) == [True, True, False] and list(info["limit"]) == [functional.LIMIT_LAW_NONFINITE,
                                                                         functional.LIMIT_LAW_ENERGY, 0]
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward)) and np.all(np.isfinite(states))
    messages = [str(w.message) for w in caught]
    assert any("'law_nonfinite'" in m for m in messages) and any("'law_energy'" in m for m in messages)
    # the single env's episode, bitwise (the same step function)
    single = pe.PennyEnv("ellipse", "reach", law=sneaky_law, backend=backend)
    _, (o1, r1, _, _, i1), _ = _episode(single, S_PUMP)
    assert np.array_equal(o1, obs[1]) and r1 == reward[1] and i1["time"] == info["time"][1]


def ripple_table():
    """A disk of radius 0.15 plus a ripple that vanishes, with its gradient, on every point of the 97 x 97 grid of
    ConvexTable's check: the grid sees the disk's gradient and Hessian, so the declared bounds pass; between
    grid points the gradient ripples by +-0.8 and the Hessian reaches about 750 (declared: 6.7). The
    reliability trial's table of this kind let the ends 6.7 mm outside the true wall, silently."""
    r0, ext, grid = 0.15, (-0.16, 0.16, -0.16, 0.16), 97
    k = math.pi * (grid - 1) / (ext[1] - ext[0])
    amp = 0.8 / k

    def h(x, y):
        return (x * x + y * y - r0 * r0) / (2 * r0) + amp * np.sin(k * (x - ext[0])) * np.sin(k * (y - ext[2]))

    def grad(x, y):
        return (x / r0 + amp * k * np.cos(k * (x - ext[0])) * np.sin(k * (y - ext[2])),
                y / r0 + amp * k * np.sin(k * (x - ext[0])) * np.cos(k * (y - ext[2])))
    return ConvexTable(h, grad, grad_bound=1.1, hessian_bound=1.01 / r0, extent=ext, name="ripple")


RIPPLE_START = [0.0, 0.0, 0.0, 1.0, 25.0, 0.5]


def test_false_bounds_are_named_when_an_end_is_found_outside_the_wall():
    table = ripple_table()  # (accepted: the grid check cannot see the ripple)
    with pytest.raises(ValueError, match=r"an end of the penny was found [0-9.e-]+ m outside the wall of table ripple "
                                         r"\(ConvexTable\).*hessian_bound = 6\.73.*give true bounds") as err:
        pe.simulate(RIPPLE_START, table=table, t_final=2.0)
    depth = float(str(err.value).split("found ")[1].split(" m")[0])
    assert depth > 1e-5  # far beyond the tolerance (1e-8 of the table's size)
    with pytest.warns(RuntimeWarning, match="plain-Python"):
        with pytest.raises(ValueError, match="outside the wall of table ripple"):
            pb.simulate(np.array([RIPPLE_START]), table=table, t_final=2.0)
    with pytest.warns(UserWarning):  # (the plain-Python step: this table has no compiled formulas)
        env = pe.PennyEnv("circle", "reach", table=table)
    k, (obs, _, _, trunc, info), caught = _episode(env, RIPPLE_START)
    assert trunc and info["limit"] == functional.LIMIT_OUTSIDE_WALL and np.all(np.isfinite(obs))
    assert any("'outside_wall'" in m and "table ripple" in m for m in caught)


@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP", "DISABLED"])
def test_the_vector_env_reports_faults_in_every_autoreset_mode(sneaky_law, mode):
    from gymnasium.vector import AutoresetMode
    env = pe.PennyVectorEnv(2, "ellipse", "reach", law=sneaky_law, backend="python",
                            autoreset_mode=getattr(AutoresetMode, mode))
    env.reset(seed=0, options={"state": np.array([S_NAN, [0.0, 0.0, 0.0, 1.0, 0.5, 0.1]]), "target": TARGET})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(100):
            trunc = env.step(np.zeros((2, 2)))[3]
            if trunc.any():
                break
            assert not caught
        assert [str(w.message).count("'law_nonfinite'") for w in caught] == [1]  # (at the step that ended it)
        env.reset(options={"reset_mask": trunc})
        env.step(np.zeros((2, 2)))
    assert len(caught) == 1


def test_the_guard_is_silent_on_sound_laws_and_tables():
    # dense impacts of every built-in law on a table with a C^1,1 wall, with controls and Zeno rests: no fault
    rng = np.random.default_rng(0)
    S = np.zeros((64, 6))
    S[:, 3] = rng.uniform(-np.pi, np.pi, 64)
    S[:, 4] = rng.choice([-1.0, 1.0], 64) * rng.uniform(20, 60, 64)
    S[:, 5] = rng.uniform(-2, 2, 64)
    for law in ("elastic", "plastic", 0.5):
        for table in (pe.RoundedRectangle(0.3, 0.2, 0.03), pe.Stadium(0.1, 0.1)):
            res = pb.simulate(S, table=table, law=law, t_final=2.0, controls=rng.uniform(-1e-6, 1e-6, (20, 2)),
                              control_dt=0.1, backend="python")
            assert res.impact_counts.sum() > 300


@pytest.mark.slow
def test_the_cuda_backend_under_the_simulator_behaves_as_the_cpu():
    pytest.importorskip("numba_cuda")
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "physics" / "cuda_sim_guard_check.py")], capture_output=True,
                       text=True, env=env, timeout=900, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]
    assert [row["case"] for row in rows] == ["vector", "batch"] and all(row["same"] for row in rows), rows
