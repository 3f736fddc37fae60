"""Certified witnesses: non-learned controllers that solve the probe tasks, found by search with the
package's own simulator as the model, and certified by an episode of the package's own environment.

``python -m studies.witness ENV_ID [--pairs N] [--seed S] [--workers W] [field=value ...]``

For each of N start/target pairs (pair i: ``gymnasium.make(ENV_ID, **overrides)`` reset with seed S + i,
the probe's own start/target distribution) a small family of parametrised state-feedback controllers
(below) is simulated from the pair's exact start on a PennyVectorEnv, one row per candidate (the compiled
step, bitwise the single env's). The first candidate whose episode ends with success is then run as a
controller in the real episode (gymnasium.make of the id, reset with the pair's seed) and the pair counts
as witnessed only if that episode ends with ``info["is_success"]``. The command prints
"witnessed k/N pairs" and, per pair not witnessed, why: which success condition the searched episodes never
met (position: the target within the tolerance; speed: at rest there, |R theta_dot| under speed_tolerance and
|phi_dot| under spin_tolerance; time: within the episode's time limit) and, where a theorem of
docs/controllability_theory.md covers the pair (penny_env.analysis.controllability_theorems.pair_theorem, which
reads the cell's table, regions, time limit and speeds), "impossible (theorem Tk)" with the theorem's numbers.
A pair that a theorem excludes is still searched: a witness there would contradict the theorem, and stops the run.

Families (``FAMILIES``; the controllers read the exact state, which a witness may):

* steer (steering torque only, park): theta_dot changes only at impacts (theorem T2 of
  docs/controllability_theory.md), so the controller steers to a heading psi1 until the first impact; after
  an impact that left the rolling speed under the park tolerance it steers towards the target (backwards
  when rolling backwards) and lets the slow roll carry it there, the heading's PD law braking the spin;
  after an impact that left it faster it turns by delta2 from the heading at the impact and rolls on to
  the next impact. Searched: 48 headings psi1 x 12 turns delta2.
* drive (rolling torque only, reach): phi_dot changes only at impacts (T3), so the controller rolls along
  its heading (forwards or backwards, at speed v) into the wall; an oblique impact leaves phi_dot != 0, and
  with the heading turning it drives at v = k (target - contact point) . heading (at most vmax), which
  moves the contact point towards the target over each half turn. An impact that leaves |phi_dot| under
  w_min sends it rolling on to the next wall. Searched: 2 directions x 4 speeds x 2 gains x 2 vmax x 2 w_min.
* both (both torques, park): the study's feedback controller (training/policies.py FeedbackPolicy) at
  three top speeds.

Field overrides are applied like ``gymnasium.make`` keywords (values read as YAML: ``law=0.5``,
``law=plastic``, ``init='{theta_dot: [3, 4]}'``); ``table=NAME`` takes the table of the scene preset NAME
(penny_env/presets/scenes: plane, ellipse, stadium, circle, rounded_rectangle), i.e. ``scene=NAME``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass, field

import numpy as np

from penny_env.step.tasks.park import rest_speed

PROBE_PREFIX = "PennyProbe"
PROBES = ("Steer", "Drive", "Both")
V_SWITCH = 0.95  # steer: track the target after an impact that left |R theta_dot| under this x speed_tolerance
KP, KD = 25.0, 10.0  # heading PD law [1/s^2, 1/s] (critically damped at 5 rad/s, as FeedbackPolicy's)
KW = 40.0  # rolling-speed P law [1/s]
HOLD = 0.003  # [m] closer than this to the target, hold the heading (its direction is ill defined)


def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


# -- controllers: vectorised over candidate rows, with per-row memory ------------------------------------
class SteerPark:
    """Steering torque only, park (see the module docstring). params: (K, 2) rows (psi1, delta2) [rad]."""

    probe = "Steer"

    def __init__(self, core, params):
        self.R, self.gain1 = core.R, core.gain1
        self.v_switch = V_SWITCH * rest_speed(core.task)
        self.psi1, self.delta2 = np.asarray(params, float).T
        n = len(self.psi1)
        self.mode = np.zeros(n, np.int64)  # 0: to psi1; 1: to the heading at the last impact + delta2; 2: track
        self.psi = self.psi1.copy()

    @staticmethod
    def candidates():
        psi1 = np.linspace(-np.pi, np.pi, 48, endpoint=False)
        delta2 = np.linspace(-np.pi, np.pi, 12, endpoint=False)
        return np.array([(a, b) for a in psi1 for b in delta2])

    def __call__(self, S, targets, impacts):
        W, phi, w = S[:, 4], S[:, 3], S[:, 5]
        hit = impacts > 0
        slow = np.abs(self.R * W) < self.v_switch
        self.mode = np.where(hit, np.where(slow, 2, 1), self.mode)
        self.psi = np.where(hit & ~slow, phi + self.delta2, self.psi)
        rx, ry = targets[:, 0] - S[:, 0], targets[:, 1] - S[:, 1]
        toward = np.arctan2(ry, rx) + np.where(W < 0, np.pi, 0.0)
        near = np.hypot(rx, ry) < HOLD
        want = np.where(self.mode == 2, np.where(near, phi, toward), self.psi)
        u1 = KP * _wrap(want - phi) - KD * w
        return np.clip(u1 / self.gain1, -1.0, 1.0)[:, None]


class DriveReach:
    """Rolling torque only, reach (see the module docstring). params: (K, 5) rows (sign, v, k, vmax, w_min)."""

    probe = "Drive"

    def __init__(self, core, params):
        self.R, self.gain2 = core.R, core.gain2
        self.sign, self.v, self.k, self.vmax, self.w_min = np.asarray(params, float).T
        self.mode = np.zeros(len(self.sign), np.int64)  # 0: roll on at v (sign) into the wall; 1: track

    @staticmethod
    def candidates():
        return np.array([(s, v, k, vm, wm) for s in (1.0, -1.0) for v in (0.05, 0.1, 0.2, 0.3)
                         for k in (1.0, 3.0) for vm in (0.1, 0.25) for wm in (0.0, 0.5)])

    def __call__(self, S, targets, impacts):
        W, phi, w = S[:, 4], S[:, 3], S[:, 5]
        hit = impacts > 0
        turning = np.abs(w) > np.maximum(self.w_min, 1e-6)
        self.mode = np.where(hit, np.where(turning, 1, 0), self.mode)
        self.sign = np.where(hit & ~turning & (W != 0), np.sign(W), self.sign)  # roll on, away from the wall
        proj = (targets[:, 0] - S[:, 0]) * np.cos(phi) + (targets[:, 1] - S[:, 1]) * np.sin(phi)
        v = np.where(self.mode == 1, np.clip(self.k * proj, -self.vmax, self.vmax), self.sign * self.v)
        return np.clip(KW * (v / self.R - W) / self.gain2, -1.0, 1.0)[:, None]


class BothPark:
    """Both torques, park: FeedbackPolicy (training/policies.py) per row. params: (K, 1) rows (v_max,)."""

    probe = "Both"

    def __init__(self, core, params):
        from training.policies import FeedbackPolicy
        self.policies = [FeedbackPolicy(core, v_max=float(p[0])) for p in np.asarray(params, float)]

    @staticmethod
    def candidates():
        return np.array([[0.05], [0.03], [0.1]])

    def __call__(self, S, targets, impacts, obs=None):
        return np.concatenate([pol(obs[i:i + 1]) for i, pol in enumerate(self.policies)]).astype(np.float64)


FAMILIES = {"Steer": SteerPark, "Drive": DriveReach, "Both": BothPark}


def _act(ctrl, S, targets, impacts, obs):
    if isinstance(ctrl, BothPark):
        return ctrl(S, targets, impacts, obs)
    return ctrl(S, targets, impacts)


# -- ids and overrides --------------------------------------------------------------------------------
def probe_of(env_id: str) -> str:
    """'Steer', 'Drive' or 'Both' from a registered probe id; ValueError naming the id otherwise."""
    import gymnasium as gym
    import penny_env  # noqa: F401 (registers the ids)

    if not isinstance(env_id, str):
        raise TypeError(f"ENV_ID must be a string, got {type(env_id).__name__}")
    probe = env_id[len(PROBE_PREFIX):].split("-", 1)[0] if env_id.startswith(PROBE_PREFIX) else None
    if probe not in PROBES or env_id not in gym.registry:
        known = [i for i in gym.registry if i.startswith(PROBE_PREFIX)]
        raise ValueError(f"ENV_ID {env_id!r} is not a registered probe id (PennyProbe{{Steer,Drive,Both}}-*-v0); "
                         f"probe ids: {known}")
    return probe


def parse_overrides(items) -> dict:
    """{field: value} from 'field=value' strings (values read as YAML); table=NAME means scene=NAME."""
    import yaml
    from penny_env.envs.scene import CONFIG_DIR
    from penny_env.envs.yaml_io import safe_load as yaml_load  # (1e-2 read as a float, as in YAML 1.2)

    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"override {item!r} must be field=value")
        key, raw = item.split("=", 1)
        try:
            value = yaml_load(raw)
        except yaml.YAMLError as exc:
            raise ValueError(f"override {key}: cannot read {raw!r}: {exc}") from None
        if key == "table" and isinstance(value, str):
            names = sorted(p.stem for p in (CONFIG_DIR / "scenes").glob("*.yaml"))
            if value not in names:
                raise ValueError(f"table={value!r} is not a table preset; tables: {names}")
            key = "scene"
        out[key] = value
    return out


def make_env(env_id: str, overrides: dict):
    """The real episode's env: gymnasium.make(env_id, **overrides) (with its TimeLimit); errors name the field."""
    import gymnasium as gym

    probe_of(env_id)
    return gym.make(env_id, **overrides)


