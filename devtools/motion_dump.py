"""Dump the motion a source tree computes, through the public API only, so that two trees can be compared
bitwise after a change that must not alter the physics (a refactor, a new guard, a faster certificate).

    python -m devtools.motion_dump --out /tmp/after.npz            # from the tree to dump (its root)
    python -m devtools.motion_dump --compare /tmp/before.npz /tmp/after.npz

What it dumps (every array of every case, float64 compared bit for bit):

* env episodes: for each of :data:`ENV_IDS`, a PennyVectorEnv of 6 envs in NEXT_STEP and in SAME_STEP mode
  and a single env, 300 steps of seeded random actions (resets included): observations, rewards, flags and
  the info's arrays (impact counts, times and ends, kinetic energy, time, distance, limit);
* ``penny_env.simulate`` on :data:`SIMULATE_CASES` (tables, laws, controls, sensitivities): impact times,
  ends and states, final state and time, and the Jacobians where asked;
* ``penny_env.batch.simulate``, ``first_impact`` and ``impact_map`` on random batches per table and law.

Run it in a clean process per tree (``cd TREE && python -m devtools.motion_dump --out FILE``: the tree's own
penny_env is imported from its root).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

ENV_IDS = ("PennyReach-Ellipse-v0", "PennyPark-Circle-v0", "PennyPark-Stadium-v0", "PennyImpacts-Stadium-v0",
           "PennyReach-RoundedRectangle-v0", "PennyReach-Plane-v0", "PennyProbeSteer-Ellipse-E05-v0",
           "PennyProbeDrive-Stadium-Plastic-v0", "PennyProbeBoth-Ellipse-E05-v0", "PennyDrive-Circle-v0")
STEPS = 300
N_ENVS = 6
TABLES = {"ellipse": {"kind": "ellipse", "a": 0.15, "b": 0.2}, "circle": {"kind": "circle", "radius": 0.2},
          "stadium": {"kind": "stadium", "radius": 0.1, "length": 0.15},
          "rounded": {"kind": "rounded_rectangle", "width": 0.3, "height": 0.2, "radius": 0.04}}
LAWS = ("elastic", "plastic", 0.5)


def _simulate_cases():
    rng = np.random.default_rng(7)
    cases = []
    for tname in TABLES:
        for law in LAWS:
            for k in range(2):
                s = [0.3 * rng.uniform(-0.1, 0.1), 0.3 * rng.uniform(-0.1, 0.1), rng.uniform(-np.pi, np.pi),
                     rng.uniform(-np.pi, np.pi), rng.uniform(-20, 20), rng.uniform(-3, 3)]
                controls = rng.uniform(-1, 1, (30, 2)) * np.array([6.25e-7, 1.5e-5]) if k else None
                cases.append((f"{tname}-{law}-{k}", s, tname, law, controls, bool(k)))
    return cases


def dump_envs(out: dict) -> None:
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    import penny_env  # noqa: F401
    for env_id in ENV_IDS:
        for mode in ("NEXT_STEP", "SAME_STEP"):
            env = gym.make_vec(env_id, N_ENVS, vectorization_mode="vector_entry_point",
                               autoreset_mode=getattr(AutoresetMode, mode))
            rng = np.random.default_rng(1)
            obs, info = env.reset(seed=11)
            rows = {"obs": [obs]}
            for _ in range(STEPS):
                a = rng.uniform(-1.2, 1.2, env.action_space.shape)
                obs, r, te, tr, info = env.step(a)
                for key, v in (("obs", obs), ("reward", r), ("terminated", te), ("truncated", tr)):
                    rows.setdefault(key, []).append(np.asarray(v))
                for key in ("impacts", "impact_times", "impact_ends", "kinetic_energy", "time", "distance", "limit",
                            "arc_impacts"):
                    if key in info:
                        rows.setdefault("info_" + key, []).append(np.asarray(info[key]))
                if "final_obs" in info:
                    done = np.asarray(info["_final_obs"])
                    final = np.stack([np.asarray(info["final_obs"][i], dtype=np.float32) if done[i]
                                      else np.zeros(obs.shape[1], np.float32) for i in range(N_ENVS)])
                    rows.setdefault("final_obs", []).append(final)
                    rows.setdefault("final_mask", []).append(done)
            env.close()
            for key, v in rows.items():
                out[f"env/{env_id}/{mode}/{key}"] = np.stack(v)
        env = gym.make(env_id)
        rng = np.random.default_rng(2)
        obs, info = env.reset(seed=5)
        rows = {"obs": [obs]}
        for _ in range(STEPS):
            obs, r, te, tr, info = env.step(rng.uniform(-1.2, 1.2, env.action_space.shape))
            rows["obs"].append(obs)
            for key, v in (("reward", r), ("terminated", te), ("truncated", tr), ("impacts", info["impacts"]),
                           ("kinetic_energy", info["kinetic_energy"]), ("time", info["time"]),
                           ("limit", info["limit"])):
                rows.setdefault(key, []).append(np.asarray(v))
            if te or tr:
                obs, info = env.reset()
                rows["obs"].append(obs)
        env.close()
        for key, v in rows.items():
            out[f"single/{env_id}/{key}"] = np.stack(v)


def dump_simulate(out: dict) -> None:
    import penny_env as pe
    for name, s, tname, law, controls, sens in _simulate_cases():
        kw = dict(table=pe.physics.make_table(TABLES[tname]), law=law, sensitivities=sens)
        if controls is not None:
            tr = pe.simulate(s, controls=controls, control_dt=0.05, **kw)
        else:
            tr = pe.simulate(s, t_final=3.0, **kw)
        out[f"simulate/{name}/impact_times"] = np.asarray(tr.impact_times, float)
        out[f"simulate/{name}/impact_ends"] = np.asarray(tr.impact_ends, float)
        out[f"simulate/{name}/impact_states"] = np.asarray(tr.impact_states, float).reshape(-1)
        out[f"simulate/{name}/final_state"] = np.asarray(tr.final_state, float)
        out[f"simulate/{name}/final_time"] = np.asarray(tr.final_time, float)
        out[f"simulate/{name}/dense"] = np.asarray(tr.states_at(np.linspace(0, tr.final_time, 50)), float)
        if sens:
            out[f"simulate/{name}/jacobian"] = np.asarray(tr.jacobian, float)
            if getattr(tr, "control_jacobian", None) is not None:
                out[f"simulate/{name}/control_jacobian"] = np.asarray(tr.control_jacobian, float)


def dump_batch(out: dict) -> None:
    import penny_env.batch as pb
    rng = np.random.default_rng(3)
    for tname, spec in TABLES.items():
        n = 64
        S = np.column_stack([rng.uniform(-0.05, 0.05, n), rng.uniform(-0.05, 0.05, n), rng.uniform(-3, 3, n),
                             rng.uniform(-3, 3, n), rng.uniform(-30, 30, n), rng.uniform(-5, 5, n)])
        u = rng.uniform(-1, 1, (n, 2)) * np.array([6.25e-7, 1.5e-5])
        t, e = pb.first_impact(S, u, 2.0, table=spec)
        out[f"batch/{tname}/first_impact_t"] = np.asarray(t, float)
        out[f"batch/{tname}/first_impact_end"] = np.asarray(e, float)
        for law in LAWS:
            res = pb.simulate(S, table=spec, law=law, t_final=2.0)
            out[f"batch/{tname}/{law}/final_states"] = np.asarray(res.final_states, float)
            for field in ("impact_counts", "impact_times", "impact_ends", "impact_states", "impact_index"):
                v = getattr(res, field, None)
                if v is not None:
                    out[f"batch/{tname}/{law}/{field}"] = np.asarray(v, float).reshape(-1)


def compare(a_path: str, b_path: str) -> int:
    a, b = np.load(a_path), np.load(b_path)
    keys_a, keys_b = set(a.files), set(b.files)
    bad = 0
    for k in sorted(keys_a ^ keys_b):
        print(f"only in {'before' if k in keys_a else 'after'}: {k}")
        bad += 1
    for k in sorted(keys_a & keys_b):
        x, y = a[k], b[k]
        same = x.shape == y.shape and (x.tobytes() == y.tobytes()
                                       if x.dtype == y.dtype else np.array_equal(x, y, equal_nan=True))
        if not same:
            bad += 1
            print(f"DIFFERS: {k} {x.shape} {y.shape} {x.dtype} {y.dtype}")
    groups = {}
    for k in keys_a & keys_b:
        groups.setdefault(k.split("/")[0], 0)
        groups[k.split("/")[0]] += 1
    print(f"{len(keys_a & keys_b)} arrays compared ({', '.join(f'{g}: {n}' for g, n in sorted(groups.items()))}); "
          f"{bad} differ or are missing")
    return 1 if bad else 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", help="write the dump here (.npz)")
    ap.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), help="compare two dumps bitwise")
    ap.add_argument("--quick", action="store_true", help="two env ids, fewer steps (for the tests)")
    args = ap.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    if not args.out:
        ap.error("give --out FILE or --compare BEFORE AFTER")
    global ENV_IDS, STEPS
    if args.quick:
        ENV_IDS, STEPS = ENV_IDS[:2], 20
    out: dict = {}
    dump_envs(out)
    if not args.quick:
        dump_simulate(out)
        dump_batch(out)
    np.savez(args.out, **out)
    print(f"wrote {len(out)} arrays to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
