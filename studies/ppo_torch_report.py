"""A report of one training.ppo_torch run: the machine and device, throughput, the final evaluation and the curve.

    python -m studies.ppo_torch_report [--quick] [--report docs/ppo_torch_gpu.md] [training.ppo_torch's arguments]

e.g. ``python -m studies.ppo_torch_report --config configs/train/ppo_torch_gpu.yaml --env-backend cuda --device cuda
--cuda-graph off --report docs/ppo_torch_gpu.md``; ``--out`` is training.ppo_torch's run folder.
"""
from __future__ import annotations

from pathlib import Path

from training import ppo_torch

ROOT = Path(__file__).resolve().parents[1]


def write_report(rep, results: dict) -> None:
    """A markdown report of one run: the machine and device, throughput, the final evaluation and the curve."""
    from lab.common import table
    device = results["device"]
    if device.startswith("cuda"):
        import torch
        device = f"{device} ({torch.cuda.get_device_name(0)})"
    ev = results.get("eval") or {}
    lines = rep.header(f"training.ppo_torch on {results['env_id']}")
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
    rep.write(lines)


def main(argv=None):
    from lab.common import report_command

    rep = report_command("studies.ppo_torch_report", "ppo_torch_gpu.md", __doc__, argv, out_flag="--report",
                         rest=True, quick="a few thousand steps (checks the pipeline)",
                         out_help="the markdown report: throughput, evaluation and the success curve, with the device")
    args = ppo_torch.parse_args(rep.rest + (["--quick"] if rep.quick else []))  # (training.ppo_torch's arguments)
    agent, results = ppo_torch.train_agent(args)
    write_report(rep, results)
    return agent, results


if __name__ == "__main__":
    main()
