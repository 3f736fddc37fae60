"""One builder for the three targets of the package's plain-Python functions.

The physics (kernels.py, flows.py, scalar.py, the tables' formulas, the laws) and the environment's step
(envs/functional.py, envs/tasks.py) are written once, as plain Python on floats and tuples. A
:class:`Builder` compiles copies of those very functions for one target:

* ``"python"``: the functions as they are (no copy): the readable reference, for debugging and for the
  tests that compare the compiled targets with it;
* ``"cpu"``: numba copies whose globals are one shared namespace (the math namespace ``SCALAR`` becomes
  physics/numba_math.py), cached on disk where allowed (compiled.py's cache rules), and the loops over
  pennies compiled with ``parallel=True`` (numba ``prange``) plus a serial copy (physics/parallel.py);
* ``"cuda"``: numba-cuda device functions of the same copies (``SCALAR`` becomes physics/cuda_math.py),
  and each loop over pennies becomes a kernel with one thread per penny.

A loop over pennies is a plain function whose body is one call of a per-penny function with the index
first, ``for i in prange(N): body(i, a, b, ...)`` (compiled.advance_batch, functional.step_envs). The
CPU and Python targets run that function (``prange`` is ``range`` in plain Python); for CUDA,
:meth:`Builder.kernel` generates the kernel ``i = cuda.grid(1); if i < N: body(i, a, b, ...)`` from the
body's signature. So the per-penny work is the same function on all three targets, and only the
two-line glue differs. On the CPU the body's text is placed in the loop (:func:`hoisted_loop_source`),
with its extractions of arrays from the record arguments (``S = st[0]``) moved before the loop: numba
counts references to every array a statement extracts, with two atomic operations per array per
penny, which at 18 arrays cost a quarter of the open plane's whole step; and the calls of the step and
the event loop's driver are pasted in at the source level (:func:`inline_source`).

The copies of one build share one namespace: a function calls the copies of its callees, never the
plain Python ones. Every copy's name carries the table variant and a hash of all the sources it
inlines (compiled.source_digest), so numba's disk cache can never serve stale machine code.
"""
from __future__ import annotations

import builtins
import functools
import inspect
import types

import numpy as np

TARGETS = ("python", "cpu", "cuda")
CUDA_THREADS = 128  # threads per block of the kernels (one penny per thread)


def check_target(target) -> str:
    if not isinstance(target, str):
        raise TypeError(f"target must be a str, one of {TARGETS}, got {type(target).__name__}")
    if target not in TARGETS:
        raise ValueError(f"target must be one of {TARGETS}, got {target!r}")
    return target


@functools.lru_cache(maxsize=None)
def cuda_available() -> bool:
    """numba-cuda is installed and a CUDA device (or numba's CUDA simulator) is usable (checked once). Without
    the simulator, a machine whose CUDA driver library does not load has no GPU: answered without importing
    numba.cuda (about 1.5 s)."""
    import importlib.util
    import os
    if importlib.util.find_spec("numba_cuda") is None:
        return False
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        import ctypes
        try:
            ctypes.CDLL("libcuda.so.1" if os.name != "nt" else "nvcuda.dll")
        except OSError:
            return False
    try:
        from numba import cuda
    except ImportError:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 (a broken driver means no GPU for us)
        return False