# -- one cell -----------------------------------------------------------------------------------------
@dataclass
class PairResult:
    seed: int
    witnessed: bool
    reason: str = ""
    steps: int = 0
    impacts: int = 0
    params: tuple = ()
    actions: list = field(default_factory=list, repr=False)
    theorem: str = ""  # the id of the theorem that makes the pair impossible ("T2.5"), or ""


def theorem_line(thm) -> str:
    """'impossible (theorem T2.5) on speed and time: <the theorem's numbers>' (the conditions it rules out)."""
    return f"{thm.label} on {' and '.join(thm.conditions) or 'every condition'}: {thm.reason}"


class TheoremContradiction(RuntimeError):
    """A witness episode succeeded on a pair that a theorem declares impossible: the simulator, the witness or
    the theorem's premises are wrong. Never caught by the study: it stops the run."""


class Witness:
    """The witness search of one cell (a probe id and field overrides); :meth:`pair` certifies one pair."""

    def __init__(self, env_id: str, overrides: dict | None = None):
        import gymnasium as gym

        self.env_id, self.overrides = env_id, dict(overrides or {})
        self.probe = probe_of(env_id)
        self.env = make_env(env_id, self.overrides)
        self.core = self.env.unwrapped._core
        self.family = FAMILIES[self.probe]
        self.cands = self.family.candidates()
        self.max_steps = self.env.spec.max_episode_steps
        # the time limit once: an override max_episode_steps= is the real episode's (gym.make took it above), and
        # passing it beside **overrides gave make_vec the keyword twice
        vec_kwargs = {**self.overrides, "max_episode_steps": self.max_steps}
        self.vec = gym.make_vec(env_id, num_envs=len(self.cands), vectorization_mode="vector_entry_point",
                                **vec_kwargs)
        self.plane = self.core.plane
        # the theorems read the time limit from the task: under gymnasium's TimeLimit the env's own task keeps the
        # preset's max_episode_steps, so the episode's limit (an override's) is put into the task they read
        self.scene = self.core.scene
        self.task = dataclasses.replace(self.core.task, max_episode_steps=self.max_steps)

    def close(self):
        self.env.close()
        self.vec.close()

    def search(self, state, target):
        """(index of the first candidate that succeeded or None, diagnostics) from the pair's start. The
        diagnostics say how close the candidates came to each success condition: best_d, the closest approach;
        slowest_within, the lowest |R theta_dot| at a step end within the tolerance (park); calmest, the lowest
        |phi_dot| at a step end within the tolerance and under speed_tolerance (park with spin_tolerance)."""
        vec = self.vec.unwrapped if hasattr(self.vec, "unwrapped") else self.vec
        K = len(self.cands)
        obs, _ = vec.reset(options={"state": np.tile(state, (K, 1)), "target": np.tile(target, (K, 1))})
        ctrl = self.family(self.core, self.cands)
        impacts = np.zeros(K, np.int64)
        tol, vtol = self.task.tolerance, rest_speed(self.task)
        diag = {"best_d": np.inf, "any_hit": False, "max_w_after_hit": 0.0, "slowest_within": np.inf,
                "calmest": np.inf, "steps": 0}
        hits = np.zeros(K, np.int64)
        live = np.ones(K, bool)  # rows whose episode has not ended (an ended row is reset by the vector env)
        for step in range(self.max_steps):
            S = vec.states
            acts = _act(ctrl, S, vec.targets, impacts, obs)
            obs, _, term, trunc, info = vec.step(acts)
            impacts = np.asarray(info["impacts"])
            hits += impacts
            S = vec.states
            d = np.where(live, np.asarray(info["distance"], float), np.inf)
            diag["best_d"] = min(diag["best_d"], float(np.min(d)))
            within = d < tol
            if within.any():
                v = np.abs(self.core.R * S[within, 4])
                diag["slowest_within"] = min(diag["slowest_within"], float(v.min()))
                if (v < vtol).any():
                    diag["calmest"] = min(diag["calmest"], float(np.abs(S[within, 5][v < vtol]).min()))
            if hits.any():
                diag["max_w_after_hit"] = max(diag["max_w_after_hit"], float(np.max(np.abs(S[hits > 0, 5]))))
            diag["steps"] = step + 1
            term = np.asarray(term, bool) & live  # (a row truncated early is reset on its next step: not this pair)
            if term.any():
                return int(np.flatnonzero(term)[0]), {}
            live &= ~np.asarray(trunc, bool)
            if not live.any():
                break
        diag["any_hit"] = bool(hits.any())
        return None, diag

    def theorem(self, state, target):
        """The theorem that makes this pair impossible (a TheoremVerdict), or None."""
        from penny_env.analysis.controllability_theorems import pair_theorem
        return pair_theorem(self.scene, self.task, state, target)

    def why(self, diag, theorem=None) -> str:
        """Why no candidate succeeded: the success conditions never met by the searched episodes (position, speed,
        time) and, where a theorem covers the pair, the theorem with its numbers."""
        tol, vtol = self.task.tolerance, rest_speed(self.task)
        T = self.max_steps * self.scene.control_dt
        parts = []
        if self.probe == "Drive" and diag.get("any_hit") and diag.get("max_w_after_hit", 1.0) < 1e-9:
            parts.append("start on an invariant line (T3.4): every impact was straight-on, phi_dot stayed 0")
        best = diag.get("best_d", np.inf)
        if best >= tol:
            parts.append(f"position never met: closest approach {best:.3f} m >= tolerance {tol:g} m")
        elif self.task.kind == "park" and diag.get("slowest_within", np.inf) >= vtol:
            parts.append(f"position met (closest approach {best:.4f} m < tolerance {tol:g} m) but speed never: within "
                         f"the tolerance |R theta_dot| >= {diag['slowest_within']:.4f} m/s >= speed_tolerance {vtol:g} m/s")
        elif getattr(self.task, "spin_tolerance", None) is not None:
            parts.append(f"position and rolling speed met but spin never: within the tolerance and under speed_tolerance "
                         f"|phi_dot| >= {diag.get('calmest', np.inf):.3g} rad/s >= spin_tolerance "
                         f"{self.task.spin_tolerance:g} rad/s")
        head = (f"no strategy in the family succeeded ({len(self.cands)} candidates run for {diag.get('steps', 0)} "
                f"steps = {diag.get('steps', 0) * self.scene.control_dt:g} s, the time limit {T:g} s)")
        line = head + ": " + "; ".join(parts) if parts else head
        if theorem is not None:
            line = f"{theorem_line(theorem)}. Search: {line}"
        return line

    def pair(self, seed: int) -> PairResult:
        """Search the pair of this seed, then certify the chosen controller in the real env episode."""
        env = self.env
        env.reset(seed=seed)
        state, target = env.unwrapped.state.copy(), env.unwrapped.target.copy()
        thm = self.theorem(state, target)
        tid = thm.id if thm is not None else ""
        idx, diag = self.search(state, target)
        if idx is None:
            return PairResult(seed, False, self.why(diag, thm), theorem=tid)
        params = self.cands[idx:idx + 1]
        ok, steps, n_imp, actions = run_episode(env, self.family(self.core, params), seed)
        if not ok:
            why = f"the searched candidate {tuple(params[0].tolist())} failed in the real episode"
            return PairResult(seed, False, why if thm is None else f"{theorem_line(thm)}. Search: {why}", steps, n_imp,
                              tuple(params[0].tolist()), theorem=tid)
        if thm is not None:
            raise TheoremContradiction(f"{self.env_id} {self.overrides} seed {seed}: a witness episode succeeded on a "
                                       f"pair that {thm.label} excludes ({thm.reason}); the simulator, the witness "
                                       "or the theorem's premises are wrong")
        return PairResult(seed, True, "", steps, n_imp, tuple(params[0].tolist()), actions)


