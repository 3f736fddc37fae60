"""What a user's function reads from its module's globals: the fingerprint that tells when a module constant was
edited after the function was registered (a law, a table's formulas, a task's stages). numba freezes the globals a
function reads when it compiles it, and the plain-Python step reads them as they are: either way an edit runs
without the checks of registration unless the caller tries the function again when the fingerprint changes
(backends/checks.py, envs/task_trials.py)."""
from __future__ import annotations


def globals_read(f) -> tuple:
    """The module globals ``f``'s code reads (its nested code objects included), as sorted (name, repr(value))
    pairs; functions and other callables by identity."""
    g = getattr(f, "__globals__", {})
    names = set()
    todo = [getattr(f, "__code__", None)]
    while todo:
        code = todo.pop()
        if code is None:
            continue
        names.update(code.co_names)
        todo.extend(c for c in code.co_consts if hasattr(c, "co_names"))
    return tuple((n, id(g[n]) if callable(g[n]) else repr(g[n])) for n in sorted(names) if n in g)
