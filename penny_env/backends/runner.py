"""The vector step's runners: one interface (:class:`Runner`), behind which the CPU loop and the CUDA kernels sit.

A runner holds the N envs' state (step/functional.EnvState) where its target computes (numpy arrays on the host;
device arrays on a GPU: backends/cuda_env.DeviceStep) and runs the step built for its target
(backends/env.EnvEntryPoints). Every runner is made as ``Runner(spec, n, K, options)`` by
backends/stepping.make_runner, the one door of the envs into the backends; PennyVectorEnv talks to it through
the methods of :class:`Runner` only, and builds the info from what :meth:`Runner.step` and :meth:`Runner.reset`
return, with one builder for every array type (envs/vector_env.py).
"""
from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from ..step.functional import SAME_STEP, EnvState, StepResults, check_actions, kinetic_energy
from . import threads
from .interrupts import compiling, overloads


class StepSpec(NamedTuple):
    """What a runner steps (made by backends/stepping.make_runner): the entry points built for its target
    (env.EnvEntryPoints), the constants packed (packing.pack) and the records they pack (functional.EnvParams
    ``p``, scalar.Model ``m``, the task's constants ``k``), the observation's and the action's widths, whether
    the task counts impacts on its marked arc, and the audit of a user's registered table (or None)."""

    fns: object
    consts: np.ndarray
    p: tuple
    m: tuple
    k: tuple
    obs_dim: int
    n_act: int
    counts_arc: bool
    audit: object = None


class RunnerOptions(NamedTuple):
    """Where and how a runner steps: the CUDA device index (None: the current one), the outputs' array type
    ("numpy", "torch" or "device") and the CUDA step's kernels ("split" or "one"). The CPU runner takes the
    defaults only (numpy outputs)."""

    device: int | None = None
    outputs: str = "numpy"
    kernels: str = "split"


class Runner(Protocol):
    """The vector step of N envs on one target, as PennyVectorEnv uses it (CpuRunner, cuda_env.DeviceStep)."""

    outputs: str  # "numpy", "torch" or "device": the array type of what the runner returns
    spec: StepSpec  # what it steps (its constructor's)

    def __init__(self, spec: StepSpec, n: int, K: int, options: RunnerOptions) -> None:
        """N envs' state, zeroed, and the step of ``spec`` for them; K: the impact slots each step reports."""

    def check_actions(self, actions):
        """The actions as :meth:`step` takes them; TypeError / ValueError naming the sub-env, nothing changed."""

    def step(self, actions) -> StepOutputs:
        """One step of every env on checked actions, autoreset included, in the runner's array type."""

    def reset(self, keys, episodes, rows, states=None, targets=None) -> tuple:
        """Episodes drawn for ``rows`` (reset options applied); (obs, StepOutputs of the reset's info)."""

    def warm_up(self) -> None:
        """Every compiled function a step or a reset can call, loaded (or compiled) now, not inside a step."""

    def mask(self):
        """An info mask of every env (``_key``), in the runner's array type."""

    def host(self, name: str) -> np.ndarray:
        """A field of the state as a numpy array (a copy on a GPU)."""

    def state_to_host(self) -> EnvState:
        """The whole state as numpy arrays (pickling)."""

    def state_from_host(self, st) -> None:
        """The whole state from numpy arrays (unpickling)."""


class StepOutputs(NamedTuple):
    """What a step (or a reset) returns: the per-env results (functional.StepResults) and the info's impact
    arrays, counts (N,), times (N, K) and ends (N, K), in the runner's array type."""

    results: StepResults
    counts: object
    times: object
    ends: object


def new_state(n: int) -> EnvState:
    """A zeroed functional.EnvState of n envs (numpy)."""
    return EnvState(np.zeros((6, n)), np.zeros((4, n)), np.zeros((2, n)), np.zeros((2, n)), np.zeros(n, dtype=np.int64),
                    np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n), np.zeros(n, dtype=np.uint64),
                    np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool))


