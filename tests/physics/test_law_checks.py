"""Users' laws are tried when they are registered, never when an env compiles (issue 31, deliverable 1):
physics/law_checks.py. The reproducers of the reliability trial (../shared/measurements/reliability_2026-11-26/)
are copied here: repro_law_edit, repro_law_poison, repro_law_energy and repro_law_nan, plus the trial's small
unclear messages (e = NaN or "0.5") and the siblings found on the way (built-in names, false
conserves_energy claims, names with capitals)."""
import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import penny_env as pe
import penny_env.batch as pb
from penny_env.physics import laws
from penny_env.physics.law_checks import ENERGY_RTOL, trial_arguments, try_law

ROOT = Path(__file__).resolve().parents[2]
S = [0.1, 0, 0, 0, 20.0, 0.5]


@pytest.fixture
def registry():
    """register_law, with every name it registered removed afterwards (and their functions)."""
    n = len(laws.COMPILED_LAWS)
    names = []

    def register(name, *args, **kw):
        names.append(name)
        pe.register_law(name, *args, **kw)

    yield register
    for name in names:
        laws.LAW_KINDS.pop(name, None)
    del laws.COMPILED_LAWS[n:]


def restitution_like(factor):
    """A restitution law with k = factor n / metric (factor 2: elastic; in (1, 2): e = factor - 1)."""
    def update(W, w, a, b, grad2, e, Itot, J, m):
        k = factor * (a * W + b * w) / (a * a / Itot + b * b / J)
        return W - k * a / Itot, w - k * b / J
    return update


def test_the_built_in_laws_pass_the_trials():
    # the trials hold what the built-in laws do: elastic keeps the energy within ENERGY_RTOL, the others lose
    try_law("elastic", laws.restitution_update, 1.0, True)
    for e in (0.0, 0.3, 1.0):
        try_law("restitution", laws.restitution_update, e, False)
    try_law("plastic", laws.plastic_update, 0.0, False)
    args = trial_arguments(1.0)
    assert len(args) > 1000 and all(a[0] * a[2] + a[1] * a[3] > 0 for a in args)  # ends moving outward


def test_wrong_signature_is_refused_and_poisons_nothing():
    # repro_law_poison: register_law("mine", lambda W, w: (-W, -w)) was accepted; every env then failed to compile
    with pytest.raises(TypeError, match=r"register_law\('mine'\): update must take the nine arguments.*\(W, w\)"):
        pe.register_law("mine", lambda W, w: (-W, -w))
    assert "mine" not in laws.LAW_KINDS
    env = pe.PennyEnv("circle", "park")
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))


def test_a_law_that_adds_energy_is_refused():
    # repro_law_energy: 3x the elastic impulse ran 45 impacts to |theta_dot| = 3.4e14, then "rest", complete=True
    with pytest.raises(ValueError, match=r"register_law\('pump'\): update adds kinetic energy.*beyond round-off"):
        pe.register_law("pump", restitution_like(3.0))
    assert "pump" not in laws.LAW_KINDS


def test_a_law_returning_nan_is_refused():
    # repro_law_nan: NaN observations and rewards from the next impact on, no error, no info["limit"]
    with pytest.raises(ValueError, match=r"register_law\('nanlaw'\): update returned a non-finite velocity"):
        pe.register_law("nanlaw", lambda W, w, a, b, g2, e, I, J, m: (W * math.nan, w))


@pytest.mark.fast
@pytest.mark.parametrize("e, error, match", [(math.nan, ValueError, "e must be finite"),
                                             ("0.5", TypeError, "e must be a real number, got str"),
                                             (True, TypeError, "e must be a real number, got bool"),
                                             (math.inf, ValueError, "e must be finite")])
def test_e_must_be_a_finite_real_number(e, error, match):
    with pytest.raises(error, match=match):
        pe.register_law("half", restitution_like(1.5), e)


def test_results_that_are_not_two_real_numbers_are_a_type_error():
    for bad, what in ((lambda W, w, a, b, g2, e, I, J, m: W, "two numbers"),
                      (lambda W, w, a, b, g2, e, I, J, m: (W, "0"), "two real numbers"),
                      (lambda W, w, a, b, g2, e, I, J, m: (W, w, 0.0), "two numbers")):
        with pytest.raises(TypeError, match=what):
            pe.register_law("bad", bad)


