"""What PennyEnv and PennyVectorEnv share besides the step (functional.py): the scene's constants, the task's
record and constants, the spaces' bounds, the seeds' checks and the reset options' checks.

Episode randomness is counter based (step/draws.py): the initial state and target of episode ``e`` of an env
whose seed key is ``k`` are a hash of (k, e, draw index), drawn per env by functional.initial_state on every
backend. A sub-env of the vector env seeded with ``seed + i`` therefore draws exactly what a single env
seeded with ``seed + i`` draws, episode after episode, on the CPU and on a GPU.
"""
from __future__ import annotations


import numpy as np

from ..physics import SolverSettings
from ..backends import stepping
from ..physics.faults import warn_episode_fault
from ..physics.tables.registered import ImpactAudit, audited
from ..physics.flows import end_kinematics
from ..physics.params import MAX_ANGULAR_SPEED
from ..physics.validation import as_state, check_inside, real_array

from ..step.functional import FAULT_OF_LIMIT, LIMIT_NAMES, LIMIT_TASK_OUTPUT, OBS_BOUND, TARGET_OBS_BOUND
from ..step.config import ConfigError
from ..step.draws import seed_keys  # noqa: F401  (re-exported: the envs turn seeds into keys with it)
from .scene import Scene, Task
from ..step.tasks import task_record
from ..step.tasks.base import check_constants, retry_before_use

X, Y, THETA, PHI, THETA_DOT, PHI_DOT = range(6)
INSIDE_TOL = check_inside.__defaults__[-1]  # check_inside's tolerance on the ends' h (x table.size)


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


