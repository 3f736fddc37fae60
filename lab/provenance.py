"""Which committed reports are older than the code that makes them.

    python -m lab.provenance --check            # list stale reports, exit 1 if any
    python -m lab.provenance --stamp docs/X.md --reason "..."   # accept without a rerun

Rule: every report in docs/ records, in its header, a hash of its **sources**: its own command's
module and the modules whose code computes its numbers (the physics or env step it measures, the
presets it runs), listed explicitly in :data:`REPORTS` (small on purpose: the helpers of formatting
and plotting are left out). The hash is SHA-256 over each source file's repository path and bytes,
in the listed order, so any edit of a listed file makes the report stale. A report's command writes
the line itself (common.header calls :func:`stamp_line`); ``--check`` (and tests/studies/test_provenance.py)
compare it with the current sources and name the command that regenerates each stale report.

``--stamp REPORT --reason TEXT`` records the current hash in a report **without** rerunning it, with
the date and the reason in the line itself, for reports whose command takes hours (docs/study.md,
docs/optimal_control_central.md) after one has checked that the changes do not reach its numbers. The
reason stays visible in the report.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]  # the repository (or source tree) root

_PHYSICS = ("penny_env/physics/scalar.py", "penny_env/physics/flows.py", "penny_env/physics/kernels.py",
            "penny_env/physics/laws.py", "penny_env/physics/params.py", "penny_env/physics/simulation.py")
_TABLES = ("penny_env/physics/tables/base.py", "penny_env/physics/tables/ellipse.py",
           "penny_env/physics/tables/stadium.py", "penny_env/physics/tables/rounded_rectangle.py")
# the compile machinery of the compiled physics and batch loops (backends/)
_BATCH = ("penny_env/physics/batch_loops.py", "penny_env/backends/pennies.py", "penny_env/backends/builder.py",
          "penny_env/backends/physics.py", "penny_env/backends/batch.py")
_ENV = ("penny_env/backends/builder.py", "penny_env/backends/env.py", "penny_env/backends/packing.py",
        "penny_env/backends/runner.py",
        "penny_env/step/functional.py", "penny_env/step/draws.py", "penny_env/envs/core.py",
        "penny_env/step/tasks/base.py", "penny_env/step/tasks/reach.py", "penny_env/step/tasks/park.py",
        "penny_env/step/tasks/impacts.py", "penny_env/envs/scene.py", "penny_env/presets/envs.yaml",
        "penny_env/presets/scenes/ellipse.yaml", "penny_env/presets/scenes/circle.yaml",
        "penny_env/presets/scenes/stadium.yaml", "penny_env/presets/scenes/plane.yaml",
        "penny_env/presets/scenes/rounded_rectangle.yaml")

_CUDA = ("penny_env/backends/cuda_env.py", "penny_env/backends/cuda_math.py", "penny_env/envs/vector_env.py")

# report -> (the command that regenerates it, run from the repository root; its sources)
REPORTS = {
    "docs/bench_solvers.md": ("python -m studies.bench_solvers --out docs/bench_solvers.md",
                              ("studies/bench_solvers.py", "studies/integrators.py",
                               "studies/matching.py", "studies/reference.py") + _PHYSICS + _TABLES),
    "docs/work_precision.md": ("python -m studies.work_precision --out docs/work_precision.md",
                               ("studies/work_precision.py", "studies/integrators.py",
                                "studies/reference.py") + _PHYSICS + _TABLES),
    "docs/stability.md": ("python -m studies.stability --out docs/stability.md",
                          ("studies/stability.py", "penny_env/physics/validation.py") + _BATCH + _PHYSICS
                          + _TABLES),
    "docs/throughput.md": ("python -m devtools.throughput --out docs/throughput.md --readme README.md",
                           ("devtools/throughput.py", "penny_env/envs/penny_env.py",
                            "penny_env/envs/vector_env.py", "penny_env/backends/threads.py") + _ENV + _PHYSICS
                           + _TABLES),
    "docs/baselines.md": ("python -m studies.baselines --out docs/baselines.md",
                          ("studies/baselines.py",) + _ENV + _PHYSICS + _TABLES),
    "docs/paper_figures.md": ("python -m studies.paper_figures --out docs/paper_figures.md",
                              ("studies/paper_figures.py", "penny_env/batch.py") + _BATCH + _PHYSICS + _TABLES),
    "docs/dynamics.md": ("python -m studies.dynamics --out docs/dynamics.md",
                         ("studies/dynamics.py", "penny_env/analysis/dynamics.py", "penny_env/batch.py") + _BATCH
                         + _PHYSICS + _TABLES),
    "docs/controllability.md": ("python -m studies.controllability --out docs/controllability.md",
                                ("studies/controllability.py", "penny_env/analysis/dynamics.py",
                                 "penny_env/batch.py") + _BATCH + _PHYSICS + _TABLES),
    "docs/optimal_control.md": ("python -m studies.impact_oc --pairs 12 --workers 1",
                                ("studies/impact_oc.py", "studies/oc_bounds.py", "studies/drive_zonotope.py",
                                 "studies/both_bound.py", "studies/optimal_control.py",
                                 "studies/shooting.py",
                                 "studies/witness.py", "training/policies.py", "penny_env/physics/sensitivity.py",
                                 "penny_env/envs/vector_env.py", "penny_env/envs/penny_env.py") + _ENV + _PHYSICS
                                + _TABLES),
    "docs/optimal_control_central.md": ("python -m studies.optimal_control --workers 2",
                                        ("studies/optimal_control.py", "studies/shooting.py",
                                         "penny_env/physics/sensitivity.py")
                                        + _PHYSICS + _TABLES),
    "docs/billiards.md": ("python -m studies.billiards --out docs/billiards.md",
                          ("studies/billiards.py", "penny_env/analysis/boundary_map.py", "penny_env/batch.py",
                           "penny_env/physics/sensitivity.py") + _BATCH + _PHYSICS + _TABLES),
    "docs/billiards_answer.md": ("python -m studies.billiards_answer",
                                 ("studies/billiards_answer.py", "penny_env/analysis/periodic_orbits.py",
                                  "studies/point_billiard.py", "penny_env/analysis/boundary_map.py",
                                  "studies/billiards.py", "penny_env/batch.py",
                                  "penny_env/physics/sensitivity.py") + _BATCH + _PHYSICS + _TABLES),
    "docs/lyapunov_spread.md": ("python -m studies.lyapunov_spread --out docs/lyapunov_spread.md",
                                ("studies/lyapunov_spread.py", "studies/billiards_answer.py",
                                 "penny_env/analysis/boundary_map.py", "penny_env/batch.py",
                                 "penny_env/physics/sensitivity.py") + _BATCH + _PHYSICS + _TABLES),
    "docs/witnesses.md": ("python -m studies.witness_study --workers 2",
                          ("studies/witness.py", "studies/witness_study.py", "studies/verdict.py",
                           "training/policies.py", "penny_env/analysis/controllability_theorems.py",
                           "penny_env/analysis/flat_sides.py", "penny_env/analysis/one_input.py",
                           "penny_env/envs/vector_env.py", "penny_env/envs/penny_env.py") + _ENV + _PHYSICS + _TABLES),
    "docs/contention.md": ("python -m devtools.contention --out docs/contention.md",
                           ("devtools/contention.py", "penny_env/backends/threads.py",
                            "penny_env/envs/vector_env.py") + _BATCH + _ENV + _PHYSICS + _TABLES),
    "docs/compile_time.md": ("python -m devtools.compile_time --out docs/compile_time.md",
                             ("devtools/compile_time.py", "penny_env/backends/threads.py",
                              "penny_env/backends/cache.py") + _BATCH + _ENV + _PHYSICS + _TABLES),
    # on a CUDA GPU (docs/gpu.md): the commands need one, so a change of these sources is stamped until one is lent
    "docs/throughput_gpu.md": ("python -m devtools.throughput_gpu --variants --out docs/throughput_gpu.md",
                               ("devtools/throughput_gpu.py", "devtools/throughput.py") + _CUDA + _ENV + _PHYSICS
                               + _TABLES),
    "docs/ppo_torch_gpu.md": ("python -m studies.ppo_torch_report --config configs/train/ppo_torch_gpu.yaml --env-backend cuda "
                              "--device cuda --curve-points 5 --cuda-graph off --report docs/ppo_torch_gpu.md",
                              ("training/ppo_torch.py", "studies/ppo_torch_report.py", "configs/train/ppo_torch_gpu.yaml") + _CUDA
                              + _ENV + _PHYSICS
                              + _TABLES),
    "docs/ladder.md": ("python -m studies.ladder",
                       ("studies/ladder.py", "studies/cells.py", "configs/ladder/cpu.yaml", "studies/witness_demos.py",
                        "training/protocol.py", "training/agent_side.py", "training/guides.py",
                        "training/ppo_torch.py", "training/ppo_heading.py", "training/her_sac.py",
                        "penny_env/envs/vector_env.py")
                       + _ENV + _PHYSICS + _TABLES),
    "docs/ppo_speed.md": ("python -m devtools.ppo_speed --out docs/ppo_speed.md",
                          ("devtools/ppo_speed.py", "training/ppo_torch.py", "training/protocol.py",
                           "penny_env/sb3.py", "penny_env/envs/vector_env.py") + _ENV + _PHYSICS + _TABLES),
    # the comparison of two source trees: its numbers come from the trees it names, so only its own
    # module makes it stale
    "docs/throughput_compare.md": ("python -m devtools.throughput_compare --before OLD --after NEW "
                                   "--out docs/throughput_compare.md", ("devtools/throughput_compare.py",)),
    # the rare path's share: this tree's certificate beside another tree's (OLD); its numbers come from the step
    "docs/rare_share.md": ("python -m devtools.rare_share --train-policies runs/rare_share_policies --before OLD "
                           "--out docs/rare_share.md",
                           ("devtools/rare_share.py", "training/ppo_torch.py") + _ENV + _PHYSICS + _TABLES),
    "docs/throughput_compare_busy.md": ("python -m devtools.throughput_compare --busy --before OLD --after NEW "
                                        "--out docs/throughput_compare_busy.md",
                                        ("devtools/throughput_compare.py",)),
}
# reports whose command was removed, kept unchanged because another command still reads them: not checked
ARCHIVED = {"docs/study.md": "the removed RL study (studies.study, CHANGELOG.md): studies.witness_study reads its "
                             "docs/study.csv for the learnability column until it reads the ladder"}
# the command modules whose header writes the line (common.header's module argument -> report)
MODULE_REPORTS = {"studies.bench_solvers": "docs/bench_solvers.md",
                  "studies.work_precision": "docs/work_precision.md",
                  "studies.stability": "docs/stability.md",
                  "devtools.throughput": "docs/throughput.md",
                  "studies.baselines": "docs/baselines.md",
                  "studies.paper_figures": "docs/paper_figures.md",
                  "studies.dynamics": "docs/dynamics.md",
                  "studies.controllability": "docs/controllability.md",
                  "studies.optimal_control": "docs/optimal_control_central.md",
                  "studies.impact_oc": "docs/optimal_control.md",
                  "devtools.throughput_compare": "docs/throughput_compare.md",
                  "devtools.rare_share": "docs/rare_share.md",
                  "studies.billiards": "docs/billiards.md",
                  "studies.billiards_answer": "docs/billiards_answer.md",
                  "studies.lyapunov_spread": "docs/lyapunov_spread.md",
                  "studies.witness_study": "docs/witnesses.md",
                  "devtools.contention": "docs/contention.md",
                  "devtools.compile_time": "docs/compile_time.md",
                  "devtools.throughput_gpu": "docs/throughput_gpu.md",
                  "studies.ppo_torch_report": "docs/ppo_torch_gpu.md",
                  "studies.ladder": "docs/ladder.md",
                  "devtools.ppo_speed": "docs/ppo_speed.md"}

PREFIX = "- sources: sha256 "
_LINE = re.compile(r"^- sources: sha256 ([0-9a-f]{16})\b")


def sources_hash(report: str, root: Path = ROOT) -> str:
    """The first 16 hex digits of SHA-256 over the report's sources (path and bytes, in order)."""
    h = hashlib.sha256()
    for rel in REPORTS[report][1]:
        h.update(rel.encode() + b"\0")
        h.update((root / rel).read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:16]