def test_an_exception_in_the_law_is_reported_with_the_impact():
    def domain(W, w, a, b, grad2, e, Itot, J, m):
        return W * math.sqrt(e - 2.0), w  # math domain error for e < 2
    with pytest.raises(ValueError, match=r"register_law\('dom'\): update raised ValueError: math domain error on the impact W="):
        pe.register_law("dom", domain, e=0.5)


def test_a_law_numba_cannot_compile_is_refused_with_numbas_message():
    pytest.importorskip("numba")
    def twice(x):  # a plain Python helper: Python runs the law, numba cannot call it
        return 2.0 * x

    def calls_a_helper(W, w, a, b, grad2, e, Itot, J, m):
        k = twice(a * W + b * w) / (a * a / Itot + b * b / J)
        return W - k * a / Itot, w - k * b / J
    with pytest.raises(ValueError, match=r"register_law\('helper'\): numba cannot compile update.*TypingError") as err:
        pe.register_law("helper", calls_a_helper)
    assert "helper" not in laws.LAW_KINDS and len(str(err.value)) < 800


def test_a_false_conserves_energy_claim_is_refused(registry):
    with pytest.raises(ValueError, match="conserves_energy=True, but update loses kinetic energy"):
        pe.register_law("lossy", restitution_like(1.5), conserves_energy=True)
    registry("elastic_too", restitution_like(2.0), conserves_energy=True)  # (elastic: within ENERGY_RTOL)


@pytest.mark.fast
def test_the_built_in_names_cannot_be_replaced():
    # a user's "elastic" would have changed every environment id that runs the elastic law
    for name in ("elastic", "plastic", "restitution", "Elastic"):
        with pytest.raises(ValueError, match="built-in law and cannot be replaced"):
            pe.register_law(name, restitution_like(1.5))
    assert laws.LAW_KINDS["elastic"].update is laws.restitution_update


def test_a_name_with_capitals_is_found(registry):
    # make_law lower-cased every name, so a law registered as "MyLaw" could never be used
    registry("MyLaw", restitution_like(1.5), e=0.5)
    assert laws.make_law("MyLaw").kind == "MyLaw"


def test_registering_a_name_again_replaces_its_law_everywhere(registry):
    # repro_law_edit: v2 registered under v1's name ran v1's compiled code (scalar_model's cache is keyed on the
    # law's (kind, e), which did not change); now every later use runs v2, plain and compiled
    table = pe.Ellipse(0.15, 0.2)
    registry("mylaw", restitution_like(1.5))
    v1 = pe.simulate(S, table=table, law="mylaw", t_final=1.0).final_state
    v1_batch = pb.simulate(np.array([S]), table=table, law="mylaw", t_final=1.0, backend="python").final_states[0]
    with pytest.warns(UserWarning, match="'mylaw' now names the new law"):
        registry("mylaw", restitution_like(1.9))
    v2 = pe.simulate(S, table=table, law="mylaw", t_final=1.0).final_state
    v2_batch = pb.simulate(np.array([S]), table=table, law="mylaw", t_final=1.0, backend="python").final_states[0]
    # the reference: the same v2 under a fresh name
    registry("fresh_v2", restitution_like(1.9))
    ref = pe.simulate(S, table=table, law="fresh_v2", t_final=1.0).final_state
    assert np.array_equal(v1, v1_batch) and np.array_equal(v2, v2_batch)
    assert not np.array_equal(v1, v2) and np.array_equal(v2, ref)


@pytest.mark.slow
def test_registering_a_name_again_reaches_the_compiled_builds(registry):
    pytest.importorskip("numba")
    table = pe.Circle(0.15)
    registry("again", restitution_like(1.5))
    a = pb.simulate(np.array([S]), table=table, law="again", t_final=0.6, backend="numba").final_states
    with pytest.warns(UserWarning):
        registry("again", restitution_like(1.9))
    b = pb.simulate(np.array([S]), table=table, law="again", t_final=0.6, backend="numba").final_states
    c = pb.simulate(np.array([S]), table=table, law="again", t_final=0.6, backend="python").final_states
    assert not np.array_equal(a, b) and np.array_equal(b, c)


def test_the_same_record_again_is_silent(registry, recwarn):
    f = restitution_like(1.5)
    registry("same", f, e=0.5)
    registry("same", f, e=0.5)
    assert not [w for w in recwarn if "now names" in str(w.message)]


