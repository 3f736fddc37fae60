"""The seam between the plain functions and their builds: the names a build supplies are declared
(physics/build_names.py) and every build supplies exactly those its copies call (builder.Builder.check_supplied);
the runners share one interface (backends/runner.Runner)."""
import inspect
from pathlib import Path

import pytest

from penny_env.backends.builder import Builder, BuildError
from penny_env.physics import build_names

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def declared_helper():
    """A module-like namespace whose function ``uses`` calls ``scaled``, a build-supplied name it declares."""
    scope = {"__name__": "tests.backends.fake_stage"}
    (scope["scaled"],) = build_names.build_supplied(scope["__name__"], ("scaled",))
    exec("def uses(x):\n    return scaled(x) + 1.0\n", scope)  # noqa: S102
    yield scope
    build_names.DECLARED["scaled"].discard(scope["__name__"])
    if not build_names.DECLARED["scaled"]:
        del build_names.DECLARED["scaled"]


@pytest.mark.fast
def test_a_build_supplies_exactly_the_declared_names_its_copies_call(declared_helper):
    b = Builder("python", "python")
    b.copy(declared_helper["uses"])
    with pytest.raises(BuildError, match=r"its copies call \['scaled'\], which it does not supply"):
        b.check_supplied()
    b.supply("scaled", lambda x: 2.0 * x)
    b.check_supplied()
    assert b.namespace["uses"](3.0) == 7.0

    lone = Builder("python", "python")
    lone.supply("scaled", lambda x: x)
    with pytest.raises(BuildError, match=r"it supplies \['scaled'\], which no copy calls"):
        lone.check_supplied()
    with pytest.raises(BuildError, match="'undeclared_name' is not a build-supplied name"):
        lone.supply("undeclared_name", lambda x: x)


def test_a_stand_in_called_outside_a_build_names_itself(declared_helper):
    with pytest.raises(RuntimeError, match="scaled is supplied by each build that copies tests.backends.fake_stage"):
        declared_helper["uses"](1.0)
    from penny_env.step import functional
    with pytest.raises(RuntimeError, match="task_reward is supplied by each build"):
        functional.task_reward(None, None, None, 0.0, 0, None)
    with pytest.raises(RuntimeError, match="cuda is supplied"):
        __import__("penny_env.backends.env", fromlist=["cuda"]).cuda.atomic  # noqa: B018
    with pytest.raises(ValueError, match="distinct identifiers"):
        build_names.build_supplied("x", ("a", "a"))


def test_the_env_build_of_every_task_supplies_its_declared_names():
    """The python target's build of each built-in task holds the task's stages and the unpacker under their
    declared names (the compiled builds run the same code), and no numba.cuda outside a CUDA build."""
    from penny_env.backends.env import env_entry_points
    from penny_env.envs.core import Core
    from penny_env.envs.scene import resolve
    from penny_env.step import functional
    for task in ("reach", "park", "impacts"):
        core = Core(*resolve("ellipse", task), backend="python")
        ns = env_entry_points("python", -1, core.task_record, type(core.k), fresh=True).step_envs.__globals__
        for name in functional.BUILD_SUPPLIED + ("unpack",):
            assert callable(ns[name]) and not build_names.is_supplied(ns[name]), (task, name)
        assert "cuda" not in ns


@pytest.mark.fast
def test_no_name_is_left_to_a_build_undeclared():
    """No module of the package silences the linter's undefined-name check (F821): a name the code calls is defined,
    imported or declared build-supplied."""
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in sorted((ROOT / "penny_env").rglob("*.py"))
            for i, line in enumerate(p.read_text().splitlines(), 1) if "noqa: F821" in line]
    assert hits == []


def test_the_runners_share_one_interface():
    """CpuRunner and DeviceStep have every method of the Runner Protocol, with its parameters, and one
    constructor shape (spec, n, K, options)."""
    from penny_env.backends.cuda_env import DeviceStep
    from penny_env.backends.runner import CpuRunner, Runner
    methods = [name for name, f in vars(Runner).items() if inspect.isfunction(f) and (not name.startswith("_")
                                                                                      or name == "__init__")]
    assert {"__init__", "step", "check_actions", "reset", "warm_up", "host", "state_to_host"} <= set(methods)
    for cls in (CpuRunner, DeviceStep):
        for name in methods:
            if not hasattr(cls, name):  # (a bound method set per instance: CpuRunner.mask, a copy's array)
                assert f"self.{name} = " in inspect.getsource(cls.__init__), (cls.__name__, name)
                continue
            want = list(inspect.signature(getattr(Runner, name)).parameters)
            assert list(inspect.signature(getattr(cls, name)).parameters) == want, (cls.__name__, name)