def reset_outputs(obs, st: EnvState, p, K: int, xp=np) -> StepOutputs:
    """The outputs a reset's info is built from: no impacts, the envs' energy, time, distance and arc count, in
    the array namespace of ``st`` (numpy on the host)."""
    n = st.S.shape[1]
    z = np.zeros
    results = StepResults(obs, z(n), z(n, dtype=bool), z(n, dtype=bool), kinetic_energy(st.S, p), z(n, dtype=np.int8),
                          st.time.copy(), st.dist.copy(), st.count.copy(), None, z(n, dtype=bool))
    return StepOutputs(results, z(n, dtype=np.int64), np.full((n, K), np.nan), z((n, K), dtype=np.int8))


class CpuRunner:
    """The vector step on the CPU: the compiled loop (numba, parallel over envs, serial below
    threads.SERIAL_BELOW envs and in forked children) or the plain-Python one (backend "python"); the state in
    numpy arrays. What a step returns is new arrays each step (the caller may keep them)."""

    outputs = "numpy"

    def __init__(self, spec: StepSpec, n: int, K: int, options: RunnerOptions = RunnerOptions()):
        if options != RunnerOptions():
            raise ValueError(f"the CPU runner takes no device, numpy outputs and no CUDA kernels, got {options}")
        fns, p, obs_dim = spec.fns, spec.p, spec.obs_dim
        self.spec = spec
        self.fns, self.consts, self.p, self.audit = fns, spec.consts, p, spec.audit
        self.n, self.K, self.obs_dim, self.n_act, self.counts_arc = n, K, obs_dim, spec.n_act, spec.counts_arc
        self.same_step = p.autoreset == SAME_STEP
        self.st = new_state(n)
        self.mask = np.ones(n, dtype=bool).copy  # (an info mask: a new array each call, a copy costs a third of np.ones)
        serial = getattr(fns.step_envs, "serial", None)
        # fewer envs than threads.SERIAL_BELOW: the serial loop, called directly (threads.locked)
        self.step_envs = serial() if serial is not None and n < threads.SERIAL_BELOW else fns.step_envs
        # the dispatcher the steps will run: also the serial one in a forked child (threads.serial_now), where the
        # parallel one is never built (what the compile notice names: backends/stepping.py)
        self.dispatcher = (serial() if serial is not None and (threads.serial_now() or n < threads.SERIAL_BELOW)
                           else getattr(fns.step_envs, "__wrapped__", fns.step_envs))
        # reused from step to step (the info returns none of them; a fresh array costs about 0.2 us, a fifth of the
        # step's host time at N = 1): the arc counts and guard faults, the done flags, the empty post-impact states
        # and rest flags (the env does not keep them), SAME_STEP's final observations, the counts' template
        final = (n if self.same_step else 0, obs_dim)
        # (post-impact states only where a user's table is audited at its impacts: physics/tables/registered.py)
        Kp = K if spec.audit is not None else 0
        self._scratch = (np.empty(n, dtype=np.int64), np.zeros(n, dtype=np.int8), np.empty(n, dtype=bool),
                         np.empty((Kp, 6, n)), np.empty((Kp, n), dtype=np.int8), np.empty(final, dtype=np.float32),
                         np.full(n, K, dtype=np.int64), np.empty(n, dtype=np.int64))

    def check_actions(self, actions):
        return check_actions(actions, (self.n, self.n_act), "actions")  # (the step clips, as PennyEnv does)

    def buffers(self, n=None):
        """Fresh step outputs (functional.StepResults' arrays as a plain tuple) and impact buffers: the impact slots
        are (n, K) arrays handed to the loop transposed ((K, n): scalar.ImpactBuffers' layout), so each env's slots
        stay together; their counts start at K, so the step pads every slot (functional.step_env clears what a row
        held). Returns (out, buf, times, ends)."""
        n = self.n if n is None else n
        K, d = self.K, self.obs_dim
        arc, fault, done, post, rest, final, full, arc_total = self._scratch if n == self.n else \
            (np.empty(n, dtype=np.int64), np.zeros(n, dtype=np.int8), np.empty(n, dtype=bool), np.empty((0, 6, n)),
             np.empty((0, n), dtype=np.int8), np.empty((n if self.same_step else 0, d), dtype=np.float32),
             np.full(n, K, dtype=np.int64), np.empty(n, dtype=np.int64))
        out = (np.empty((n, d), dtype=np.float32), np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=bool),
               np.empty(n), np.empty(n, dtype=np.int8), np.empty(n), np.empty(n),
               np.empty(n, dtype=np.int64) if self.counts_arc else arc_total, final, done)  # (arc_total: not buf's arc)
        times, ends = np.empty((n, K)), np.empty((n, K), dtype=np.int8)
        buf = (full.copy(), times.T, ends.T, post, rest, arc, fault)  # (a copy: np.full costs 0.7 us, a copy 0.1)
        return out, buf, times, ends

    def step(self, actions) -> StepOutputs:
        out, buf, times, ends = self.buffers()
        self.step_envs(tuple(self.st), actions, self.consts, out, buf)
        # (the records made with tuple.__new__: the NamedTuples' own constructors cost a few per cent of a step at N = 1)
        if self.audit is not None:  # a user's registered shape: its formulas against its own h at a sample of impacts
            counts, post = buf[0], buf[3]
            for i in np.flatnonzero(counts):
                k = min(int(counts[i]), self.K)
                self.audit.check(post[:k, :, i], ends[i, :k], f"PennyVectorEnv.step, env {i}")
        return tuple.__new__(StepOutputs, (tuple.__new__(StepResults, out), buf[0], times, ends))

    def reset(self, keys, episodes, rows, states=None, targets=None):
        """Episodes drawn for ``rows`` (their keys and episode counters given for every env), reset options' states
        and targets put in, every env's observation made; (obs, StepOutputs of the reset's info)."""
        st = self.st
        st.key[:], st.episode[:] = keys, episodes
        st.pending[rows] = False
        obs = np.empty((self.n, self.obs_dim), dtype=np.float32)
        self.fns.reset_rows(rows, tuple(st), self.consts, obs)
        if states is not None or targets is not None:
            if states is not None:
                st.S[:, rows] = states[rows].T
            if targets is not None:
                st.target[:, rows] = targets[rows].T
            self.fns.observe_rows(rows, tuple(st), self.consts, obs)
        others = np.flatnonzero(~np.isin(np.arange(self.n), rows))
        if others.size:  # the envs outside a reset_mask keep their state; their observation as it is
            self.fns.observe_rows(others, tuple(st), self.consts, obs)
        return obs, reset_outputs(obs, st, self.p, self.K)

    def warm_up(self) -> None:
        """Every compiled function a step or a reset of this env can call, loaded (or compiled) now rather than inside
        a step: the step with this env's own arrays (numba types an array's layout: the (K, 1) impact slots of one env
        are C-contiguous, those of more envs Fortran-ordered, so a warm-up of another size would leave the first
        step to compile), the resets and observations of one row and, where a reset of every row takes the
        parallel loop, of every row. A compile interrupted by Ctrl-C corrupts numba's LLVM state; their first calls
        hold it (threads.locked)."""
        n = self.n
        fns = (self.step_envs, self.fns.reset_rows, self.fns.observe_rows)
        before = overloads(*fns)
        with compiling(collect=lambda: overloads(*fns) != before):
            st = tuple(new_state(n))
            out, buf, _, _ = self.buffers()
            self.step_envs(st, np.zeros((n, self.n_act)), self.consts, out, buf)
            for rows in {1, n} if n >= threads.SERIAL_BELOW and not threads.serial_now() else {1}:
                obs = np.empty((n, self.obs_dim), dtype=np.float32)
                self.fns.reset_rows(np.arange(rows), st, self.consts, obs)
                self.fns.observe_rows(np.arange(rows), st, self.consts, obs)

    def host(self, name):
        return getattr(self.st, name)

    def state_to_host(self) -> EnvState:
        return self.st

    def state_from_host(self, st) -> None:
        self.st = EnvState(*st)
