"""Measure what the README's two commands cost on this machine (issue 21.8): each one runs as written,
step by step, in a fresh copy of the checkout with a fresh virtual environment; the report gives each
step's wall time, the virtual environment's size after each install and the machine's load average.

    python -m training.measure_readme [--parts main tests] [--out docs/readme_costs.md] [--quick] [--report-only]

Parts: "main" (the README's main job: install, the paper's figures, the PPO baseline) and "tests"
(install everything, the test suite). Each part's measurement is kept in runs/readme_costs/<part>.json
(under the working directory), so the parts can be measured at different times; the report is built
from every part measured so far, each with its own date and load (--report-only: only that). Installs take their wheels from
pip's cache or the machine's package index as configured: the report says how long that took here,
not how long a download would. --quick checks the pipeline: the main job only, in the current
environment (no venv, no installs), training cut to 4096 steps, the report into a temporary folder.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PARTS = {"main": "Install and run the main job", "tests": "Install and run the tests"}
QUICK_TRAIN = ["--set", "total_timesteps=4096", "--set", "eval_episodes=4", "--set", "curve_points=1",
               "--set", "curve_episodes=2"]


def readme_block(readme: str, part: str) -> str:
    """The bash block that follows the README's sentence for `part`."""
    m = re.search(re.escape(PARTS[part]) + r".*?```bash\n(.*?)```", readme, re.S)
    if m is None:
        raise ValueError(f"README.md: no bash block after {PARTS[part]!r}")
    return m.group(1).strip()


def steps_of(block: str) -> list[str]:
    return [s.strip() for s in block.split("&&") if s.strip()]


def copy_checkout(dest: Path) -> Path:
    """The checkout's files (tracked and untracked, not ignored) copied to dest: a fresh clone's view."""
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split("\0")
    for f in filter(None, files):
        if (ROOT / f).is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, dest / f)
    return dest


def folder_bytes(path: Path) -> int:
    total = 0
    for dirpath, _, names in os.walk(path):
        for n in names:
            p = os.path.join(dirpath, n)
            if not os.path.islink(p):
                total += os.path.getsize(p)
    return total


class LoadSampler:
    """The 1-minute load average, sampled every few seconds while a step runs (max and mean)."""

    def __init__(self, every: float = 5.0):
        self.every, self.samples = every, []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while True:
            self.samples.append(os.getloadavg()[0])
            if self._stop.wait(self.every):
                return

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()

    def summary(self):
        return {"max": max(self.samples), "mean": sum(self.samples) / len(self.samples)}


def run_part(part: str, readme: str, workdir: Path, quick: bool = False, log=print) -> dict:
    """Run the README block of `part` in workdir step by step; per step: wall seconds, exit code, load."""
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME")}
    if quick:  # the current environment and this checkout's code (its compiled cache), run in the copy
        env["PYTHONPATH"] = str(ROOT)
        env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    from penny_env.analysis.common import machine_lines
    machine, load_at_start = machine_lines(), os.getloadavg()
    rows = []
    for step in steps_of(readme_block(readme, part)):
        row = {"step": step}
        argv = shlex.split(step)
        if argv[0] in (".", "source"):  # activation: the later steps run with the venv's bin first on PATH
            venv = (workdir / argv[1]).parent.parent
            if not quick:
                env["VIRTUAL_ENV"] = str(venv)
                env["PATH"] = str(venv / "bin") + os.pathsep + env["PATH"]
            rows.append(dict(row, seconds=0.0, rc=0, note="activation"))
            continue
        if quick and (argv[:3] == ["python3", "-m", "venv"] or argv[0] == "pip"):
            rows.append(dict(row, skipped="--quick: the current environment"))
            continue
        cmd = step
        if quick and argv[:3] == ["python", "-m", "training.train"]:
            cmd = step + " " + " ".join(QUICK_TRAIN)
            row["run_as"] = cmd
        log(f"[measure_readme] {part}: {cmd}")
        t0 = time.perf_counter()
        with LoadSampler() as load:
            run = subprocess.run(["bash", "-c", cmd], cwd=workdir, env=env, capture_output=True, text=True)
        row.update(seconds=time.perf_counter() - t0, rc=run.returncode, load=load.summary(),
                   output_tail=(run.stdout + run.stderr)[-1500:])
        if argv[0] == "pip" and (workdir / ".venv").is_dir():
            row["venv_bytes"] = folder_bytes(workdir / ".venv")
        log(f"[measure_readme]   {row['seconds']:.0f} s, exit {run.returncode}, load max {row['load']['max']:.1f}")
        rows.append(row)
        if run.returncode != 0:
            break
    return {"part": part, "quick": quick, "machine": machine, "steps": rows, "load_at_start": load_at_start}