class Core:
    """Everything the environments compute, from (Scene, Task). Picklable (rebuilt from them)."""

    def __init__(self, scene: Scene, task: Task, settings: SolverSettings | None = None, backend: str = "auto",
                 record=None):
        self.scene, self.task = scene, task
        self.settings = settings if settings is not None else SolverSettings()
        self.params = scene.make_params()
        self.table = scene.make_table()
        self.law = scene.make_law()
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
        self.task_record = task_record(task.kind) if record is None else record
        retry_before_use(self.task_record)  # (a registered task whose module was edited since: tried again)
        if self.task_record.needs_walls and self.table is None:
            raise ConfigError(f"task.kind {task.kind!r} needs a table with walls; scene.table is the open plane")
        try:
            self.k = self.task_record.constants(scene, task, self.L)
        except (ConfigError, TypeError) as exc:
            raise type(exc)(str(exc)) from None
        except Exception as exc:  # noqa: BLE001 (the task's own function: named, not a bare ZeroDivisionError)
            raise ValueError(f"task {self.task_record.name!r}: constants(scene, task, L) raised {type(exc).__name__}: "
                             f"{exc}") from exc
        check_constants(self.task_record, self.k)
        self.counts_arc = self.task_record.marked_arc is not None  # info["arc_impacts"]
        self.impacts = self.counts_arc  # (the name the renderer and the info use)
        self.obs_dim = self.task_record.obs_dim
        self.max_steps = task.max_episode_steps
        # "numba": the compiled step (functional.py), "python": as written (backends/stepping.env_backend)
        self.backend = stepping.env_backend(backend, self.table, self.law)
        # a user's registered shape: a sample of the impacts compared with its own h (tables/registered.py)
        self.audit = ImpactAudit(self.table, self.R) if audited(self.table) else None
        self.ax, self.ay = scene.spawn_axes()

    def named_failure(self, exc, where: str):
        """A ValueError naming the scene's law or table when ``exc`` was raised inside the user's function (the
        plain-Python step calls them as written; physics/faults.blame), else None (re-raise ``exc`` as it is)."""
        from ..physics.faults import blame
        return blame(exc, self.law, self.table, where)

    def entry_points(self, target=None, **options):
        """The env step's entry points (backends/env.py) for ``target`` ("python", "cpu", "cuda"; None: this
        core's backend) and this scene's table kind and task."""
        return stepping.entry_points(self, target, **options)

    def draw_episodes(self, keys, episodes):
        """(S (6, N), target (2, N), arc (2, N)): the initial states, targets and marked arcs' directions of
        episodes ``episodes`` (N,) of the envs with seed keys ``keys`` (N,) uint64 (draws.seed_keys), drawn by
        the env step's own reset stage (functional.initial_state) on this core's backend."""
        return stepping.draw_episodes(self, keys, episodes)

    def __getstate__(self):
        return {"scene": self.scene, "task": self.task, "settings": self.settings, "backend": self.backend}

    def __setstate__(self, state):
        self.__init__(state["scene"], state["task"], state["settings"], state.get("backend", "auto"))

    # -- spaces --------------------------------------------------------------------------
    def obs_bounds(self):
        """(low, high) float32 of the observation space: functional.OBS_BOUND and TARGET_OBS_BOUND for the entries
        every task has, the task's extra_obs (rounded to float32, as the step's guard compares them) for its own."""
        hi = np.full(self.obs_dim, OBS_BOUND, dtype=np.float32)
        if not self.plane:
            hi[8:10] = TARGET_OBS_BOUND
        lo = -hi
        for j, (a, b) in enumerate(self.task_record.extra_obs):  # the task's own entries
            lo[10 + j], hi[10 + j] = a, b
        return lo, hi

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
            # every check in one numpy pass over the rows (a Python loop over 4096 rows took 0.4-2.5 s); the rows it
            # flags (every row any check could refuse, and a few more at the wall's tolerance) go through the checks
            # one by one, in row order, so the first refused row raises the same error, naming the row and the field
            for i in np.flatnonzero(self._flag_states(states, W_max, w_max)):
                self._check_state(states[i], "options['state']" if n == 1 else f"options['state'][{i}]", W_max, w_max)
        if "target" in options:
            if self.task_record.needs_walls:
                raise ValueError(f"options['target']: the {self.task.kind} task's target is the centre of the marked "
                                 "arc, drawn each episode; it cannot be set")
            targets = self._rows(options["target"], n, 2, "options['target']")
            for i in np.flatnonzero(self._flag_targets(targets)):  # (as the states: flagged rows checked one by one)
                self._check_target(targets[i], "options['target']" if n == 1 else f"options['target'][{i}]")
        return states, targets

    def _check_state(self, s, name, W_max, w_max):
        """One row's checks, in order: finite and within MAX_ANGULAR_SPEED (as_state), both ends inside the table,
        |theta_dot| and |phi_dot| within the scene's step speed limits. ValueError naming ``name`` and the field."""
        as_state(s, name)
        check_inside(s[:, None], self.params, self.table, name)
        for j, field, bound in ((THETA_DOT, "theta_dot", W_max), (PHI_DOT, "phi_dot", w_max)):
            if abs(s[j]) > bound:  # the scene's init ranges obey the same bound (Scene)
                raise ValueError(f"{name}: |{field}| = {abs(s[j]):.6g} rad/s is beyond {bound:.6g} rad/s, from "
                                 "where a step at the torque limits could pass MAX_ANGULAR_SPEED "
                                 "(Scene.step_speed_limits; docs/physics.md#limits)")

    def _table_h(self, x, y):
        """table.h on arrays of any shape, or None where the table's h does not take them (a user's table written for
        one row): the caller then checks every row one by one."""
        try:
            with np.errstate(all="ignore"):
                g = np.asarray(self.table.h(x, y))
        except Exception:  # noqa: BLE001 (a user's h that takes no batch: the row-by-row checks name what it raises)
            return None
        return g if g.shape == np.shape(x) and g.dtype.kind == "f" else None

    def _flag_states(self, states, W_max, w_max):
        """(n,) bool: the rows of (n, 6) states that :meth:`_check_state` could refuse: non-finite, a speed beyond
        MAX_ANGULAR_SPEED or the step speed limits (exact comparisons), or an end within a margin of the wall's
        tolerance (check_inside: h > 1e-9 size), so that a last-bit difference between the batch and the one-row
        evaluation of h never lets a refused row through."""
        finite = np.isfinite(states).all(axis=1)
        flag = ~finite
        speeds = np.abs(np.where(finite[:, None], states[:, 4:6], 0.0))
        flag |= (speeds > MAX_ANGULAR_SPEED).any(axis=1) | (speeds[:, 0] > W_max) | (speeds[:, 1] > w_max)
        if self.table is None:
            return flag
        s = np.where(finite[:, None], states, 0.0).T
        lim = 0.999 * INSIDE_TOL * self.table.size
        for sigma in (1.0, -1.0):
            px, py, _, _ = end_kinematics(s, sigma, self.R)
            g = self._table_h(px, py)
            if g is None:
                return np.ones(len(states), bool)
            flag |= ~(g <= lim)  # (a NaN from h: flagged, the row's own check says what is wrong)
        return flag

    def _flag_targets(self, targets):
        """(n,) bool: the rows of (n, 2) finite targets that :meth:`_check_target` could refuse (no heading of the 64
        keeps both ends clearly inside the table, within a margin of 1e-9 size for last-bit differences)."""
        n = len(targets)
        if self.plane or n == 0:
            return np.zeros(n, bool)
        ph = np.linspace(0.0, np.pi, 64, endpoint=False)
        c, s = self.R * np.cos(ph), self.R * np.sin(ph)
        tx, ty = targets[:, :1], targets[:, 1:]
        front = self._table_h(tx + c, ty + s)
        back = self._table_h(tx - c, ty - s)
        if front is None or back is None:
            return np.ones(n, bool)
        margin = -1e-9 * self.table.size
        return ~((front < margin) & (back < margin)).any(axis=1)

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


