"""Core.check_options checks the rows of reset options {"state", "target"} in one numpy pass (issue 36 item 4):
the same errors (type, message naming the row and the field) as the row-by-row checks it replaced, on bad rows
anywhere in a batch, and the same accepted states, bitwise."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import penny_env  # noqa: F401
from penny_env.envs.core import PHI_DOT, THETA_DOT
from penny_env.physics.validation import as_state, check_inside

IDS = [("PennyProbeSteer-Stadium-Elastic-v0", {}), ("PennyProbeSteer-Ellipse-Elastic-v0", {}),
       ("PennyProbeDrive-Ellipse-Plastic-v0", {"scene": "circle"}),
       ("PennyProbeSteer-Ellipse-Elastic-v0", {"scene": "rounded_rectangle"}), ("PennyProbeSteer-Plane-v0", {})]


def _core(env_id, kw):
    env = gym.make(env_id, backend="python", **kw)
    return env.unwrapped._core


def reference_check_options(core, options, n):
    """The row-by-row checks as Core.check_options made them before issue 36 (a copy, the reference)."""
    states = targets = None
    if "state" in options:
        W_max, w_max = core.scene.step_speed_limits()
        states = core._rows(options["state"], n, 6, "options['state']")
        for i, s in enumerate(states):
            name = "options['state']" if n == 1 else f"options['state'][{i}]"
            as_state(s, name)
            check_inside(s[:, None], core.params, core.table, name)
            for j, field, bound in ((THETA_DOT, "theta_dot", W_max), (PHI_DOT, "phi_dot", w_max)):
                if abs(s[j]) > bound:
                    raise ValueError(f"{name}: |{field}| = {abs(s[j]):.6g} rad/s is beyond {bound:.6g} rad/s, from "
                                     "where a step at the torque limits could pass MAX_ANGULAR_SPEED "
                                     "(Scene.step_speed_limits; docs/physics.md#limits)")
    if "target" in options:
        targets = core._rows(options["target"], n, 2, "options['target']")
        for i, t in enumerate(targets):
            core._check_target(t, "options['target']" if n == 1 else f"options['target'][{i}]")
    return states, targets


def _outcome(fn):
    try:
        out = fn()
    except (TypeError, ValueError) as exc:
        return type(exc).__name__, str(exc)
    return "ok", out


def _states(core, rng, n):
    """Rows of every kind: valid, ends exactly on the wall or a hair outside/inside it, far outside, non-finite,
    speeds beyond the step limits and beyond MAX_ANGULAR_SPEED."""
    W_max, w_max = core.scene.step_speed_limits()
    ax, ay = core.ax, core.ay
    S = np.zeros((n, 6))
    r = np.sqrt(rng.random(n)) * 0.6
    b = rng.uniform(-np.pi, np.pi, n)
    S[:, 0], S[:, 1] = r * ax * np.cos(b), r * ay * np.sin(b)
    S[:, 2:4] = rng.uniform(-np.pi, np.pi, (n, 2))
    S[:, 4] = rng.uniform(-0.9, 0.9, n) * W_max
    S[:, 5] = rng.uniform(-0.9, 0.9, n) * w_max
    kind = rng.integers(0, 10, n)
    if core.table is not None:  # an end on the wall, moved by a relative hair: both sides of the tolerance
        wall = core.table.boundary(512)[:-1]
        k = rng.integers(0, len(wall), n)
        sigma = np.where(rng.random(n) < 0.5, 1.0, -1.0)
        hair = rng.choice([-1e-6, -1e-9, -1e-12, 0.0, 1e-12, 1e-10, 1e-9, 2e-9, 1e-6], n) * core.table.size
        for i in np.flatnonzero(kind < 3):
            c, s = np.cos(S[i, 3]), np.sin(S[i, 3])
            g = np.array(core.table.grad(*wall[k[i]]))
            g /= np.hypot(*g)
            S[i, 0:2] = wall[k[i]] + hair[i] * g - sigma[i] * core.R * np.array([c, s])
        far = kind == 3
        S[far, 0] += 3 * ax
    S[kind == 4, rng.integers(0, 6)] = rng.choice([np.nan, np.inf, -np.inf])
    for j, bound in ((4, W_max), (5, w_max)):  # a hair beyond the step limit (within MAX_ANGULAR_SPEED or not)
        rows = kind == j + 1
        S[rows, j] = rng.choice([-1.0, 1.0], rows.sum()) * (bound + rng.choice([1e-9, 0.25, 0.4], rows.sum()))
    S[kind == 7, 4 + rng.integers(0, 2)] = 2e5  # beyond MAX_ANGULAR_SPEED
    return S, kind


@pytest.mark.parametrize("env_id,kw", IDS)
def test_same_verdict_and_message_as_the_row_checks(env_id, kw):
    core = _core(env_id, kw)
    rng = np.random.default_rng(0)
    S, kind = _states(core, rng, 3000)
    W_max, w_max = core.scene.step_speed_limits()
    # per row: the vectorised flags cover every row the row-by-row checks refuse
    bad = np.array([_outcome(lambda s=s: reference_check_options(core, {"state": s}, 1))[0] != "ok" for s in S])
    assert bad.sum() > 100 and (~bad).sum() > 100
    flags = core._flag_states(S, W_max, w_max)
    assert not (bad & ~flags).any()
    assert (flags & ~bad).sum() <= 0.02 * len(S)  # the margin flags only the hair's breadth at the wall
    # batches: a good batch, then bad rows planted at random places among good ones
    good = S[~bad][:256]
    assert _outcome(lambda: core.check_options({"state": good}, len(good)))[0] == "ok"
    for trial in range(40):
        batch = good.copy()
        k = rng.integers(1, 4)
        batch[rng.choice(len(batch), k, replace=False)] = S[bad][rng.choice(bad.sum(), k, replace=False)]
        ref = _outcome(lambda: reference_check_options(core, {"state": batch}, len(batch)))
        new = _outcome(lambda: core.check_options({"state": batch}, len(batch)))
        assert ref[0] != "ok" and new == ref, trial
    for s in S[bad][:50]:  # one env (the single env's name, no row index), and one row for every env
        for n in (1, 7):
            assert _outcome(lambda: core.check_options({"state": s}, n)) == \
                _outcome(lambda: reference_check_options(core, {"state": s}, n))


@pytest.mark.parametrize("env_id,kw", IDS)
def test_targets_same_as_the_row_checks(env_id, kw):
    core = _core(env_id, kw)
    rng = np.random.default_rng(1)
    n = 600
    T = rng.uniform(-1.3, 1.3, (n, 2)) * np.array([core.ax, core.ay])
    if core.table is not None:  # targets at the reachable region's edge: the penny's radius inside the wall
        wall = core.table.boundary(256)[:-1]
        for i in range(0, n, 3):
            p = wall[rng.integers(len(wall))]
            g = np.array(core.table.grad(*p))
            T[i] = p - (core.R + rng.choice([-1e-3, -1e-9, 0.0, 1e-9, 1e-3])) * g / np.hypot(*g)
    bad = np.array([_outcome(lambda t=t: reference_check_options(core, {"target": t}, 1))[0] != "ok" for t in T])
    flags = core._flag_targets(T)
    assert not (bad & ~flags).any()
    if core.table is not None:
        assert bad.sum() > 20 and (~bad).sum() > 20
    for trial in range(30):
        batch = T[~bad][:128].copy()
        if bad.any():
            batch[rng.integers(len(batch))] = T[bad][rng.integers(bad.sum())]
        ref = _outcome(lambda: reference_check_options(core, {"target": batch}, len(batch)))
        new = _outcome(lambda: core.check_options({"target": batch}, len(batch)))
        assert new[0] == ref[0] and (new[0] == "ok" or new == ref)
    nan = T[:5].copy()
    nan[3, 1] = np.nan
    assert _outcome(lambda: core.check_options({"target": nan}, 5)) == \
        _outcome(lambda: reference_check_options(core, {"target": nan}, 5))


def test_accepted_states_bitwise():
    """A reset to chosen states and targets puts them in bitwise, and observes them as the single env does."""
    env_id = "PennyProbeSteer-Stadium-Elastic-v0"
    n = 64
    vec = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", backend="python").unwrapped
    vec.reset(seed=123)
    rng = np.random.default_rng(2)
    S, T = vec.states, vec.targets
    S[:, 2:4] += rng.normal(0, 1, (n, 2))
    S[:, 4:6] *= rng.uniform(-1, 1, (n, 2))
    mask = rng.random(n) < 0.5
    mask[0] = True
    before = vec.states
    obs, _ = vec.reset(options={"state": S, "target": T, "reset_mask": mask})
    got = vec.states
    assert np.array_equal(got[mask], S[mask]) and np.array_equal(got[~mask], before[~mask])
    assert np.array_equal(vec.targets[mask], T[mask])
    one = gym.make(env_id, backend="python").unwrapped
    for i in np.flatnonzero(mask)[:8]:
        o1, _ = one.reset(seed=0, options={"state": S[i], "target": T[i]})
        assert np.array_equal(o1, obs[i])
    vec.close()