def run_episode(env, ctrl, seed):
    """Run controller ctrl (one row) in env from reset(seed); (is_success, steps, impacts, actions)."""
    obs, _ = env.reset(seed=seed)
    u = env.unwrapped
    impacts = np.zeros(1, np.int64)
    n_imp, actions = 0, []
    for step in range(1, 10 ** 6):
        # float64, as the search's vector env got them (a float32 cast changes the torques' last bits, and on a
        # chaotic table the episode)
        a = _act(ctrl, u.state[None, :], u.target[None, :], impacts, obs[None, :])[0]
        actions.append(a)
        obs, _, term, trunc, info = env.step(a)
        impacts = np.array([info["impacts"]], np.int64)
        n_imp += info["impacts"]
        if term or trunc:
            return bool(info["is_success"]), step, n_imp, actions
    raise AssertionError("unreachable: the TimeLimit ends every episode")


def witness_cell(env_id, overrides, seeds, workers=1):
    """[PairResult] of the given pair seeds (in order), run in `workers` processes."""
    if workers <= 1 or len(seeds) <= 1:
        w = Witness(env_id, overrides)
        try:
            return [w.pair(s) for s in seeds]
        finally:
            w.close()
    from concurrent.futures import ProcessPoolExecutor
    chunks = [seeds[i::workers] for i in range(workers)]
    with ProcessPoolExecutor(workers) as ex:
        parts = list(ex.map(_cell_chunk, [(env_id, overrides, c) for c in chunks]))
    by_seed = {r.seed: r for part in parts for r in part}
    return [by_seed[s] for s in seeds]


