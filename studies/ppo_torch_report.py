"""A report of one training.ppo_torch run: the machine and device, throughput, the final evaluation and the curve.

    python -m studies.ppo_torch_report --report docs/ppo_torch_gpu.md [training.ppo_torch's arguments]

e.g. ``python -m studies.ppo_torch_report --config configs/train/ppo_torch_gpu.yaml --env-backend cuda --device cuda
--cuda-graph off --report docs/ppo_torch_gpu.md``. ``--quick`` never writes into docs/.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from training import ppo_torch

ROOT = Path(__file__).resolve().parents[1]


def write_report(path, argv, results: dict) -> None:
    """A markdown report of one run: the machine and device, throughput, the final evaluation and the curve."""
    from lab.common import header, table, write
    device = results["device"]
    if device.startswith("cuda"):
        import torch
        device = f"{device} ({torch.cuda.get_device_name(0)})"
    ev = results.get("eval") or {}
    lines = header(f"training.ppo_torch on {results['env_id']}", "studies.ppo_torch_report", argv)
    lines += [f"- device: {device}; env state on the device: {results['env_on_device']}; rollouts replayed from a "
              f"CUDA graph: {results['cuda_graph']}", "",
              *table(["env steps", "training s", "env-steps/s (end to end)", "rollout s", "update s",
                      "training success (last 100 episodes)", "evaluation success", "evaluation episodes",
                      "evaluation mean return"],
                     [[f"{results['timesteps']:,}", f"{results['train_seconds']:.1f}", f"{results['steps_per_s']:,.0f}",
                       f"{results['rollout_seconds']:.1f}", f"{results['update_seconds']:.1f}",
                       f"{results['train_success_rate']:.2f}", f"{ev.get('success_rate', float('nan')):.3f}",
                       f"{ev.get('episodes', 0)}", f"{ev.get('mean_return', float('nan')):.2f}"]])]
    if results["curve"]:
        lines += ["", "Deterministic evaluations during training (not counted in the training time):", "",
                  *table(["env steps", "training s", "success", "mean return"],
                         [[f"{c['global_step']:,}", f"{c['wall_time_s']:.1f}", f"{c['success_rate']:.3f}",
                           f"{c['mean_return']:.2f}"] for c in results["curve"]])]
    write(str(path), lines)



def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--report", required=True, help="the markdown report (e.g. docs/ppo_torch_gpu.md: throughput, "
                    "evaluation and the success curve, with the device's name)")
    args = ppo_torch.parse_args(argv, ap)
    if args.quick and Path(ap.last.report).resolve().is_relative_to(ROOT / "docs"):
        ap.error("--quick never writes into docs/: give --report a path outside it")
    agent, results = ppo_torch.train_agent(args)
    write_report(ap.last.report, argv, results)
    return agent, results


if __name__ == "__main__":
    main()
