"""Success rates of trivial policies (zero and uniformly random actions) on every registered id:
a task that these solve is not a control task.

    python -m studies.baselines [--episodes 64] [--quick] [--out docs/baselines.md]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=64)
    ap.add_argument("--quick", action="store_true", help="4 episodes on two ids (for tests)")
    ap.add_argument("--out", default=None,
                    help="Markdown report (default: runs/reports/baselines.md under the working directory; "
                    "--quick: a new temporary directory)")
    args = ap.parse_args(argv)
    import gymnasium as gym
    import penny_env  # noqa: F401
    from lab.common import header, report_path
    from training.train import evaluate

    ids = sorted(k for k in gym.registry if k.startswith("Penny"))
    episodes = 4 if args.quick else args.episodes
    if args.quick:
        ids = ids[:2]
    rows = []
    for eid in ids:
        env = gym.make(eid)
        shape = env.action_space.shape
        env.close()
        rng = np.random.default_rng(0)
        zero = evaluate(eid, lambda o: np.zeros((len(o),) + shape, np.float32), episodes, 123)
        rand = evaluate(eid, lambda o: rng.uniform(-1, 1, (len(o),) + shape).astype(np.float32), episodes, 123)
        rows.append(f"| {eid} | {zero['success_rate']:.2f} | {zero['mean_return']:.2f} | "
                    f"{rand['success_rate']:.2f} | {rand['mean_return']:.2f} |")
        print(rows[-1], flush=True)
    lines = header("Trivial policies on every environment id", "studies.baselines", argv or sys.argv[1:])
    lines += [f"{episodes} episodes per policy and id, seeds from 123.", "",
              "| id | zero: success | zero: return | random: success | random: return |",
              "|---|---|---|---|---|", *rows, ""]
    out = report_path(args.out, args.quick, "baselines.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines))
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
