"""What PennyEnv and PennyVectorEnv share besides the step (functional.py): the scene's constants,
the spaces' bounds and the per-episode sampling.

Episode randomness is counter based: the initial state and the target of episode ``e`` of an env
whose seed key is ``k`` are a hash (SplitMix64) of (k, e, draw index), computed with uint64 numpy
arrays. A sub-env of the vector env seeded with ``seed + i`` therefore draws exactly what a single
env seeded with ``seed + i`` draws, episode after episode, and the draws of many envs are one
array operation (no per-env generator objects in the step path).
"""
from __future__ import annotations


import numpy as np

from ..physics import SolverSettings
from ..physics.validation import as_state, check_inside, real_array
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


MAX_RENDER_FPS = 1000  # metadata["render_fps"] of a scene whose control_dt is below 1 ms


def render_fps(control_dt: float) -> int:
    """metadata["render_fps"]: one frame per control period, within [1, MAX_RENDER_FPS] (1 / 5e-324
    is inf, which int(round()) cannot take)."""
    fps = 1.0 / control_dt
    return MAX_RENDER_FPS if fps >= MAX_RENDER_FPS else max(1, int(round(fps)))


def check_seed(seed, name: str = "seed", count: int = 1) -> int:
    """A seed as Gymnasium takes it, an int >= 0 (not a bool; numpy integers too), that with the
    count - 1 seeds after it (a vector env's seed + i) stays below 2**64, the range of the episode
    keys (seed_keys; beyond it two seeds would share a key). TypeError or ValueError naming name."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{name} must be an int >= 0 or None, got {type(seed).__name__}")
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"{name} must be >= 0, got {seed}")
    if seed + count - 1 >= 1 << 64:
        what = "" if count == 1 else f" (with the {count} sub-envs' seeds seed + i)"
        raise ValueError(f"{name} must be < 2**64{what}, got {seed}")
    return seed


def seed_keys(seeds) -> np.ndarray:
    """uint64 keys from integer seeds in [0, 2**64) (check_seed)."""
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

    def __init__(self, scene: Scene, task: Task, settings: SolverSettings | None = None, backend: str = "auto"):
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
        self.backend = self._backend(backend)  # "numba": the compiled step (functional.py), "python": as written
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
        """'numba' or 'python': 'auto' takes numba where it is installed and the table compiles
        (physics.compiled.choose_backend), else the plain-Python step with a warning naming it."""
        from ..physics.compiled import choose_backend
        if backend not in ("auto", "numba", "python"):
            raise ValueError(f"backend must be 'auto', 'numba' or 'python', got {backend!r}")
        if backend == "python":
            return "python"
        try:
            chosen = "numba" if choose_backend(backend, self.params, self.table, self.law, self.settings,
                                               "scene.table") == "numba" else "python"
        except ValueError as err:  # (the batch's wording names its own plain backend)
            raise ValueError(str(err).replace("backend='numpy'", "backend='python'")) from None
        if chosen == "python":
            import warnings
            warnings.warn("penny_env: the compiled step cannot run here (numba missing or a table that does not "
                          "compile); using the plain-Python step (backend='python'), much slower", stacklevel=4)
        return chosen

    def __getstate__(self):
        return {"scene": self.scene, "task": self.task, "settings": self.settings, "backend": self.backend}

    def __setstate__(self, state):
        self.__init__(state["scene"], state["task"], state["settings"], state.get("backend", "auto"))

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

    def distance(self, S, target):
        dx = target[0] - S[X]
        dy = target[1] - S[Y]
        return np.sqrt(dx * dx + dy * dy)

    # -- reset options -------------------------------------------------------------------
    def check_options(self, options, n, extra=()):
        """(states (n, 6) or None, targets (n, 2) or None) from reset options {"state", "target"}
        (plus the keys in extra, which the caller handles), with the checks of the scene fields:
        states finite with both ends of the penny inside the table; targets finite, inside the
        region the contact point can reach (and so inside the observation's Box). One row (shape
        (6,) / (2,)) applies to every env."""
        if not isinstance(options, dict):
            raise TypeError(f"reset options must be a dict, got {type(options).__name__}")
        allowed = ["state", "target", *extra]
        unknown = sorted(set(options) - set(allowed), key=str)
        if unknown:
            raise ValueError(f"reset options: unknown key(s) {unknown}; allowed: {allowed}")
        states = targets = None
        if "state" in options:
            W_max, w_max = self.scene.step_speed_limits()
            states = self._rows(options["state"], n, 6, "options['state']")
            for i, s in enumerate(states):
                name = "options['state']" if n == 1 else f"options['state'][{i}]"
                as_state(s, name)
                check_inside(s[:, None], self.params, self.table, name)
                for j, field, bound in ((THETA_DOT, "theta_dot", W_max), (PHI_DOT, "phi_dot", w_max)):
                    if abs(s[j]) > bound:  # the scene's init ranges obey the same bound (Scene)
                        raise ValueError(f"{name}: |{field}| = {abs(s[j]):.6g} rad/s is beyond {bound:.6g} rad/s, from "
                                         "where a step at the torque limits could pass MAX_ANGULAR_SPEED "
                                         "(Scene.step_speed_limits; docs/physics.md#limits)")
        if "target" in options:
            if self.impacts:
                raise ValueError("options['target']: the impacts task's target is the centre of the marked arc, "
                                 "drawn each episode; it cannot be set")
            targets = self._rows(options["target"], n, 2, "options['target']")
            for i, t in enumerate(targets):
                self._check_target(t, "options['target']" if n == 1 else f"options['target'][{i}]")
        return states, targets

    @staticmethod
    def _rows(value, n, width, name):
        arr = real_array(value, name, "an array")
        if arr.shape == (width,):
            arr = np.broadcast_to(arr, (n, width))
        if arr.shape != (n, width):
            raise ValueError(f"{name} must have shape ({width},){'' if n == 1 else f' or ({n}, {width})'}, got {arr.shape}")
        if width == 2 and not np.isfinite(arr).all():  # (states: as_state names the fields)
            raise ValueError(f"{name} has non-finite entries")
        return np.array(arr)

    def _check_target(self, t, name):
        """A target the contact point can reach: some heading puts both ends of the penny inside
        the table (64 headings tried); on the open plane any finite point."""
        if self.plane:
            return
        ph = np.linspace(0.0, np.pi, 64, endpoint=False)
        R = self.R
        fits = ((self.table.h(t[0] + R * np.cos(ph), t[1] + R * np.sin(ph)) < 0)
                & (self.table.h(t[0] - R * np.cos(ph), t[1] - R * np.sin(ph)) < 0))
        if not fits.any():
            raise ValueError(f"{name} = ({t[0]:.6g}, {t[1]:.6g}) is outside the region the penny's contact point "
                             "can reach (no heading keeps both ends inside the table)")


def check_actions(actions, shape, name="action"):
    """float64 array of the given shape from actions: a TypeError for a wrong type (strings,
    None, bools, complex numbers, objects), a ValueError naming the sub-env(s) for a wrong shape
    or non-finite entries. Nothing is clipped here (the step clips)."""
    arr = real_array(actions, name, "an array")  # also finds a bool or string inside a list
    if arr.shape != shape:
        if len(shape) == 2 and shape[1] == 1 and arr.shape == shape[:1]:
            arr = arr[:, None]
        else:
            raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    finite = np.isfinite(arr)
    if not finite.all():
        if arr.ndim == 1:
            raise ValueError(f"{name} has a non-finite entry: {arr.tolist()}")
        bad = np.flatnonzero(~finite.all(axis=1))
        raise ValueError(f"{name}: non-finite action in sub-env(s) {bad[:10].tolist()}{' ...' if bad.size > 10 else ''}")
    return np.ascontiguousarray(arr)
