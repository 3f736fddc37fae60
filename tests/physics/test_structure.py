"""The package's shape: one event loop (the numpy-mask loop is gone), no exported function that
shadows its own submodule, no two public functions named advance."""
import importlib
import importlib.util
import inspect

import pytest

import penny_env
import penny_env.batch
import penny_env.physics as physics


@pytest.mark.fast
def test_the_array_event_loop_is_gone():
    for name in ("events", "advance", "flow", "simulate", "tables.convex"):
        spec = importlib.util.find_spec(f"penny_env.physics.{name}")
        assert (spec is None) == (name != "tables.convex"), name


@pytest.mark.fast
def test_no_exported_function_shadows_its_submodule():
    for package in (penny_env, physics):
        for name in package.__all__:
            obj = getattr(package, name)
            if inspect.isfunction(obj) or inspect.isclass(obj):
                assert importlib.util.find_spec(f"{package.__name__}.{name}") is None, f"{package.__name__}.{name}"


@pytest.mark.fast
def test_one_public_advance():
    from penny_env.backends import batch as compiled
    from penny_env.backends import pennies
    from penny_env.physics import scalar
    names = [(m.__name__, n) for m in (physics, penny_env.batch, compiled, pennies, scalar)
             for n, f in vars(m).items() if n == "advance" and callable(f)]
    assert names == []
    assert not hasattr(compiled.CompiledBatch, "advance")
