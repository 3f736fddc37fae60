"""The one door of the environments (penny_env/envs/) into the backends.

The envs import this module and nothing else of penny_env/backends/ (an import contract: pyproject.toml). It
owns every compile concern of an env: which backend runs the step (numba or plain Python), which target runs a
vector env (the CPU or a CUDA GPU), the constants' packing, the compile notice and the warm-up (the machine
code loaded or compiled when the env is made, never inside its first step), and, on the CPU, whether the
vector step runs its serial or its parallel loop.

* :func:`env_backend`: "numba" or "python" for a Core's backend argument;
* :func:`make_single`: the single env's step (:class:`~penny_env.backends.runner.StepSpec`), warm;
* :func:`make_runner`: the vector env's Core and runner (:class:`~penny_env.backends.runner.Runner`), warm;
* :func:`entry_points` and :func:`draw_episodes`: a Core's compiled step and its reset's draws.

A "core" here is an envs.core.Core, read by its attributes only (as step/functional.env_params reads it):
params, table, law, settings, k, task_record, obs_dim, n_act, counts_arc, audit, backend.
"""
from __future__ import annotations

import numpy as np

from ..physics.scalar import impact_buffers, scalar_model
from ..step.functional import EnvState, env_params
from .memory import memory_left
from .runner import CpuRunner, Runner, RunnerOptions, StepSpec

_WARM: set = set()  # the single env's entry points (env.EnvEntryPoints) called once in this process
WARM_UP_SLOTS = 16  # impact slots of the single env's warm-up call (the env's own buffers have the same types)

__all__ = ["env_backend", "entry_points", "draw_episodes", "make_single", "make_runner", "memory_left", "Runner",
           "StepSpec"]


