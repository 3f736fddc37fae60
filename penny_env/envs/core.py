"""The episode logic shared by PennyEnv and PennyVectorEnv: constants, per-episode sampling,
observations, actions and the batched control step.

Episode randomness is counter based: the initial state and the target of episode ``e`` of an env
whose seed key is ``k`` are a hash (SplitMix64) of (k, e, draw index), computed with uint64 numpy
arrays. A sub-env of the vector env seeded with ``seed + i`` therefore draws exactly what a single
env seeded with ``seed + i`` draws, episode after episode, and the draws of many envs are one
array operation (no per-env generator objects in the step path).
"""
from __future__ import annotations


import numpy as np

from ..physics import SolverSettings, flow
from ..physics import advance_pennies as advance  # the plain-Python per-penny loop
from .fast_path import ScalarPhysics, certified_free
from .scene import Scene, Task, ConfigError
from .tasks import task_constants

X, Y, THETA, PHI, THETA_DOT, PHI_DOT = range(6)

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
N_DRAWS = 8
OFFSET_TRIES = 64  # target candidates per episode when task.heading_offset > 0


def _mix(z):
    """SplitMix64 finaliser on uint64 arrays (wrapping arithmetic)."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


def seed_keys(seeds) -> np.ndarray:
    """uint64 keys from non-negative integer seeds."""
    arr = np.array([int(s) % (1 << 64) for s in np.atleast_1d(seeds)], dtype=np.uint64)
    return _mix(arr + _GOLDEN)


def uniforms(keys, episodes, n=N_DRAWS) -> np.ndarray:
    """(n, N) uniforms in [0, 1) for episode `episodes` of the envs with `keys`."""
    base = _mix(keys + _GOLDEN * (episodes.astype(np.uint64) + np.uint64(1)))
    j = (np.arange(1, n + 1, dtype=np.uint64) * _GOLDEN)[:, None]
    z = _mix(base[None, :] + j)
    return (z >> _S11).astype(np.float64) * (1.0 / 9007199254740992.0)


class Core:
    """Everything the environments compute, from (Scene, Task). Picklable (rebuilt from them)."""

    def __init__(self, scene: Scene, task: Task, settings: SolverSettings | None = None, backend: str = "numpy"):
        self.scene, self.task = scene, task
        self.settings = settings if settings is not None else SolverSettings()
        self.params = scene.make_params()
        self.table = scene.make_table()
        self.law = scene.make_law()
        if task.kind == "impacts" and self.table is None:
            raise ConfigError("task.kind 'impacts' needs a table with walls; scene.table is the open plane")
        p = self.params
        self.R, self.J, self.Itot = p.R, p.J, p.rolling_inertia
        self.dt = scene.control_dt
        self.controls = scene.controls
        self.n_act = len(self.controls)
        self.gain1 = scene.torque_limits["u1"] / self.J if 0 in self.controls else 0.0
        self.gain2 = scene.torque_limits["u2"] / self.Itot if 1 in self.controls else 0.0
        self.plane = self.table is None
        self.L = scene.length_scale()
        self.inv_L = 1.0 / self.L
        self.s_W = 1.0 / scene.obs_scale["theta_dot"]
        self.s_w = 1.0 / scene.obs_scale["phi_dot"]
        self.k = task_constants(scene, task, self.L)
        self.impacts = task.kind == "impacts"
        self.obs_dim = 11 if self.impacts else 10
        self.max_steps = task.max_episode_steps
        self.backend = self._backend(backend)  # "numba": compiled physics (single env) and step (vector env)
        self.fast = ScalarPhysics(p, self.table, self.law, self.settings, compiled=self.backend == "numba")
        ax, ay = scene.spawn_axes()
        self.ax, self.ay = ax, ay
        fmax = 1.0 if self.plane else 1.0 - p.R / self.table.inradius
        self.f_spawn = scene.init["spawn_fraction"]
        self.f_target = task.target_fraction * fmax
        self.delta = 0.0 if self.plane else self.settings.contact_tol * self.table.size
        self.heading_offset = task.heading_offset
        if self.heading_offset > 0 and not self.heading_offset < self.f_target * min(ax, ay):
            # any line through the spawn point leaves target points farther than the target
            # ellipse's semi-minor axis, so below it the accepted region has positive area
            raise ConfigError(f"task.heading_offset must be < target_fraction (1 - R / inradius) x the spawn "
                              f"ellipse's semi-minor axis = {self.f_target * min(ax, ay):.6g} m, got {self.heading_offset!r}")

    def _backend(self, backend):
        """'numba' or 'numpy' (see physics.compiled.choose_backend)."""
        from ..physics.compiled import choose_backend
        return choose_backend(backend, self.params, self.table, self.law, self.settings, "scene.table")

    def __getstate__(self):
        return {"scene": self.scene, "task": self.task, "settings": self.settings, "backend": self.backend}

    def __setstate__(self, state):
        self.__init__(state["scene"], state["task"], state["settings"], state.get("backend", "numpy"))

    # -- spaces --------------------------------------------------------------------------
    def obs_bounds(self):
        hi = np.ones(self.obs_dim, dtype=np.float32)
        if not self.plane:
            hi[8:10] = 2.0
        lo = -hi
        if self.impacts:
            lo[10] = 0.0
        return lo, hi

    # -- sampling ------------------------------------------------------------------------
    def sample(self, keys, episodes):
        """(S (6, N), target (2, N), arc (2, N) = (cos, sin) of the arc direction)."""
        u = uniforms(keys, episodes)
        n = u.shape[1]
        init = self.scene.init
        S = np.empty((6, n))
        r = self.f_spawn * np.sqrt(u[0])
        a = 2.0 * np.pi * u[1] - np.pi
        S[X] = r * self.ax * np.cos(a)
        S[Y] = r * self.ay * np.sin(a)
        for row, name, j in ((THETA, "theta", 2), (PHI, "phi", 3), (THETA_DOT, "theta_dot", 4), (PHI_DOT, "phi_dot", 5)):
            lo, hi = init[name]
            S[row] = lo + (hi - lo) * u[j]
        b = 2.0 * np.pi * u[7] - np.pi
        arc = np.empty((2, n))
        cb, sb = np.cos(b, out=arc[0]), np.sin(b, out=arc[1])
        target = np.empty((2, n))
        if self.impacts:
            rho = self._wall_radius(cb, sb)
            np.multiply(rho, cb, out=target[0])
            np.multiply(rho, sb, out=target[1])
        else:
            rt = self.f_target * np.sqrt(u[6])
            target[0] = rt * self.ax * cb
            target[1] = rt * self.ay * sb
            if self.heading_offset > 0:
                self._offset_targets(keys, episodes, S, target)
        return S, target, arc

    def _offset_targets(self, keys, episodes, S, target):
        """Redraw, in place, the targets closer than task.heading_offset to the initial heading
        line: the first of OFFSET_TRIES further candidates (draws N_DRAWS.. of the episode's
        stream, so the draws above are unchanged) that is far enough, else the farthest one."""
        c, s = np.cos(S[PHI]), np.sin(S[PHI])

        def offset(tx, ty):
            return np.abs((tx - S[X]) * s - (ty - S[Y]) * c)

        best = offset(target[0], target[1])
        u = uniforms(keys, episodes, N_DRAWS + 2 * OFFSET_TRIES)[N_DRAWS:]
        for i in range(OFFSET_TRIES):
            todo = best < self.heading_offset
            if not todo.any():
                break
            rt = self.f_target * np.sqrt(u[2 * i])
            b = 2.0 * np.pi * u[2 * i + 1] - np.pi
            tx, ty = rt * self.ax * np.cos(b), rt * self.ay * np.sin(b)
            d = offset(tx, ty)
            take = todo & (d > best)
            target[0] = np.where(take, tx, target[0])
            target[1] = np.where(take, ty, target[1])
            best = np.where(take, d, best)

    def _wall_radius(self, c, s):
        """Distance from the centre to the wall along (c, s) (the table's own wall_distance)."""
        return self.table.wall_distance(c, s)

    # -- actions -------------------------------------------------------------------------
    def accelerations(self, a):
        """(acc1, acc2) arrays from clipped (N, n_act) float64 actions."""
        n = a.shape[0]
        if self.n_act == 2:
            return a[:, 0] * self.gain1, a[:, 1] * self.gain2
        if self.controls == (0,):
            return a[:, 0] * self.gain1, np.zeros(n)
        return np.zeros(n), a[:, 0] * self.gain2

    # -- observations --------------------------------------------------------------------
    @staticmethod
    def angle_trig(S):
        """(4, N): cos theta, sin theta, cos phi, sin phi."""
        return np.stack([np.cos(S[THETA]), np.sin(S[THETA]), np.cos(S[PHI]), np.sin(S[PHI])])

    def observe(self, S, target, count=None, trig=None):
        """(N, obs_dim) float32 observations (layout in PennyEnv's docstring); trig: angle_trig(S)
        if already known."""
        n = S.shape[1]
        o = np.empty((self.obs_dim, n))
        rx = target[0] - S[X]
        ry = target[1] - S[Y]
        o[0] = S[X] * self.inv_L
        o[1] = S[Y] * self.inv_L
        o[8] = rx * self.inv_L
        o[9] = ry * self.inv_L
        if self.plane:
            np.tanh(o[0:2], out=o[0:2])
            np.tanh(o[8:10], out=o[8:10])
        o[2:6] = self.angle_trig(S) if trig is None else trig
        o[6] = np.tanh(S[THETA_DOT] * self.s_W)
        o[7] = np.tanh(S[PHI_DOT] * self.s_w)
        if self.impacts:
            o[10] = np.minimum(count / self.k.goal, 1.0)
        return o.T.astype(np.float32)

    def distance(self, S, target):
        dx = target[0] - S[X]
        dy = target[1] - S[Y]
        return np.sqrt(dx * dx + dy * dy)

    # -- physics ---------------------------------------------------------------------------
    def advance(self, S, acc1, acc2):
        """(new S, log arrays (env, time, end, state (k, 6)) or None) over one control period,
        batched with numpy (the vector env's numpy backend).

        The open plane is one closed-form (or quadrature) flow. With walls, the pennies whose first
        certified search step excludes an impact are flowed directly (what advance() would do),
        the others go through physics.advance_pennies()."""
        if self.plane:
            return flow(S, acc1, acc2, self.dt, self.R), None
        free = certified_free(S, acc1, acc2, self.dt, self.params, self.table, self.settings)
        if free.all():
            return flow(S, acc1, acc2, self.dt, self.R), None
        out = np.empty_like(S)
        i = np.flatnonzero(free)
        j = np.flatnonzero(~free)
        if i.size:
            out[:, i] = flow(S[:, i], acc1[i], acc2[i], self.dt, self.R)
        sub, log, _ = advance(S[:, j], acc1[j], acc2[j], self.dt, self.params, self.table, self.law, self.settings)
        out[:, j] = sub
        if log.env.size == 0:
            return out, None
        return out, (j[log.env], log.time, log.end, log.state)
