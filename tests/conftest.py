"""Shared test helpers, and the optional extras.

The suite passes with skips when an optional extra is missing: a test module that needs one for all
its tests starts with ``pytest.importorskip(name, reason=...)``, a single test calls it in its body.
hypothesis (the ``test`` extra) is used by property tests that sit next to plain ones in the same
modules: without it, ``@given`` tests are skipped with their reason (see _skip_without_hypothesis) and
the plain tests of those modules still run.
"""
import inspect
import os
import sys
import types

import numpy as np
import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")


def _skip_without_hypothesis():
    """Install a stand-in ``hypothesis`` module whose ``@given`` marks the test skipped.

    Only when hypothesis is not installed. Strategies and settings become inert placeholders (they are
    only built, never drawn from, since every test that would draw from them is skipped)."""
    reason = "hypothesis is not installed (the penny-env[test] extra): property test skipped"

    class _Inert:
        def __call__(self, *args, **kwargs):
            if len(args) == 1 and callable(args[0]) and not kwargs:  # used as a decorator
                if getattr(args[0], "__name__", "").startswith("test"):
                    return args[0]  # settings(...) on a test: keep the (skipped) test
                return lambda *a, **k: self  # st.composite on a strategy builder: calls give a placeholder
            return self

        def __getattr__(self, name):
            return self

    def given(*args, **kwargs):
        def decorate(test):
            def skipped(*_, **__):
                pytest.skip(reason)
            # keep the arguments hypothesis does not draw (fixtures, parametrize) in the signature
            sig = inspect.signature(test)
            skipped.__signature__ = sig.replace(parameters=[q for q in sig.parameters.values() if q.name not in kwargs])
            skipped.__name__, skipped.__qualname__ = test.__name__, test.__qualname__
            skipped.__module__, skipped.__doc__ = test.__module__, test.__doc__
            skipped.pytestmark = [pytest.mark.skip(reason=reason)]
            return skipped
        return decorate

    inert = _Inert()
    stub = types.ModuleType("hypothesis")
    stub.given, stub.settings, stub.assume, stub.example, stub.note = given, inert, inert, inert, inert
    stub.HealthCheck = inert
    stub.__getattr__ = lambda name: inert  # any other name a test imports (event, Phase, ...)
    strategies = types.ModuleType("hypothesis.strategies")
    strategies.__getattr__ = lambda name: inert
    stub.strategies = strategies
    sys.modules["hypothesis"], sys.modules["hypothesis.strategies"] = stub, strategies


try:
    from hypothesis import settings
except ImportError:
    _skip_without_hypothesis()
else:
    settings.register_profile("ci", deadline=None, max_examples=60, derandomize=True)
    settings.load_profile("ci")


def pytest_configure(config):
    """Under pytest-xdist (``pytest -n 2``, the README's command): a test module runs whole on one worker, and the
    modules that hold the slow tests are handed out first.

    * The controller schedules by module (``--dist loadscope``, in collection order): a module's module-scoped
      fixture (a quick study run, a venv with the README's install, a wheel) is built once, where tests split
      between workers made each worker build it again (``--dist loadgroup`` would group marked tests only, but its
      marks do not reach the node ids under pytest 9). The order is :func:`pytest_collection_modifyitems`'s.
    * A worker shares its compiled builds with the other (shared_builds.py).
    """
    if getattr(config.option, "numprocesses", None) and getattr(config.option, "dist", "no") == "load":
        config.option.dist = "loadscope"
        config.option.loadscopereorder = False
    if os.environ.get("PYTEST_XDIST_WORKER"):
        from tests import shared_builds
        shared_builds.install()


def pytest_collection_modifyitems(config, items):
    """In the test workers: the modules that hold a slow test or build a module-scoped fixture first, in their own
    order, then the others: both workers start on the long modules and the many short ones fill in at the end, so
    that neither waits alone for a long one begun last. (The same order in every worker: pytest-xdist checks that
    they collected alike.)"""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return

    def long(item):
        info = getattr(item, "_fixtureinfo", None)
        shared = any(d and d[-1].scope == "module" for d in (info.name2fixturedefs.values() if info else ()))
        return shared or item.get_closest_marker("slow") is not None

    first = {item.module.__name__ for item in items if hasattr(item, "module") and long(item)}
    items.sort(key=lambda item: getattr(getattr(item, "module", None), "__name__", "") not in first)


PAPER_STATE = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])


def random_inside_state(rng, params, table, speed=10.0, spin=2.0, margin=0.0):
    """A state with both ends strictly inside the table (rejection sampling)."""
    xmin, xmax, ymin, ymax = table.extent
    for _ in range(10_000):
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        phi = rng.uniform(-np.pi, np.pi)
        ok = True
        for s in (1, -1):
            px, py = x + s * params.R * np.cos(phi), y + s * params.R * np.sin(phi)
            if table.h(px, py) >= -margin * table.size:
                ok = False
        if ok:
            return np.array([x, y, rng.uniform(-3, 3), phi, rng.uniform(-speed, speed), rng.uniform(-spin, spin)])
    raise RuntimeError("no inside state found")


def random_pennies(seed, table, law, n, steer=True):
    """(rng, params, law, S (6, n), acc1, acc2) of a property test's case: the default PennyParams, the law made
    (laws.make_law), n states inside the table (:func:`random_inside_state`) and accelerations drawn after them,
    normal with deviation 3 (acc1 zero unless steer), from numpy's generator seeded with seed."""
    import penny_env as pe
    from penny_env.physics.laws import make_law
    rng = np.random.default_rng(seed)
    params = pe.PennyParams()
    S = np.stack([random_inside_state(rng, params, table) for _ in range(n)], axis=1)
    return rng, params, make_law(law), S, rng.normal(0, 3, n) * steer, rng.normal(0, 3, n)


@pytest.fixture
def paper_state():
    return PAPER_STATE.copy()



REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _reports_snapshot():
    """Modification times of docs/* and README.md, and their `git status` where git is there."""
    import shutil
    import subprocess
    paths = [os.path.join(REPO, "README.md")]
    docs = os.path.join(REPO, "docs")
    if os.path.isdir(docs):
        paths += [os.path.join(docs, f) for f in sorted(os.listdir(docs))]
    snap = {p: os.stat(p).st_mtime_ns for p in paths if os.path.exists(p)}
    if shutil.which("git") and os.path.exists(os.path.join(REPO, ".git")):
        run = subprocess.run(["git", "status", "--porcelain", "--", "docs", "README.md"], cwd=REPO,
                             capture_output=True, text=True)
        snap["git status"] = run.stdout
    return snap


@pytest.fixture
def reports_untouched(tmp_path, monkeypatch):
    """Runs the test from an empty temporary working directory, then checks that the committed reports
    (docs/, README.md) are as they were and that nothing landed in ./docs: report commands write only
    where --out says (a --quick run without --out: a temporary directory)."""
    before = _reports_snapshot()
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    assert _reports_snapshot() == before
    assert not os.path.exists(os.path.join(tmp_path, "docs")), "a report without --out landed in ./docs"


@pytest.fixture
def python_sigint_handler():
    """Python's own SIGINT handler (KeyboardInterrupt) in this process for the test, and so SIG_DFL in the processes
    it starts (a handler is reset at exec; Python then installs its own): a shell starts a background job (``cmd &``,
    nohup) with SIGINT ignored, its processes inherit that, and a test of what Ctrl-C does would test nothing."""
    import signal
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)