def _fmt_seconds(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s:.0f} s ({s / 60:.1f} min)"


def report(results: dict) -> list[str]:
    lines = ["# What the README's commands cost", "",
             "Written by `python -m training.measure_readme` (each command of the README run as written, in a fresh copy",
             "of the checkout with a fresh virtual environment). The machine is shared: the load average says how",
             "busy it was (2 cores: a load above 2 means other jobs competed for them); an idle machine is faster.",
             "Installs take their wheels from pip's cache and the machine's package index: no download time.",
             "Regenerate: `python -m training.measure_readme --out docs/readme_costs.md` (both parts), or one part",
             "with `--parts main` or `--parts tests` (the other part's last measurement is kept).", ""]
    for part in ("main", "tests"):
        if part not in results:
            continue
        r = results[part]
        lines += [f"## {PARTS[part]}", "", *r["machine"], f"- load average at the start (1, 5, 15 min): "
                  f"{', '.join(f'{x:.1f}' for x in r['load_at_start'])}", "",
                  "| step | wall time | exit | load average (mean / max) | virtual env size |",
                  "|---|---:|---:|---:|---:|"]
        total = 0.0
        for row in r["steps"]:
            if "skipped" in row:
                lines.append(f"| `{row['step']}` | skipped ({row['skipped']}) | | | |")
                continue
            total += row["seconds"]
            load = f"{row['load']['mean']:.1f} / {row['load']['max']:.1f}" if "load" in row else ""
            size = f"{row['venv_bytes'] / 2**30:.2f} GiB" if "venv_bytes" in row else ""
            lines.append(f"| `{row.get('run_as', row['step'])}` | {_fmt_seconds(row['seconds'])} | {row['rc']} | "
                         f"{load} | {size} |")
        ok = all(row.get("rc", 0) == 0 for row in r["steps"])
        lines += ["", f"Total: {_fmt_seconds(total)}{'' if ok else ' (a step FAILED: see its exit code)'}.", ""]
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", nargs="+", choices=list(PARTS), default=list(PARTS))
    ap.add_argument("--out", default=None, help="the report (default: runs/reports/readme_costs.md under the "
                                                "working directory; --quick: a new temporary directory)")
    ap.add_argument("--quick", action="store_true", help="the main job in the current environment, training cut short")
    ap.add_argument("--report-only", action="store_true", help="measure nothing: the report of the parts measured so far")
    args = ap.parse_args(argv)
    if args.quick and args.report_only:
        ap.error("--quick and --report-only exclude each other")
    from penny_env.analysis.common import report_path, write
    out = report_path(args.out, args.quick, "readme_costs.md")
    store = (out.parent / "readme_costs_parts") if args.quick else Path("runs") / "readme_costs"
    store.mkdir(parents=True, exist_ok=True)
    readme = (ROOT / "README.md").read_text()
    parts = [] if args.report_only else ["main"] if args.quick else args.parts
    for part in parts:
        with tempfile.TemporaryDirectory(prefix=f"penny_env-readme-{part}-") as tmp:
            res = run_part(part, readme, copy_checkout(Path(tmp)), quick=args.quick)
        (store / f"{part}.json").write_text(json.dumps(res, indent=2))
    results = {p: json.loads((store / f"{p}.json").read_text()) for p in PARTS if (store / f"{p}.json").is_file()}
    if not results:
        ap.error(f"no part measured yet in {store}: run without --report-only first")
    lines = report(results)
    write(str(out), lines)
    print("\n".join(lines))
    print(f"wrote {out}")
    return results


if __name__ == "__main__":
    main()