POISON = """
    import numpy as np, gymnasium as gym
    import penny_env
    from penny_env.physics import laws
    # a law numba cannot type, put in the registry behind register_law's back (a user's law that compiles on
    # the CPU alone but fails inside a build would do the same): the built-in ids must not compile it
    laws._register(laws.LawRecord("mine", lambda W, w: (-W, -w)))
    env = gym.make("penny_env:PennyPark-Circle-v0")
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, np.float32))
    v = penny_env.PennyVectorEnv(4, "stadium", "impacts")
    v.reset(seed=0)
    v.step(np.zeros((4, 2)))
    print("built-in ids run")
    try:
        penny_env.PennyEnv("circle", "park", law="mine")
    except Exception as exc:
        print("own env fails:", type(exc).__name__, str(exc)[:400])
"""


def test_a_broken_law_never_enters_the_builds_of_other_envs():
    # the compiled builds hold the built-in laws and, besides them, only the law their Model runs
    # (backends/physics.py build_laws): one bad law used to break every env in the process, built-in ids too
    pytest.importorskip("numba")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"}
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(POISON)], cwd=ROOT, env=dict(env, PYTHONPATH=str(ROOT)),
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    # (its build tries the compiled law before it runs: a ValueError naming it and numba's error)
    own = r"own env fails: ValueError register_law\('mine'\): update as this build compiles it .* raised TypeError: too many"
    assert "built-in ids run" in out.stdout and re.search(own, out.stdout), out.stdout + out.stderr[-2000:]


def test_builds_hold_the_built_in_laws_and_their_own(registry):
    from penny_env.backends import physics as compiled
    registry("own", restitution_like(1.5))
    j = laws.law_index(laws.LAW_KINDS["own"].update)
    builtin = laws.builtin_law_indices()
    assert builtin == (0, 1) and compiled.build_laws(-1) == builtin == compiled.build_laws(0)
    assert compiled.build_laws(j) == builtin + (j,)
    assert compiled.variant_key(0) == compiled.variant_key(0, 1) != compiled.variant_key(0, j)
    from penny_env.backends.cache import cacheable
    assert cacheable(compiled.formulas(0)) and not cacheable(compiled.formulas(0, j))
    src = compiled.law_dispatch_source(compiled.build_laws(j))
    assert f"m.law == {j}" in src and "return math.nan" in src  # another law's Model gets NaN: the guard names it


def test_energy_tolerance_is_above_the_built_in_laws_round_off():
    # the largest relative change of the kinetic energy of the built-in laws over the trials, next to ENERGY_RTOL
    from penny_env.physics.kernels import SCALAR, law_update
    worst = 0.0
    for e, plastic in ((1.0, False), (0.5, False), (0.0, True)):
        for W, w, a, b, g2, _, Itot, J, m in trial_arguments(e):
            W1, w1 = law_update(W, w, a, b, g2, e, plastic, Itot, J, m, SCALAR)
            before, after = Itot * W * W + J * w * w, Itot * W1 * W1 + J * w1 * w1
            worst = max(worst, (after - before) / before if e == 1.0 else after / before - 1.0)
    assert worst < ENERGY_RTOL / 100


EDITABLE_LAW = '''
RESTITUTION = 1.0


def bouncy(W, w, a, b, grad2, e, Itot, J, m):
    k = (1.0 + RESTITUTION) * (a * W + b * w) / (a * a / Itot + b * b / J)
    return W - k * a / Itot, w - k * b / J
'''


def test_a_law_edited_after_registration_is_tried_again_before_it_runs(registry):
    # registered as energy-conserving, its module constant then edited before the first build: the build compiled
    # the edited, lossy law with no new check (the event loop trusts conserves_energy: it never stops a Zeno run)
    pytest.importorskip("numba")
    from penny_env.backends.physics import physics_build
    module = {"__name__": "users_laws"}
    exec(compile(EDITABLE_LAW, "users_laws.py", "exec"), module)  # noqa: S102 (the test's own source)
    registry("bouncy", module["bouncy"], conserves_energy=True)
    j = laws.law_index(module["bouncy"])
    physics_build("cpu", -1, fresh=True, law=j)  # (as registered: tried, accepted)
    pe.PennyEnv("plane", "reach", law="bouncy", backend="python")
    module["RESTITUTION"] = 0.5
    lossy = r"register_law\('bouncy'\): conserves_energy=True, but update as {} .* loses kinetic energy"
    with pytest.raises(ValueError, match=lossy.format("this build compiles it")):
        physics_build("cpu", -1, fresh=True, law=j)
    with pytest.raises(ValueError, match=lossy.format("the plain-Python step runs it")):
        pe.PennyEnv("plane", "reach", law="bouncy", backend="python")