class Builder:
    """Copies of plain-Python functions compiled for one target, sharing one namespace.

    ``Builder(target, variant, cache)``: variant names the copies (compiled.variant_name + a sources
    digest); cache: CPU copies may go to numba's disk cache. :meth:`add` puts a module's names (or any
    mapping) into the namespace, :meth:`copy` compiles a function's copy for the target (and stores it
    under the function's name), :meth:`loop` the loop over pennies, :meth:`kernel` its CUDA kernel."""

    def __init__(self, target: str, variant: str, cache: bool = False):
        self.target = check_target(target)
        self.variant = variant
        self.cache = bool(cache) and target == "cpu"
        self.namespace: dict = {"__builtins__": builtins}
        if target == "cpu":
            import numba

            from . import numba_math
            self.math = numba_math
            self._jit = numba.njit(cache=self.cache)
            self._inline = numba.njit(cache=self.cache, inline="always")
            self._parallel = numba.njit(cache=self.cache, parallel=True)
            self.namespace["prange"] = numba.prange
        elif target == "cuda":
            from numba import cuda

            from . import cuda_math
            self.math = cuda_math.namespace()
            self._jit = self._inline = cuda.jit(device=True)
            self.namespace["prange"] = range
            self.namespace["cuda"] = cuda
        else:
            self.math = None

    # -- the namespace ---------------------------------------------------------------------------
    def add(self, source) -> None:
        """Every public and private name of a module (or a mapping), dunders excepted; the math
        namespaces SCALAR / ARRAY / XP are the target's."""
        items = vars(source).items() if isinstance(source, types.ModuleType) else dict(source).items()
        self.namespace.update({k: v for k, v in items if not k.startswith("__")})
        for name in ("SCALAR", "ARRAY", "XP"):
            if name in self.namespace and self.math is not None:
                self.namespace[name] = self.math

    def copy(self, f, *, inline=False, jit=None, suffix=""):
        """The target's copy of plain function f with this build's namespace as its globals, stored in
        the namespace under f's name (python: f itself). inline: numba-inlined into its callers (CPU;
        device functions are inlined by the CUDA compiler anyway). jit: another numba decorator."""
        if self.target == "python":
            return f
        compiler = jit or (self._inline if inline else self._jit)
        from .compiled import jit_copy
        out = jit_copy(f, self.namespace, compiler, self.variant + suffix, math=self.math)
        self.namespace[f.__name__] = out
        return out

    def copies(self, functions, **kw) -> None:
        for f in functions:
            self.copy(f, **kw)

    def loop(self, f, entry=None, count=None, inline=()):
        """The loop over pennies f, compiled for the target: CPU, parallel (``prange``) with a serial copy
        for small batches and forked children, under parallel.locked; CUDA, :meth:`kernel` of f's body;
        python, f itself. entry: a plain function that unpacks its arguments and calls f (the loop is then
        called through the entry's copy, bound to the parallel or the serial loop); count(args): the
        pennies of a call (default: the first argument's last axis); inline: plain functions whose calls
        in the body the CPU loop has pasted in (:func:`inline_source`)."""
        if self.target == "cuda":
            return self.kernel(f)
        if self.target == "python":
            self.namespace[f.__name__] = f
            return entry or f
        from . import parallel
        from .compiled import jit_copy
        f = hoisted_loop(f, self.namespace, tuple(inline)) or f
        fast = self.copy(f, jit=self._parallel)
        if entry is not None:
            fast = self.copy(entry)

        def serial():
            ns = dict(self.namespace)
            loop = jit_copy(f, ns, self._jit, f"{self.variant}_serial", math=self.math)
            if entry is None:
                return loop
            ns[f.__name__] = loop
            return jit_copy(entry, ns, self._jit, f"{self.variant}_serial", math=self.math)
        return parallel.locked(fast, serial, count)

    def kernel(self, loop):
        """The CUDA kernel of a loop over pennies: ``loop`` is ``for i in prange(COUNT): BODY(i, args)``
        (its source is read for COUNT and BODY); the kernel runs BODY(i, args) in thread i < COUNT. Returns
        a launcher called like the loop (device arrays, or objects with __cuda_array_interface__)."""
        from numba import cuda
        body, count = loop_parts(loop)
        params = list(inspect.signature(loop).parameters)
        args = ", ".join(params)
        source = (f"def {loop.__name__}_kernel({args}):\n    i = cuda.grid(1)\n    if i < {count}:\n"
                  f"        {body}(i, {args})\n")
        scope = dict(self.namespace)
        exec(compile(source, f"<penny_env kernel {loop.__name__}>", "exec"), scope)
        kern = cuda.jit(scope[f"{loop.__name__}_kernel"])
        count_of = eval(f"lambda {args}: {count}")  # noqa: S307 (our own loop's count expression)

        def launch(*a):
            n = int(count_of(*a))
            if n > 0:
                threads = min(CUDA_THREADS, 32 * ((n + 31) // 32))  # (a small batch: one or a few warps)
                kern[(n + threads - 1) // threads, threads](*a)
        launch.__name__ = loop.__name__
        launch.kernel = kern
        launch.source = source
        return launch


def hoisted_loop(loop, namespace, inline=()):
    """The CPU version of a loop over pennies (``for i in prange(N): body(i, args)``, body found in
    ``namespace``): the body's statements in the loop, its extractions moved before it
    (:func:`hoisted_source`), the calls of the functions ``inline`` pasted in; None where the body does
    not allow it (the loop then calls the body)."""
    body = namespace.get(loop_parts(loop)[0])
    body = getattr(body, "py_func", body)
    if not isinstance(body, types.FunctionType):
        return None
    source = hoisted_source(loop, body, inline)
    if source is None:
        return None
    scope = {}
    # compiled under the body's file name: numba's disk cache locates the copies by it
    exec(compile(source, inspect.getfile(body), "exec"), scope)  # noqa: S102 (generated from our own loop)
    out = scope[loop.__name__]
    out.__module__ = loop.__module__
    out.__qualname__ = loop.__qualname__
    out.source = source
    return out


@functools.lru_cache(maxsize=None)
def hoisted_source(loop, body, inline=()) -> str | None:
    """Source of ``loop`` (``for i in prange(COUNT): body(i, <the loop's arguments>)``) with the body's
    statements in place of the call, and the body's top-level statements ``NAME = ARG[INTEGER]`` (an
    array taken from a record argument, NAME assigned nowhere else) before the loop; the calls of the
    functions ``inline`` pasted in (:func:`inline_source`). None where the body cannot be placed in a loop
    as it is: its parameters are not (index, <the loop's>), it returns, or it assigns a name the loop
    takes."""
    import ast
    import textwrap

    name, count = loop_parts(loop)
    fn = ast.parse(textwrap.dedent(inspect.getsource(loop))).body[0]
    bfn = ast.parse(textwrap.dedent(inspect.getsource(body))).body[0]
    params = [a.arg for a in fn.args.args]
    bparams = [a.arg for a in bfn.args.args]
    if bparams[1:] != params or bfn.args.vararg or bfn.args.kwarg or bfn.args.kwonlyargs:
        return None
    nested = (ast.Return, ast.Yield, ast.YieldFrom, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal)
    if any(isinstance(n, nested) for n in ast.walk(bfn) if n is not bfn):
        return None
    stores = [n.id for n in ast.walk(bfn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)]
    if set(stores) & set(bparams):
        return None
    stmts = [s for s in bfn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]

    def extraction(s):
        return (isinstance(s, ast.Assign) and len(s.targets) == 1 and isinstance(s.targets[0], ast.Name)
                and stores.count(s.targets[0].id) == 1 and isinstance(s.value, ast.Subscript)
                and isinstance(s.value.value, ast.Name) and s.value.value.id in params
                and isinstance(s.value.slice, ast.Constant) and type(s.value.slice.value) is int)
    hoisted = [s for s in stmts if extraction(s)]
    rest = [s for s in stmts if not extraction(s)]
    if not rest:
        return None
    if inline:
        rest = inline_source(rest, inline, taken=set(stores) | set(params))
        if rest is None:
            return None
    lines = [f"def {loop.__name__}({', '.join(params)}):"]
    lines += ["    " + ast.unparse(s) for s in hoisted]
    lines.append(f"    for {bparams[0]} in prange({count}):")
    lines += [textwrap.indent(ast.unparse(s), "        ") for s in rest]
    return "\n".join(lines) + "\n"


def inline_source(stmts, functions, taken):
    """Source-level inlining (CPU loops): every statement ``TARGETS = f(ARGS)`` in ``stmts`` (at any depth)
    whose f is one of ``functions`` becomes f's statements, its parameters replaced by the arguments that
    are plain names (the others go first into fresh locals), its locals renamed apart, and its one final
    ``return X`` becoming ``TARGETS = X``; the pasted statements are inlined in turn. Why: numba inlines
    a function (``inline="always"``) by assigning its arguments to new variables, and a new variable
    holding an array costs two atomic reference-count operations per array and call where the function
    also calls one that may raise (numba issue 2350: its pruning pass cannot remove them across the
    error path); pasted with the caller's own names, the arrays are never copied. Returns the new list, or
    None where a function cannot be pasted (not one final return, keyword arguments, a global that the
    caller's names would shadow): the loop then stays as it is."""
    import ast
    import textwrap

    by_name = {f.__name__: f for f in functions}
    count = [0]

    def paste(call, targets):
        f = by_name[call.func.id]
        fn = ast.parse(textwrap.dedent(inspect.getsource(f))).body[0]
        params = [a.arg for a in fn.args.args]
        if (call.keywords or any(isinstance(a, ast.Starred) for a in call.args) or len(call.args) != len(params)
                or fn.args.vararg or fn.args.kwarg or fn.args.kwonlyargs):
            return None
        body = [s for s in fn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
        nested = (ast.Yield, ast.YieldFrom, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal)
        returns = [n for n in ast.walk(fn) if isinstance(n, ast.Return)]
        if (not body or not isinstance(body[-1], ast.Return) or body[-1].value is None or len(returns) != 1
                or any(isinstance(n, nested) for n in ast.walk(fn) if n is not fn)):
            return None
        count[0] += 1
        tag = f"_{f.__name__}{count[0]}_"
        stored = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
        loaded = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}
        if (loaded - stored - set(params)) & taken:  # a global of f that a local of the caller would shadow
            return None
        rename, first = {}, []
        for name, arg in zip(params, call.args):
            if isinstance(arg, ast.Name) and name not in stored:
                rename[name] = arg.id
            else:
                rename[name] = tag + name
                first.append(ast.Assign(targets=[ast.Name(tag + name, ast.Store())], value=arg, lineno=0))
        rename.update({name: tag + name for name in stored - set(params)})
        taken.update(v for v in rename.values())

        class Rename(ast.NodeTransformer):
            def visit_Name(self, node):
                return ast.copy_location(ast.Name(rename.get(node.id, node.id), node.ctx), node)
        body = [Rename().visit(s) for s in body]
        last = ast.Assign(targets=targets, value=body[-1].value, lineno=0)
        return first + body[:-1] + [last]

    def walk(block):
        out = []
        for s in block:
            value = s.value if isinstance(s, (ast.Assign, ast.Expr)) else None
            if (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id in by_name
                    and taken.isdisjoint({value.func.id})):
                targets = s.targets if isinstance(s, ast.Assign) else [ast.Name("_", ast.Store())]
                pasted = paste(value, targets)
                if pasted is None:
                    return None
                pasted = walk(pasted)
                if pasted is None:
                    return None
                out += pasted
                continue
            for field in ("body", "orelse", "finalbody"):
                inner = getattr(s, field, None)
                if isinstance(inner, list) and inner and isinstance(inner[0], ast.stmt):
                    new = walk(inner)
                    if new is None:
                        return None
                    setattr(s, field, new)
            out.append(s)
        return out

    return walk([ast.parse(ast.unparse(s)).body[0] for s in stmts])  # (copies: the cached trees stay intact)


@functools.lru_cache(maxsize=None)
def loop_parts(loop) -> tuple[str, str]:
    """(body name, count expression) of a loop written ``for i in prange(COUNT):`` followed by one call
    ``BODY(i, <the loop's own arguments in order>)``; ValueError for any other shape (a kernel must do
    exactly what the CPU loop does)."""
    import ast
    import textwrap

    tree = ast.parse(textwrap.dedent(inspect.getsource(loop)))
    fn = tree.body[0]
    stmts = [s for s in fn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
    params = [a.arg for a in fn.args.args]
    ok = (len(stmts) == 1 and isinstance(stmts[0], ast.For) and isinstance(stmts[0].iter, ast.Call)
          and getattr(stmts[0].iter.func, "id", "") == "prange" and len(stmts[0].iter.args) == 1
          and len(stmts[0].body) == 1 and isinstance(stmts[0].body[0], ast.Expr)
          and isinstance(stmts[0].body[0].value, ast.Call))
    if ok:
        call = stmts[0].body[0].value
        names = [getattr(a, "id", None) for a in call.args]
        ok = names == [stmts[0].target.id] + params and isinstance(call.func, ast.Name)
    if not ok:
        raise ValueError(f"{loop.__name__}: a loop over pennies must be 'for i in prange(COUNT): BODY(i, <its arguments>)'")
    return call.func.id, ast.unparse(stmts[0].iter.args[0])
