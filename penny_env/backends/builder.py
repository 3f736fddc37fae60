"""One builder for the three targets of the package's plain-Python functions.

The physics (physics/kernels.py, flows.py, scalar.py, the tables' formulas, the laws), the env step's stages
(step/functional.py) and the tasks (step/tasks/) are written once, as plain Python on floats and tuples. A
:class:`Builder` makes copies of those very functions for one target, whose globals are one shared namespace
(a function calls its callees' copies):

* ``"python"``: plain copies (no compiler): the readable reference, for debugging and for the tests that
  compare the compiled targets with it;
* ``"cpu"``: numba copies (the math namespace ``SCALAR`` becomes backends/numba_math.py), cached on disk
  where allowed (backends/cache.py), the loops over pennies compiled with ``parallel=True`` (numba
  ``prange``) plus a serial copy (backends/threads.py);
* ``"cuda"``: numba-cuda device functions (``SCALAR`` becomes backends/cuda_math.py), and each loop over
  pennies a kernel with one thread per penny.

A loop over pennies is a plain function whose body is one call of a per-penny function with the index
first, ``for i in prange(N): body(i, a, b, ...)`` (backends/physics.advance_batch, functional.step_envs). For
CUDA, :meth:`Builder.kernel` generates the kernel ``i = cuda.grid(1); if i < N: body(i, a, b, ...)``. On the
CPU the body's text is placed in the loop (:func:`hoisted_source`), with its extractions of arrays from the
record arguments (``S = st[0]``) moved before the loop (numba counts references to every array a statement
extracts, two atomic operations per array per penny), and the calls of the step and the event loop's driver
are pasted in at the source level (:func:`inline_source`). A loop that does not fit that pattern raises
:class:`BuildError` naming the loop and the reason: a silent fallback would run the slow path unnoticed.
Generated source is written to real files (backends/generated.py), so tracebacks point at real lines.

Every copy's name carries the table variant and a hash of all the sources it inlines (backends/cache.py),
so numba's disk cache can never serve stale machine code.
"""
from __future__ import annotations

import builtins
import functools
import inspect
import types

from ..physics.build_names import DECLARED, is_supplied
from . import generated

TARGETS = ("python", "cpu", "cuda")
CUDA_THREADS = 128  # threads per block of the kernels (one penny per thread)


class BuildError(RuntimeError):
    """A loop or function that the builder cannot compile the way it must (the message says which and why)."""


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


def jit_copy(f, namespace, jit=None, variant="", math=None):
    """``jit`` (None: no compiler, the plain copy) of a copy of function f whose globals are ``namespace``;
    default arguments that are modules (``xp``) become ``math``. ``variant`` goes into the copy's qualified
    name: numba's on-disk cache files are named after it, and copies compiled against different tables
    must not share them."""
    defaults = tuple(math if isinstance(d, types.ModuleType) and math is not None else d for d in (f.__defaults__ or ()))
    copy = types.FunctionType(f.__code__, namespace, f.__name__, defaults, f.__closure__)
    copy.__module__ = f.__module__
    copy.__qualname__ = f"{f.__qualname__}__{variant}" if variant else f.__qualname__
    copy.__doc__ = f.__doc__
    return copy if jit is None else jit(copy)