def env_backend(backend, table, law) -> str:
    """"numba" or "python" for a Core's ``backend`` ("auto", "numba" or "python"): "auto" takes numba where the
    table compiles (choice.choose_backend), else the plain-Python step with a warning naming it. numba is imported
    first (with Ctrl-C held: interrupts.load_numba); with the plain-Python step, a user's law is checked again as
    it is now, not only as it was registered (a compiled build checks its own copy: backends/physics.py)."""
    from .choice import choose_backend
    from .interrupts import load_numba
    if backend not in ("auto", "numba", "python"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'python', got {backend!r}")
    if backend != "python":
        load_numba()
        chosen = choose_backend(backend, table, "scene.table", python="python")
        if chosen == "python":
            import warnings
            warnings.warn("penny_env: the compiled step cannot run here (numba missing or a table that does not "
                          "compile); using the plain-Python step (backend='python'), much slower", stacklevel=4)
        backend = chosen
    if backend == "python":
        from .checks import recheck_law
        recheck_law(law.update)
    return backend


def entry_points(core, target=None, **options):
    """The env step's entry points (env.EnvEntryPoints) for ``target`` ("python", "cpu", "cuda"; None: the core's
    backend) and the core's table kind and task; options: env.env_entry_points' (max_registers)."""
    from .env import env_entry_points
    if target is None:
        target = "cpu" if core.backend == "numba" else "python"
    m = _model(core)
    fns = env_entry_points(target, m.kind, core.task_record, type(core.k), law=m.law, **options)
    from .checks import check_table_as_run
    from .physics import physics_build
    check_table_as_run(core.table, physics_build(target, m.kind, law=m.law))  # (the build the step extends)
    return fns


def draw_episodes(core, keys, episodes):
    """(S (6, N), target (2, N), arc (2, N)): the initial states, targets and marked arcs' directions of episodes
    ``episodes`` (N,) of the envs with seed keys ``keys`` (N,) uint64 (draws.seed_keys), drawn by the env step's
    own reset stage (functional.initial_state) on the core's backend."""
    from .packing import pack
    keys = np.ascontiguousarray(keys, dtype=np.uint64)
    n = keys.shape[0]
    st = EnvState(np.zeros((6, n)), np.zeros((4, n)), np.zeros((2, n)), np.zeros((2, n)), np.zeros(n, np.int64),
                  np.zeros(n), np.zeros(n, np.int64), np.zeros(n), keys,
                  np.ascontiguousarray(np.broadcast_to(episodes, (n,)), dtype=np.int64), np.zeros(n, bool))
    obs = np.empty((n, core.obs_dim), dtype=np.float32)
    entry_points(core).reset_rows(np.arange(n), tuple(st), pack(env_params(core), _model(core), core.k), obs)
    return st.S, st.target, st.arc


def make_single(core, max_steps=None) -> StepSpec:
    """The single env's step for ``core`` on its backend: the entry points and the constants packed (max_steps:
    functional.env_params', None the task's). Compiled, its first build in this process is announced and loaded
    (or compiled) now, with Ctrl-C held until that is done (interrupts.compiling)."""
    spec = _spec(core, env_params(core, max_steps), None)
    fns = spec.fns
    if core.backend == "numba":
        from .cache import announce_compile
        from .interrupts import compiling
        announce_compile("single env step", _table_name(core), spec.m.kind, fns.env_step)
        if fns not in _WARM:
            with compiling():
                obs = np.empty((1, core.obs_dim), dtype=np.float32)
                s, trig, target, arc, d = fns.initial_state(np.uint64(0), 0, spec.consts, obs)
                st = (s, trig, target, arc, 0, d, 0, 0.0)
                fns.observe_state(st, spec.consts, obs)
                fns.env_step(st, 0.0, 0.0, spec.consts, obs, tuple(impact_buffers(1, WARM_UP_SLOTS)))
                _WARM.add(fns)
    return spec


def make_runner(make_core, n: int, K: int, autoreset: int, backend="auto", device=None, outputs=None,
                cuda_options=None) -> tuple:
    """(core, runner) of a vector env of ``n`` envs reporting ``K`` impacts a step, autoreset code ``autoreset``
    (functional.NEXT_STEP, SAME_STEP, DISABLED). ``make_core(backend)`` makes the env's Core on a Core's backend.

    The target: CUDA for backend "cuda" (numba-cuda and a GPU or its simulator, else ValueError) and for "auto"
    with a device or torch outputs asked likewise, or where numba-cuda finds a real GPU; a table without compiled
    formulas falls back to the CPU where "auto" chose the GPU by itself (and raises where it was asked). On CUDA:
    cuda_env.DeviceStep with ``outputs`` (None: "torch" for backend "cuda", else "numpy") and cuda_options'
    "kernels" and "max_registers". On the CPU: CpuRunner, its loop announced and warmed up."""
    options = dict(cuda_options or {})
    on_gpu = _on_gpu(backend, device, outputs)
    core = make_core("python" if on_gpu else backend)  # (the GPU's core builds nothing for the CPU)
    if on_gpu:
        from .choice import compiles
        if not compiles(core.table):
            if backend == "cuda" or device is not None or outputs == "torch":
                raise ValueError(f"backend='cuda': scene.table {type(core.table).__name__} has no compiled formulas "
                                 "(registered tables with formulas and the open plane run on the GPU)")
            on_gpu = False
            core = make_core(backend)
    p = env_params(core, autoreset=autoreset)
    if on_gpu:
        from .cuda_env import DeviceStep
        from .env import FAST_MAX_REGISTERS
        spec = _spec(core, p, "cuda", max_registers=options.get("max_registers", FAST_MAX_REGISTERS))
        runner = DeviceStep(spec, n, K, RunnerOptions(device, outputs or ("torch" if backend == "cuda" else "numpy"),
                                                      options.get("kernels", "split")))
        return core, runner
    spec = _spec(core, p, None)
    runner = CpuRunner(spec, n, K)
    if core.backend == "numba":  # the machine code loaded (or compiled) now, not inside a step or a reset
        from .cache import announce_compile
        # the dispatcher this env's steps will run (announcing the parallel one for a small env said "compiling" in
        # every process: it is never built there, so it never has a cache)
        announce_compile("vector env step", _table_name(core), spec.m.kind, runner.dispatcher)
        runner.warm_up()  # (its loops' first calls hold Ctrl-C while they compile: threads.locked)
    return core, runner


def _on_gpu(backend, device, outputs) -> bool:
    """The vector env runs on CUDA (:func:`make_runner`'s rule)."""
    import importlib.util

    from .builder import cuda_available
    if backend == "cuda" or (backend == "auto" and (device is not None or outputs == "torch")):
        if importlib.util.find_spec("numba_cuda") is None:
            raise ValueError("backend='cuda' needs numba-cuda, the cuda extra: in a clone of penny_env, "
                             "pip install -e \".[cuda]\" (docs/gpu.md)")
        if not cuda_available():
            raise ValueError("backend='cuda': numba-cuda finds no CUDA GPU here (nor its simulator, NUMBA_ENABLE_CUDASIM=1)")
        return True
    if backend != "auto" or importlib.util.find_spec("numba_cuda") is None:
        return False
    from .interrupts import load_numba
    load_numba()  # (with Ctrl-C held: backends/interrupts.py)
    import numba
    return not numba.config.ENABLE_CUDASIM and cuda_available()


def _model(core):
    return scalar_model(core.params, core.table, core.law, core.settings)


def _table_name(core) -> str:
    return "open plane" if core.table is None else type(core.table).__name__


def _spec(core, p, target, **options) -> StepSpec:
    """The StepSpec of ``core`` with EnvParams ``p`` for ``target`` (None: the core's backend): the constants
    packed (packing.pack)."""
    from .packing import pack
    m = _model(core)
    return StepSpec(entry_points(core, target, **options), pack(p, m, core.k), p, m, core.k, core.obs_dim,
                    core.n_act, core.counts_arc, core.audit)
