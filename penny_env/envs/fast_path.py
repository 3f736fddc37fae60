"""The environments' fast paths around the physics' event loop.

numpy on size-1 arrays costs ~1 us per operation, so one penny through physics.advance() costs
~100 us per control period. Most control periods contain no impact, and the first step of the
certified impact search (events.first_impact from t = 0: no end touching the wall, and the
quadratic bound of kernels.search_step keeping both ends inside over the whole period) already
proves it. For such a period advance() returns exactly flow(s, dt): the physics' later search
refinements only take steps at least as long as search_step with this bound.

* :func:`certified_free`: that certificate for (6, N) batches; the vector env flows the certified
  pennies directly and sends only the others through physics.advance().
* :class:`ScalarPhysics`: one penny in Python floats. A certified period is one
  physics.scalar.flow1 (bitwise equal to flow.flow); any other period goes to the physics' scalar
  event loop physics.scalar.advance_m (bitwise equal to the batched advance(),
  tests/test_scalar_batch.py). With ``compiled=True`` the same functions run compiled
  (physics/compiled.py; bitwise the same results, several times faster).

tests/test_fast_path.py checks all of this bitwise on random states.
"""
from __future__ import annotations

import numpy as np

from ..physics.kernels import acceleration_bound, search_step
from ..physics import scalar
from ..physics.scalar import certified_free1, scalar_model


class ScalarPhysics:
    """advance() for one penny with Python floats.

    A period that the certificate (physics.scalar.certified_free1) shows to be free of impacts is
    one :func:`flow1` (what advance() returns then); any other period goes through the physics' own
    scalar event loop, physics.scalar.advance_m (bitwise equal to the batched advance()).
    compiled: run numba's compiled copies of these functions (needs numba and a built-in table)."""

    def __init__(self, params, table, law, settings, compiled=False):
        self.params, self.table, self.law, self.settings = params, table, law, settings
        self.R = params.R
        self.model = scalar_model(params, table, law, settings)
        fns = vars(scalar)
        if compiled:
            from ..physics.compiled import compiled_functions
            fns = compiled_functions()
        self._flow1, self._certified_flow1, self._advance_m = fns["flow1"], fns["certified_flow1"], fns["advance_through_m"]
        self.compiled = compiled
        if compiled:  # load the machine code now (numba compiles or reads its cache at the first call)
            rest = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            self._flow1(rest, 0.0, 0.0, 1e-9, self.R)
            if table is not None:
                self._certified_flow1(rest, 0.0, 0.0, 1e-9, self.model)
                self._advance_m(rest, 0.0, 0.0, 1e-9, self.model)

    def certified_free(self, s, acc1, acc2, dt):
        """:func:`certified_free` for one penny (the same kernels, for floats)."""
        return certified_free1(s, acc1, acc2, dt, self.model)

    def advance(self, s, acc1, acc2, dt):
        """(new_state, impacts, rests) over one interval (advance.advance for one penny): impacts a
        list of (time since the interval start, end, post-impact state), rests of (time, pinned)."""
        if self.table is None:
            return self._flow1(s, acc1, acc2, dt, self.R), (), ()
        free, s1 = self._certified_flow1(s, acc1, acc2, dt, self.model)
        if free:
            return s1, (), ()
        s, impacts, rests, _ = self._advance_m(s, acc1, acc2, dt, self.model)  # advance_through_m
        if self.compiled:  # numba's typed lists as Python lists
            impacts, rests = list(impacts), list(rests)
        return s, impacts, rests


def certified_free(S, acc1, acc2, dt, params, table, settings):
    """Boolean (N,): the first search step of events.first_impact (from t = 0, horizon dt) finds
    no end touching the wall and certifies the whole period, so advance() returns flow(S, dt)."""
    R = params.R
    delta = settings.contact_tol * table.size
    W, w, ph = S[4], S[5], S[3]
    c, sn = np.cos(ph), np.sin(ph)
    M = acceleration_bound(W, W + acc2 * dt, w, w + acc1 * dt, acc1, acc2, R, table.grad_bound, table.hessian_bound)
    RW = R * W
    ok = None
    tau = None
    for sigma in (1.0, -1.0):
        sR = sigma * R
        px = S[0] + sR * c
        py = S[1] + sR * sn
        vx = RW * c - sR * w * sn
        vy = RW * sn + sR * w * c
        hx, hy = table.grad(px, py)
        g = table.h(px, py)
        gd = hx * vx + hy * vy
        hit = (g >= -delta) & (gd > 0.0)
        step = search_step(g, gd, M, delta)
        ok = ~hit if ok is None else ok & ~hit
        tau = step if tau is None else np.minimum(tau, step)
    return ok & ~(tau < dt)
