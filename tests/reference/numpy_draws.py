"""The episodes' draws as penny_env computed them before 2026-11-26: numpy, vectorised over envs
(envs/core.py's Core.sample of commit 933b537, kept here as an independent implementation). The per-env
stages that replaced it (step/functional.initial_state, step/tasks/) must draw the very same bits:
tests/test_draws.py compares them on every preset."""
import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
N_DRAWS = 8
OFFSET_TRIES = 64
X, Y, THETA, PHI, THETA_DOT, PHI_DOT = range(6)


def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


def seed_keys(seeds):
    arr = np.array([int(s) % (1 << 64) for s in np.atleast_1d(seeds)], dtype=np.uint64)
    return _mix(arr + _GOLDEN)


def uniforms(keys, episodes, n=N_DRAWS):
    base = _mix(keys + _GOLDEN * (episodes.astype(np.uint64) + np.uint64(1)))
    j = (np.arange(1, n + 1, dtype=np.uint64) * _GOLDEN)[:, None]
    z = _mix(base[None, :] + j)
    return (z >> _S11).astype(np.float64) * (1.0 / 9007199254740992.0)


def sample(core, keys, episodes):
    """(S (6, N), target (2, N), arc (2, N)) of Core ``core`` (its scene, task, table), as Core.sample did."""
    scene, task = core.scene, core.task
    table = core.table
    ax, ay = scene.spawn_axes()
    plane = table is None
    fmax = 1.0 if plane else 1.0 - core.params.R / table.inradius
    f_spawn = scene.init["spawn_fraction"]
    u = uniforms(keys, episodes)
    n = u.shape[1]
    init = scene.init
    S = np.empty((6, n))
    r = f_spawn * np.sqrt(u[0])
    a = 2.0 * np.pi * u[1] - np.pi
    S[X] = r * ax * np.cos(a)
    S[Y] = r * ay * np.sin(a)
    for row, name, j in ((THETA, "theta", 2), (PHI, "phi", 3), (THETA_DOT, "theta_dot", 4), (PHI_DOT, "phi_dot", 5)):
        lo, hi = init[name]
        S[row] = lo + (hi - lo) * u[j]
    b = 2.0 * np.pi * u[7] - np.pi
    arc = np.empty((2, n))
    cb, sb = np.cos(b, out=arc[0]), np.sin(b, out=arc[1])
    target = np.empty((2, n))
    if task.kind == "impacts":
        rho = table.wall_distance(cb, sb)
        np.multiply(rho, cb, out=target[0])
        np.multiply(rho, sb, out=target[1])
    else:
        f_target = task.target_fraction * fmax
        rt = f_target * np.sqrt(u[6])
        target[0] = rt * ax * cb
        target[1] = rt * ay * sb
        if task.heading_offset > 0:
            c, s = np.cos(S[PHI]), np.sin(S[PHI])

            def offset(tx, ty):
                return np.abs((tx - S[X]) * s - (ty - S[Y]) * c)

            best = offset(target[0], target[1])
            uu = uniforms(keys, episodes, N_DRAWS + 2 * OFFSET_TRIES)[N_DRAWS:]
            for i in range(OFFSET_TRIES):
                todo = best < task.heading_offset
                if not todo.any():
                    break
                rt = f_target * np.sqrt(uu[2 * i])
                bb = 2.0 * np.pi * uu[2 * i + 1] - np.pi
                tx, ty = rt * ax * np.cos(bb), rt * ay * np.sin(bb)
                d = offset(tx, ty)
                take = todo & (d > best)
                target[0] = np.where(take, tx, target[0])
                target[1] = np.where(take, ty, target[1])
                best = np.where(take, d, best)
    return S, target, arc
