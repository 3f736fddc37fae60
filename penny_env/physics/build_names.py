"""Names that a build supplies: the few functions that plain-Python code calls but does not define.

The backends (penny_env/backends/builder.py) copy plain functions into one namespace per build and put a few
functions into it under fixed names: the task's stages that the step calls (``task_reward``, ...), a table's
formulas, the generated unpacker of the packed constants. A module whose functions call such names declares
them in one tuple, ``BUILD_SUPPLIED``, and binds each to a :class:`Supplied` stand-in, so that the module reads
whole (a linter sees every name defined, an import graph sees every import) and a call outside a build says
what happened instead of raising a NameError. The builder supplies only declared names, and checks that a
build supplies every declared name that its copies call (Builder.supply, Builder.check_supplied).

Plain Python: no numba, no Gymnasium.
"""
from __future__ import annotations

DECLARED: dict = {}  # name -> the modules that declare it (Builder.supply refuses any other name)


class Supplied:
    """The stand-in of a build-supplied name in the module that declares it. Calling it, or reading an
    attribute of it, outside a build raises a RuntimeError naming the name and its declaring module."""

    def __init__(self, name: str, module: str):
        self._name, self._module = name, module

    def _refuse(self):
        return RuntimeError(f"{self._name} is supplied by each build that copies {self._module}'s functions "
                            "(penny_env/backends/builder.py); it was called outside a build")

    def __call__(self, *args, **kwargs):
        raise self._refuse()

    def __getattr__(self, attr):
        if attr.startswith("_"):  # (copy, pickle and inspect probe such names: a plain AttributeError)
            raise AttributeError(attr)
        raise self._refuse()

    def __repr__(self):
        return f"<{self._name}: supplied by a build ({self._module})>"


def build_supplied(module: str, names: tuple) -> tuple:
    """The stand-ins of ``names`` (a module's BUILD_SUPPLIED), declared for ``module`` (its __name__), in order."""
    if len(set(names)) != len(names) or not all(isinstance(n, str) and n.isidentifier() for n in names):
        raise ValueError(f"{module}: BUILD_SUPPLIED must be distinct identifiers, got {names!r}")
    for name in names:
        DECLARED.setdefault(name, set()).add(module)
    return tuple(Supplied(name, module) for name in names)


def is_supplied(value) -> bool:
    """value is a stand-in (a name that a build has not replaced)."""
    return isinstance(value, Supplied)
