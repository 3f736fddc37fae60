"""Time the README's PPO snippet (the block that trains with Stable-Baselines3) as a user runs it, then
evaluate the trained policy against uniformly random actions on fresh seeds.

    python -m studies.time_readme_snippet [--readme README.md] [--episodes 200]

Prints the machine, the date, the wall time of the snippet and both success rates; the README quotes
these numbers. Needs the [train] extra (Stable-Baselines3, torch).
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parent.parent / "README.md"


def ppo_snippet(readme: Path = README) -> str:
    """The README's Python block that trains PPO."""
    blocks = re.findall(r"```python\n(.*?)```", readme.read_text(), re.S)
    found = [b for b in blocks if "PPO(" in b]
    if len(found) != 1:
        raise ValueError(f"{readme}: expected one Python block with PPO(, found {len(found)}")
    return found[0]


def main(argv=None):
    from lab.common import machine_lines
    from training.train import evaluate

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--readme", default=str(README))
    ap.add_argument("--episodes", type=int, default=200, help="evaluation episodes per policy")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    code = ppo_snippet(Path(args.readme))
    namespace: dict = {}
    t0 = time.perf_counter()
    exec(compile(code, args.readme, "exec"), namespace)
    seconds = time.perf_counter() - t0
    model = namespace["model"]
    env_id = "PennyReach-Ellipse-v0"
    shape = namespace["venv"].action_space.shape
    rng = np.random.default_rng(1)
    trained = evaluate(env_id, lambda o: model.predict(o, deterministic=True)[0], args.episodes, 10_000)
    random = evaluate(env_id, lambda o: rng.uniform(-1, 1, (len(o),) + shape).astype(np.float32), args.episodes, 10_000)
    lines = [*machine_lines(), f"- README PPO snippet: {seconds:.0f} s wall time ({model.num_timesteps} timesteps)",
             f"- success rate on {args.episodes} fresh episodes (seeds from 10000): trained "
             f"{trained['success_rate']:.0%}, uniformly random actions {random['success_rate']:.0%}"]
    print("\n".join(lines))
    return {"seconds": seconds, "trained": trained, "random": random}


if __name__ == "__main__":
    main()