class Builder:
    """Copies of plain-Python functions for one target, sharing one namespace.

    ``Builder(target, variant, cache)``: variant names the copies (a table variant and a sources digest,
    backends/cache.py); cache: CPU copies may go to numba's disk cache. :meth:`add` puts a module's names (or
    any mapping) into the namespace, :meth:`copy` makes a function's copy for the target (stored under the
    function's name), :meth:`loop` the loop over pennies, :meth:`kernel` its CUDA kernel."""

    def __init__(self, target: str, variant: str, cache: bool = False):
        self.target = check_target(target)
        self.variant = variant
        self.cache = bool(cache) and target == "cpu"
        self.namespace: dict = {"__builtins__": builtins, "prange": range}
        self.origin: dict = {}  # name -> the plain function whose copy the namespace holds under that name
        self._modules: dict = {}  # id(globals dict) -> (that dict, the namespace of its functions' copies)
        self._copies: dict = {}   # function -> its copy (copy_foreign), keyed on the function object itself
        self.sources: list = []   # every plain function copied into the namespace (check_supplied reads their code)
        self.supplied: set = set()  # the build-supplied names put in (supply; physics/build_names.py)
        self._jit = self._inline = None  # the python target copies without compiling
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
            self.cuda = cuda
        else:
            from ..physics.kernels import SCALAR
            self.math = SCALAR

    # -- the namespace ---------------------------------------------------------------------------
    def add(self, source) -> None:
        """Every public and private name of a module (or a mapping), dunders excepted; the math
        namespaces SCALAR / ARRAY / XP are the target's."""
        items = vars(source).items() if isinstance(source, types.ModuleType) else dict(source).items()
        self.namespace.update({k: v for k, v in items if not k.startswith("__") and k != "prange"})
        for name in ("SCALAR", "ARRAY", "XP"):
            if name in self.namespace:
                self.namespace[name] = self.math

    def copy(self, f, *, inline=False, jit=None, suffix="", name=None, replaces=None):
        """The target's copy of plain function f with this build's namespace as its globals, stored in the
        namespace under ``name`` (default f's name; a build-supplied name is put in as :meth:`supply` does).
        inline: numba-inlined into its callers (CPU; device functions are inlined by the CUDA compiler anyway).
        jit: another numba decorator. replaces: the plain function this copy stands for (a table's formula in
        place of the dispatch over tables)."""
        compiler = jit or (self._inline if inline else self._jit)
        out = jit_copy(f, self.namespace, compiler, self.variant + suffix, math=self.math)
        self.sources.append(f)
        if (name or f.__name__) in DECLARED:
            self.supply(name or f.__name__, out)
        self.namespace[name or f.__name__] = out
        self.origin[name or f.__name__] = replaces or f
        return out

    def supply(self, name: str, value) -> None:
        """``value`` into the namespace under a build-supplied name: one that a module declares in its
        BUILD_SUPPLIED (physics/build_names.py); BuildError for any other name."""
        if name not in DECLARED:
            raise BuildError(f"{name!r} is not a build-supplied name: no module declares it in its BUILD_SUPPLIED "
                             f"(declared: {sorted(DECLARED)})")
        self.namespace[name] = value
        self.supplied.add(name)

    def extend(self, other: "Builder") -> None:
        """Everything build ``other`` holds (its namespace, copies and supplied names), as the start of this one
        (the env step's build starts from the physics')."""
        self.namespace.update({k: v for k, v in other.namespace.items() if k != "__builtins__"})
        self.origin.update(other.origin)
        self.sources += other.sources
        self.supplied |= other.supplied

    def check_supplied(self) -> None:
        """BuildError unless this build supplies exactly the build-supplied names its copies call: every name
        that a copied function calls and its module binds to a stand-in (physics/build_names.py) is supplied,
        and every supplied name is called by some copy. A build that lacked one would compile a call of the
        stand-in; one that supplied a name nothing calls is declared wrong."""
        called = set()
        for f in self.sources:
            g = f.__globals__
            called.update(n for n in code_names(f.__code__) if is_supplied(g.get(n)))
        missing, unused = called - self.supplied, self.supplied - called
        if missing or unused:
            raise BuildError(f"build {self.variant!r} ({self.target}): "
                             + "; ".join(([f"its copies call {sorted(missing)}, which it does not supply"] if missing
                                          else []) + ([f"it supplies {sorted(unused)}, which no copy calls"] if unused
                                                      else [])))

    def copy_foreign(self, f, name):
        """A copy of f itself, a function of another module (a task's stage, maybe a user's: a closure, a lambda,
        one of two functions of one name), stored in the namespace under ``name``. Its globals are those f
        itself sees (``f.__globals__``, never a lookup by name), with three changes: penny_env's functions that
        this build copied (the physics, the draws) are the build's copies; the other plain functions defined
        there are copied alike (so its helpers compile with it); the math namespaces are the target's. A
        function it reaches that was defined in another module of the same top-level package, or of penny_env
        (a built-in task's helper), is copied with that function's own globals."""
        out = self._foreign_copy(f)
        self.supply(name, out)
        return out

    def _foreign_copy(self, f):
        """The copy of function f (once per build and function object) with :meth:`_globals_namespace`."""
        if f not in self._copies:
            self.sources.append(f)
            self._copies[f] = jit_copy(f, self._globals_namespace(f.__globals__), self._jit, self.variant,
                                       math=self.math)
        return self._copies[f]

    def _globals_namespace(self, g: dict) -> dict:
        """The namespace of the copies of the functions whose globals are the dict ``g`` (once per build)."""
        key = id(g)
        if key in self._modules:
            return self._modules[key][1]
        ns = {"__builtins__": builtins}
        self._modules[key] = (g, ns)  # (g held: its id stays its own while the build lives)
        package = str(g.get("__name__") or "").split(".")[0]
        for k, v in list(g.items()):
            if k.startswith("__"):
                continue
            if k in ("SCALAR", "ARRAY", "XP"):
                ns[k] = self.math
            elif isinstance(v, types.FunctionType) and self.origin.get(v.__name__) is v:
                ns[k] = self.namespace[v.__name__]
            elif isinstance(v, types.FunctionType) and (v.__globals__ is g or str(v.__module__).split(".")[0]
                                                        in (package, "penny_env")):
                ns[k] = self._foreign_copy(v)
            else:
                ns[k] = v
        return ns

    def copies(self, functions, **kw) -> None:
        for f in functions:
            self.copy(f, **kw)

    def loop(self, f, entry=None, count=None, inline=()):
        """The loop over pennies f for the target: CPU, parallel (``prange``) with a serial copy for small
        batches and forked children, under threads.locked, its body in place (:func:`hoisted_loop`);
        CUDA, :meth:`kernel` of f's body; python, the plain copy. entry: a plain function that unpacks its
        arguments and calls f (the loop is then called through the entry's copy, bound to the parallel or
        the serial loop); count(args): the pennies of a call (default: the first argument's last axis);
        inline: plain functions whose calls in the body the CPU loop pastes in (:func:`inline_source`)."""
        if self.target == "cuda":
            return self.kernel(f)
        if self.target == "python":
            self.copy(f)
            return self.copy(entry) if entry is not None else self.namespace[f.__name__]
        from . import threads
        hoisted = hoisted_loop(f, self.namespace, tuple(inline))
        fast = self.copy(hoisted, jit=self._parallel, name=f.__name__)
        if entry is not None:
            fast = self.copy(entry)

        def serial():
            ns = dict(self.namespace)
            loop = jit_copy(hoisted, ns, self._jit, f"{self.variant}_serial", math=self.math)
            if entry is None:
                return loop
            ns[f.__name__] = loop
            return jit_copy(entry, ns, self._jit, f"{self.variant}_serial", math=self.math)
        return threads.locked(fast, serial, count)

    def kernel(self, loop, max_registers=None):
        """The CUDA kernel of a loop over pennies: ``loop`` is ``for i in prange(COUNT): BODY(i, args)``
        (its source is read for COUNT and BODY); the kernel runs BODY(i, args) in thread i < COUNT, its
        source generated into a real file (backends/generated.py). Returns a :class:`CudaLoop`."""
        from numba import cuda
        body, count = loop_parts(loop)
        params = list(inspect.signature(loop).parameters)
        args = ", ".join(params)
        name = f"{loop.__name__}_kernel"
        source = ('"""Generated by penny_env.backends.builder.Builder.kernel from '
                  f'{loop.__module__}.{loop.__qualname__}."""\n\n\n'
                  f"def {name}({args}):\n    i = cuda.grid(1)\n    if i < {count}:\n        {body}(i, {args})\n\n\n"
                  f"def {loop.__name__}_count({args}):\n    return {count}\n")
        scope = generated.define(name, source, dict(self.namespace, cuda=cuda), loop.__module__)
        import numba
        # (numba's CUDA simulator runs the kernels as Python: it has no registers to cap)
        options = {} if max_registers is None or numba.config.ENABLE_CUDASIM else {"max_registers": int(max_registers)}
        return CudaLoop(cuda.jit(**options)(scope[name]), scope[f"{loop.__name__}_count"], loop.__name__, source)


