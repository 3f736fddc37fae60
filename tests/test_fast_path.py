"""The environments' fast paths agree bitwise with the batched physics (penny_env/envs/fast_path.py)."""
import math

import numpy as np
import pytest

from penny_env.envs import fast_path as fp
from penny_env.physics import PennyParams, SolverSettings, advance_pennies, flow, make_law, make_table

P = PennyParams()
SET = SolverSettings()
TABLES = [make_table({"kind": "ellipse", "a": 0.15, "b": 0.2}), make_table({"kind": "circle", "r": 0.12}),
          make_table({"kind": "stadium", "radius": 0.1, "length": 0.15})]


def _bits(a):
    return np.asarray(a, dtype=float).view(np.int64)


def _random_inside(rng, table, n):
    out = []
    while len(out) < n:
        x, y = rng.uniform(-0.2, 0.2, 2)
        ph = rng.uniform(-np.pi, np.pi)
        c, s = math.cos(ph), math.sin(ph)
        if table.h(x + P.R * c, y + P.R * s) < 0 and table.h(x - P.R * c, y - P.R * s) < 0:
            out.append([x, y, rng.normal(), ph, rng.normal() * 20, rng.normal() * 8])
    return np.array(out).T


@pytest.mark.parametrize("ti", range(3))
def test_scalar_advance_and_certificate_bitwise(ti):
    table = TABLES[ti]
    rng = np.random.default_rng(10 + ti)
    n = 150
    S = _random_inside(rng, table, n)
    acc1 = np.where(rng.random(n) < 0.5, 0.0, rng.normal(size=n) * 40)
    acc2 = rng.normal(size=n) * 20
    dt = 0.05
    free = fp.certified_free(S, acc1, acc2, dt, P, table, SET)
    assert 0 < free.sum() < n
    one = fp.ScalarPhysics(P, table, make_law("elastic"), SET)
    assert [one.certified_free(tuple(S[:, i]), float(acc1[i]), float(acc2[i]), dt) for i in range(n)] == free.tolist()
    for law in (make_law("elastic"), make_law("plastic"), make_law(0.5)):
        new, log, _ = advance_pennies(S, acc1, acc2, dt, P, table, law, SET)
        assert log.env.size > 5  # impacts do happen
        assert not np.isin(np.flatnonzero(free), log.env).any()
        # certified pennies: advance() is the plain flow, bitwise
        f = np.flatnonzero(free)
        assert np.array_equal(_bits(flow(S[:, f], acc1[f], acc2[f], dt, P.R)), _bits(new[:, f]))
        phys = fp.ScalarPhysics(P, table, law, SET)
        for i in range(n):
            s1, ev, _ = phys.advance(tuple(S[:, i]), float(acc1[i]), float(acc2[i]), dt)
            assert np.array_equal(_bits(s1), _bits(new[:, i]))
            k = log.env == i
            assert len(ev) == k.sum()
            if ev:
                assert np.array_equal(_bits([e[0] for e in ev]), _bits(log.time[k]))
                assert [e[1] for e in ev] == list(log.end[k])
                assert np.array_equal(_bits([e[2] for e in ev]), _bits(log.state[k]))


def test_open_plane():
    phys = fp.ScalarPhysics(P, None, make_law("elastic"), SET)
    for acc1 in (0.0, 7.0):
        s = (0.0, 0.0, 0.0, 0.3, 10.0, 2.0)
        s1, ev, _ = phys.advance(s, acc1, 3.0, 0.05)
        ref = flow(np.array(s)[:, None], acc1, 3.0, 0.05, P.R)[:, 0]
        assert np.array_equal(_bits(s1), _bits(ref)) and not ev