def task_output_cause(core, obs, dist) -> tuple:
    """(key, words) of what the step's guard found wrong with the task's outputs (functional.conclude) in one env's
    observation row ``obs`` and distance to its target ``dist``: a target that is not finite, a target entry or one of
    the task's own entries outside the observation space (the first such entry, with its value and bounds), else the
    reward, the guard's one other test (the step reports such a reward as 0). key: the kind of cause and the entry."""
    record = core.task_record
    if not np.isfinite(dist):
        return ("target",), f"drew a target that is not finite (the distance to it is {float(dist)!r})"
    lo, hi = core.obs_bounds()
    row = np.asarray(obs, dtype=np.float32)
    for j in range(8, min(row.shape[-1], len(lo))):
        if not lo[j] <= row[j] <= hi[j]:  # (compared as the guard and observation_space compare: in float32)
            if j < 10:
                return ("entry", j), (f"drew a target off the table: the observation's target entry obs[{j}] = "
                                      f"{float(row[j]):.6g} (the target relative to the contact point, in table sizes) "
                                      f"is outside the observation space's [{lo[j]:g}, {hi[j]:g}]")
            return ("entry", j), (f"wrote obs[{j}] = {str(row[j])}, outside its declared bounds extra_obs[{j - 10}] = "
                                  f"{record.extra_obs[j - 10]} (as the float32 observation space holds them: "
                                  f"[{float(lo[j])!r}, {float(hi[j])!r}])")
    return ("reward",), "returned a reward that is not finite (reported as 0)"


def warn_limits(core, limits, task_outputs=None) -> None:
    """A RuntimeWarning per kind of guarded limit among ``limits`` (info["limit"] codes of episodes that ended): the
    event loop's guard (physics/faults.py: a law or a table breaking its contract) or the task's outputs
    (LIMIT_TASK_OUTPUT); info["limit"] names every one of them. task_outputs: (observation row, distance) of an env
    that LIMIT_TASK_OUTPUT ended, whose cause the warning names (:func:`task_output_cause`), once per env object and
    cause (a broken task in thousands of envs would otherwise print a line per episode)."""
    for code in sorted(set(int(v) for v in limits)):
        if code in FAULT_OF_LIMIT:
            warn_episode_fault(LIMIT_NAMES[code], FAULT_OF_LIMIT[code], core.law, core.table)
        elif code == LIMIT_TASK_OUTPUT:
            import warnings
            record = core.task_record
            if task_outputs is None:
                key, cause = None, ("returned a reward that is not finite, drew a target that is not or one off the "
                                    "table, or wrote an observation entry of its own outside its extra_obs bounds")
            else:
                key, cause = task_output_cause(core, *task_outputs)
            warned = core.__dict__.setdefault("_warned_task_outputs", set())
            if key is not None and key in warned:
                continue
            warned.add(key)
            warnings.warn(f"penny_env: an episode ended, truncated with info['limit'] = 'task_output': task "
                          f"{record.name!r} {cause}; fix the task's stages and register it again "
                          "(penny_env.register_task)", RuntimeWarning, stacklevel=4)
