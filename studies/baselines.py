"""Success rates of trivial policies (zero and uniformly random actions) on every registered id:
a task that these solve is not a control task.

    python -m studies.baselines [--episodes 64] [--quick] [--out docs/baselines.md]
"""
from __future__ import annotations

import numpy as np


def main(argv=None):
    from lab.common import report_command
    rep = report_command("studies.baselines", "baselines.md", __doc__, argv, quick="4 episodes on two ids (for tests)",
                         options=lambda ap: ap.add_argument("--episodes", type=int, default=64))
    import gymnasium as gym
    import penny_env  # noqa: F401
    from training.train import evaluate

    ids = sorted(k for k in gym.registry if k.startswith("Penny"))
    episodes = 4 if rep.quick else rep.args.episodes
    if rep.quick:
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
    return rep.write(rep.header("Trivial policies on every environment id")
                     + [f"{episodes} episodes per policy and id, seeds from 123.", "",
                        "| id | zero: success | zero: return | random: success | random: return |",
                        "|---|---|---|---|---|", *rows])


if __name__ == "__main__":
    main()