class CudaLoop:
    """A loop over pennies compiled as a CUDA kernel (:meth:`Builder.kernel`), one thread per penny.

    Called like the loop, with device arrays (or objects with __cuda_array_interface__), on numba's default
    stream or ``stream=``. :meth:`prepare` binds fixed arguments once: the step of the vector env launches
    the same buffers every time, so its host work per step is one launch (:class:`PreparedLaunch`)."""

    def __init__(self, kernel, count_of, name, source):
        self.kernel = kernel
        self.count_of = count_of
        self.__name__ = name
        self.source = source

    @staticmethod
    def config(n):
        threads = min(CUDA_THREADS, 32 * ((n + 31) // 32))  # (a small batch: one or a few warps)
        return (n + threads - 1) // threads, threads

    def __call__(self, *args, stream=0):
        n = int(self.count_of(*args))
        if n > 0:
            blocks, threads = self.config(n)
            self.kernel[blocks, threads, stream](*args)

    def prepare(self, *args):
        """A :class:`PreparedLaunch` of this kernel on ``args`` (compiled now if it was not)."""
        return PreparedLaunch(self, args)


class PreparedLaunch:
    """One kernel launch with its arguments marshalled once: ``launch(stream)`` runs the kernel on the
    arguments given to :meth:`CudaLoop.prepare` (numba's dispatcher would type, look up and flatten every
    argument on every call: about 40 arrays, a large part of a small step's time). Where numba-cuda's
    internals are not as expected (another version, or its simulator), it launches through the dispatcher
    (``fast`` False), with the same results."""

    def __init__(self, loop, args):
        self.loop = loop
        self.args = args
        n = int(loop.count_of(*args))
        self.n = n
        self.blocks, self.threads = loop.config(max(n, 1))
        self.fast = False
        self.launched = False
        try:
            self._marshal()
            self.fast = True
        except Exception:  # noqa: BLE001 (private API of numba-cuda 0.30: any change means the slow path)
            self.fast = False

    def _marshal(self):
        from numba.cuda import dispatcher as nd
        disp = self.loop.kernel
        if not hasattr(nd, "launch") or not hasattr(nd, "LaunchConfig"):
            raise RuntimeError("numba-cuda without cuda.core launches")
        argtypes = tuple(disp.typeof_pyval(a) for a in self.args)
        kernel = disp.overloads.get(argtypes) or disp.compile(argtypes)
        kernelargs, retr = [], []
        for t, v in zip(kernel.argument_types, self.args):
            kernel._prepare_args(t, v, 0, retr, kernelargs)
        if retr:
            raise RuntimeError("an argument needs a copy back (a host array): not a fixed launch")
        key = "is_cooperative" if getattr(nd, "CUDA_CORE_GE_1_0", False) else "cooperative_launch"
        self._config = nd.LaunchConfig(grid=self.blocks, block=self.threads, shmem_size=0, **{key: False})
        self._cukernel = kernel._codelibrary.get_cufunc().kernel
        self._kernelargs = kernelargs
        self._launch = nd.launch
        from numba.cuda.cudadrv.driver import _to_core_stream
        self._to_core_stream = _to_core_stream
        self._core_streams = {}  # id(numba stream) -> (that stream, cuda.core's view of it): converted once
        self.registers = kernel.get_regs_per_thread() if hasattr(kernel, "get_regs_per_thread") else None

    def launch(self, stream=0):
        """The kernel on ``stream`` (numba's stream object, or 0 for the default stream)."""
        if self.n == 0:
            return
        if self.fast:
            try:
                held = self._core_streams.get(id(stream))
                if held is None:
                    held = self._core_streams[id(stream)] = (stream, self._to_core_stream(stream))
                self._launch(held[1], self._config, self._cukernel, *self._kernelargs)
                self.launched = True
                return
            except Exception:  # noqa: BLE001 (the first launch proves the private path; later errors are real)
                if self.launched:
                    raise
                self.fast = False
        if not self.fast:
            self.loop.kernel[self.blocks, self.threads, stream](*self.args)


def hoisted_loop(loop, namespace, inline=()):
    """The CPU version of a loop over pennies (``for i in prange(N): body(i, args)``, body found in
    ``namespace``): the body's statements in the loop, its extractions moved before it, the calls of the
    functions ``inline`` pasted in (:func:`hoisted_source`), defined from a generated file
    (backends/generated.py). BuildError where the body does not allow it."""
    name = loop_parts(loop)[0]
    body = namespace.get(name)
    body = getattr(body, "py_func", body)
    if not isinstance(body, types.FunctionType):
        raise BuildError(f"{loop.__name__}: its body {name!r} is not a plain function in the build's namespace")
    source = hoisted_source(loop, body, inline)
    header = f'"""Generated by penny_env.backends.builder.hoisted_source from {loop.__module__}.{loop.__qualname__}."""\n\n\n'
    scope = generated.define(f"{loop.__name__}_cpu", header + source, {}, loop.__module__)
    out = scope[loop.__name__]
    out.__module__ = loop.__module__
    out.__qualname__ = loop.__qualname__
    out.source = source
    return out


@functools.lru_cache(maxsize=None)
def hoisted_source(loop, body, inline=()) -> str:
    """Source of ``loop`` (``for i in prange(COUNT): body(i, <the loop's arguments>)``) with the body's
    statements in place of the call, and the body's top-level statements ``NAME = ARG[INTEGER]`` (an
    array taken from a record argument, NAME assigned nowhere else) before the loop; the calls of the
    functions ``inline`` pasted in (:func:`inline_source`). BuildError, naming the reason, where the body
    cannot be placed in a loop as it is: its parameters are not (index, <the loop's>), it returns, it
    nests a function, or it assigns a name the loop takes."""
    import ast
    import textwrap

    name, count = loop_parts(loop)
    fn = ast.parse(textwrap.dedent(inspect.getsource(loop))).body[0]
    bfn = ast.parse(textwrap.dedent(inspect.getsource(body))).body[0]
    params = [a.arg for a in fn.args.args]
    bparams = [a.arg for a in bfn.args.args]
    where = f"{loop.__name__}: the body {body.__name__}"
    if bparams[1:] != params or bfn.args.vararg or bfn.args.kwarg or bfn.args.kwonlyargs:
        raise BuildError(f"{where} must take (index, {', '.join(params)}), got ({', '.join(bparams)})")
    nested = (ast.Return, ast.Yield, ast.YieldFrom, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal)
    bad = [n for n in ast.walk(bfn) if n is not bfn and isinstance(n, nested)]
    if bad:
        raise BuildError(f"{where} has a {type(bad[0]).__name__.lower()} statement (line {bad[0].lineno} of its "
                         "definition): a loop body runs to its end")
    stores = [n.id for n in ast.walk(bfn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)]
    if set(stores) & set(bparams):
        raise BuildError(f"{where} assigns its parameter(s) {sorted(set(stores) & set(bparams))}")
    stmts = [s for s in bfn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
    if inline:
        stmts = inline_source(stmts, inline, taken=set(stores) | set(params), where=where)
    stores = [n.id for s in stmts for n in ast.walk(s) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)]

    def extraction(s):
        return (isinstance(s, ast.Assign) and len(s.targets) == 1 and isinstance(s.targets[0], ast.Name)
                and stores.count(s.targets[0].id) == 1 and isinstance(s.value, ast.Subscript)
                and isinstance(s.value.value, ast.Name) and s.value.value.id in params
                and isinstance(s.value.slice, ast.Constant) and type(s.value.slice.value) is int)

    hoisted = []

    def lift(block):
        """block without its extractions (at any depth: pasted functions take their arrays in branches), which
        go to ``hoisted`` (pure: taking an array out of an argument, under a name assigned nowhere else)."""
        kept = []
        for s in block:
            if extraction(s):
                hoisted.append(s)
                continue
            for field in ("body", "orelse", "finalbody"):
                inner = getattr(s, field, None)
                if isinstance(inner, list) and inner and isinstance(inner[0], ast.stmt):
                    setattr(s, field, lift(inner) or [ast.Pass()])
            kept.append(s)
        return kept
    rest = lift(stmts)
    if not rest:
        raise BuildError(f"{where} does nothing but take arrays from its arguments")
    lines = [f"def {loop.__name__}({', '.join(params)}):"]
    lines += ["    " + ast.unparse(s) for s in hoisted]
    lines.append(f"    for {bparams[0]} in prange({count}):")
    lines += [textwrap.indent(ast.unparse(s), "        ") for s in rest]
    return "\n".join(lines) + "\n"


def inline_source(stmts, functions, taken, where="inline_source"):
    """Source-level inlining (CPU loops): every statement ``TARGETS = f(ARGS)`` in ``stmts`` (at any depth)
    whose f is one of ``functions`` becomes f's statements, its parameters replaced by the arguments that
    are plain names (the others go first into fresh locals), its locals renamed apart, and its one final
    ``return X`` becoming ``TARGETS = X``; the pasted statements are inlined in turn. Why: numba inlines
    a function (``inline="always"``) by assigning its arguments to new variables, and a new variable
    holding an array costs two atomic reference-count operations per array and call where the function
    also calls one that may raise (numba issue 2350: its pruning pass cannot remove them across the
    error path); pasted with the caller's own names, the arrays are never copied. Returns the new list;
    BuildError naming the function and the reason where one cannot be pasted (not one final return,
    keyword arguments, a global that the caller's names would shadow), or where one of ``functions`` is
    never called (a pasting asked for that does not happen is a loop that changed shape)."""
    import ast
    import textwrap

    by_name = {f.__name__: f for f in functions}
    count = [0]
    pasted_names = set()

    def paste(call, targets):
        f = by_name[call.func.id]
        what = f"{where}: {f.__name__} cannot be pasted in"
        fn = ast.parse(textwrap.dedent(inspect.getsource(f))).body[0]
        params = [a.arg for a in fn.args.args]
        if call.keywords or any(isinstance(a, ast.Starred) for a in call.args):
            raise BuildError(f"{what}: it is called with keyword or starred arguments")
        if len(call.args) != len(params) or fn.args.vararg or fn.args.kwarg or fn.args.kwonlyargs:
            raise BuildError(f"{what}: it is not called with one positional argument per parameter")
        body = [s for s in fn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
        nested = (ast.Yield, ast.YieldFrom, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal)
        returns = [n for n in ast.walk(fn) if isinstance(n, ast.Return)]
        procedure = not returns and targets is None  # (no value: its statements, called as a statement)
        if not body or not (procedure or (isinstance(body[-1], ast.Return) and body[-1].value is not None
                                          and len(returns) == 1)):
            raise BuildError(f"{what}: it must end in its one return statement, with a value (or return nothing "
                             "and be called as a statement)")
        if any(isinstance(n, nested) for n in ast.walk(fn) if n is not fn):
            raise BuildError(f"{what}: it nests a function, a generator or a global statement")
        count[0] += 1
        pasted_names.add(f.__name__)
        tag = f"_{f.__name__}{count[0]}_"
        stored = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
        loaded = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}
        shadowed = (loaded - stored - set(params)) & taken
        if shadowed:
            raise BuildError(f"{what}: the caller's local(s) {sorted(shadowed)} would shadow its global(s)")
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
        if procedure:
            return first + body
        last = ast.Assign(targets=targets, value=body[-1].value, lineno=0)
        return first + body[:-1] + [last]

    def walk(block):
        out = []
        for s in block:
            value = s.value if isinstance(s, (ast.Assign, ast.Expr)) else None
            if (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id in by_name
                    and value.func.id not in taken):
                out += walk(paste(value, s.targets if isinstance(s, ast.Assign) else None))
                continue
            for field in ("body", "orelse", "finalbody"):
                inner = getattr(s, field, None)
                if isinstance(inner, list) and inner and isinstance(inner[0], ast.stmt):
                    setattr(s, field, walk(inner))
            out.append(s)
        return out

    out = walk([ast.parse(ast.unparse(s)).body[0] for s in stmts])  # (copies: the cached trees stay intact)
    missing = set(by_name) - pasted_names
    if missing:
        raise BuildError(f"{where}: no call of {sorted(missing)} to paste in (the loop's body changed shape)")
    return out


def code_names(code) -> set:
    """The global and attribute names a code object and the code nested in it (comprehensions) load."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= code_names(const)
    return names


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