def _cell_chunk(args):
    env_id, overrides, seeds = args
    res = witness_cell(env_id, overrides, seeds, 1)
    for r in res:
        r.actions = []  # (not sent back between processes)
    return res


def positive_int(name, least=1):
    """argparse type: an integer >= least (1: positive), the error naming the option."""
    kind = "a positive integer" if least == 1 else f"an integer >= {least}"

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be {kind}, got {text!r}") from None
        if v < least:
            raise argparse.ArgumentTypeError(f"{name} must be {kind}, got {v}")
        return v
    return parse


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.witness", description=__doc__.split("\n\n")[0])
    ap.add_argument("env_id", metavar="ENV_ID", help="a probe id, PennyProbe{Steer,Drive,Both}-*-v0")
    ap.add_argument("overrides", nargs="*", metavar="field=value", help="field overrides (table=circle, law=plastic)")
    ap.add_argument("--pairs", type=positive_int("--pairs"), default=20, help="start/target pairs (seeds S .. S+N-1)")
    ap.add_argument("--seed", type=positive_int("--seed", 0), default=0, help="first pair's seed")
    ap.add_argument("--workers", type=positive_int("--workers"), default=1, help="processes")
    args = ap.parse_intermixed_args(argv)
    try:
        probe_of(args.env_id)
        overrides = parse_overrides(args.overrides)
        make_env(args.env_id, overrides).close()  # a bad field or value fails here, naming it
    except (TypeError, ValueError) as exc:
        ap.error(str(exc))
    seeds = list(range(args.seed, args.seed + args.pairs))
    results = witness_cell(args.env_id, overrides, seeds, args.workers)
    k = sum(r.witnessed for r in results)
    excluded = [r.theorem for r in results if r.theorem]
    where = " ".join(f"{k}={v}" for k, v in overrides.items())
    from penny_env.analysis.controllability_theorems import theorem_for
    cell = theorem_for(args.env_id, **overrides)
    print(f"{args.env_id}{' ' + where if where else ''}: witnessed {k}/{len(results)} pairs"
          + (f"; {len(excluded)}/{len(results)} impossible (theorem {', '.join(sorted(set(excluded)))})" if excluded else ""))
    if cell is not None:
        print(f"the whole cell: {theorem_line(cell)}")
    for r in results:
        if not r.witnessed:
            print(f"  seed {r.seed}: {r.reason}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