def stamp_line(report: str, reason: str | None = None, root: Path = ROOT) -> str:
    """The header line of a report: its sources' hash, and where it was stamped without a rerun, why."""
    files = ", ".join(Path(p).name for p in REPORTS[report][1])
    line = f"{PREFIX}{sources_hash(report, root)} of {files} (python -m lab.provenance --check)"
    if reason:
        line += f"; stamped {_dt.date.today().isoformat()} without a rerun: {reason}"
    return line


def recorded_hash(path: Path) -> str | None:
    """The hash a report file records, or None."""
    if not path.exists():
        return None
    for line in path.read_text().splitlines()[:30]:
        m = _LINE.match(line)
        if m:
            return m.group(1)
    return None


def stale(root: Path = ROOT) -> list[tuple[str, str]]:
    """(report, why) of every report whose recorded hash is missing or not its sources' hash now."""
    out = []
    for report in REPORTS:
        got = recorded_hash(root / report)
        if got is None:
            out.append((report, "records no sources hash"))
        elif got != sources_hash(report, root):
            out.append((report, f"made from other sources (recorded {got}, now {sources_hash(report, root)})"))
    return out


def stamp(report: str, reason: str, root: Path = ROOT) -> None:
    """Write the current sources hash into a report without rerunning it (after the header's command line)."""
    if not reason or not reason.strip():
        raise ValueError("--reason is required: say why the report's numbers hold for the current sources")
    path = root / report
    lines = path.read_text().splitlines()
    new = stamp_line(report, reason.strip(), root)
    for i, line in enumerate(lines[:30]):
        if line.startswith(PREFIX):
            lines[i] = new
            break
    else:
        at = next((i for i, line in enumerate(lines[:30]) if line.startswith(("- command", "- commands"))), 1)
        lines.insert(at + 1, new)
    path.write_text("\n".join(lines).rstrip() + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="list the stale reports with their commands; exit 1 if any")
    ap.add_argument("--stamp", metavar="REPORT", choices=sorted(REPORTS), help="record the current hash without a rerun")
    ap.add_argument("--reason", help="with --stamp: why the report's numbers hold for the current sources")
    args = ap.parse_args(argv)
    if args.stamp:
        stamp(args.stamp, args.reason or "")
        print(f"{args.stamp}: stamped {sources_hash(args.stamp)}")
        return 0
    bad = stale()
    for report, why in bad:
        print(f"STALE {report}: {why}; regenerate: {REPORTS[report][0]}")
    if not bad:
        print(f"all {len(REPORTS)} reports match their sources")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
