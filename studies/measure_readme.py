"""Measure what the README's two commands cost on this machine: each one runs as written,
step by step, in a fresh copy of the checkout with a fresh virtual environment; the report gives each
step's wall time, the virtual environment's size after each install, the machine's load average and,
for the test command, pytest's counts.

    python -m studies.measure_readme [--parts main tests] [--out docs/readme_costs.md] [--readme README.md]
                                      [--quick] [--report-only]

Parts: "main" (the README's main job: install, the paper's figures, the PPO baseline) and "tests"
(install everything, the test suite). The measurements are kept next to the report, in a JSON file of
the same name (docs/readme_costs.json beside docs/readme_costs.md), so the parts can be measured at
different times: measuring one keeps the other's last measurement, and the report always has both
sections, each with its own date and load (--report-only: measure nothing, rewrite the report and the
README from the JSON). --readme also rewrites the README's cost sentence of each part (between its
``<!-- readme-costs:PART -->`` markers) from the measurement; a part not measured for the README's
current command says so there. Installs take their wheels from pip's cache or the machine's package
indexes as configured: the report says how long that took here, not how long a download would, and
counts pip's connection retries (an index this machine cannot reach). --quick checks the pipeline: the
main job only, in the current environment (no venv, no installs), training cut to 4096 steps, the report
into a temporary folder; it refuses --readme.
"""
from __future__ import annotations

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
    """The checkout's files (tracked and untracked, not ignored) copied to dest, and committed there into a git
    repository of their own: a fresh clone's view (the suite's tests that need a git checkout, as CI's clean
    checkout has, run instead of skipping)."""
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split("\0")
    for f in filter(None, files):
        if (ROOT / f).is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, dest / f)
    who = ["-c", "user.name=measure_readme", "-c", "user.email=measure_readme@localhost", "-c", "commit.gpgsign=false"]
    for cmd in (["init", "-q"], ["add", "-A"], [*who, "commit", "-q", "-m", "the checkout, copied"]):
        subprocess.run(["git", *cmd], cwd=dest, capture_output=True, check=True)
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
    from lab.common import machine_lines
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
        output = run.stdout + run.stderr
        row.update(seconds=time.perf_counter() - t0, rc=run.returncode, load=load.summary(),
                   output_tail=output[-1500:])
        if argv[0] == "pip" and output.count(PIP_RETRY):
            row["pip_retries"] = output.count(PIP_RETRY)
        if argv[:3] == ["python", "-m", "pytest"]:
            row["pytest"] = pytest_counts(run.stdout)
        if argv[0] == "pip" and (workdir / ".venv").is_dir():
            row["venv_bytes"] = folder_bytes(workdir / ".venv")
        log(f"[measure_readme]   {row['seconds']:.0f} s, exit {run.returncode}, load max {row['load']['max']:.1f}")
        rows.append(row)
        if run.returncode != 0:
            break
    return {"part": part, "quick": quick, "machine": machine, "steps": rows, "load_at_start": load_at_start,
            "date": time.strftime("%Y-%m-%d", time.gmtime())}


PYTEST_COUNTS = re.compile(r"(\d+) (passed|failed|skipped|errors?|xfailed|xpassed|deselected)")
PIP_RETRY = "Retrying (Retry("


def pytest_counts(output: str) -> dict | None:
    """pytest's final counts ({"passed": 1199, "skipped": 9, ...}) from its summary line, or None."""
    for line in reversed(output.splitlines()):
        if re.search(r"\d+ (passed|failed|errors?)\b", line) and " in " in line:
            return {kind if kind != "error" else "errors": int(n) for n, kind in PYTEST_COUNTS.findall(line)}
    return None


def _fmt_seconds(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s:.0f} s ({s / 60:.1f} min)"


def report(results: dict) -> list[str]:
    lines = ["# What the README's commands cost", "",
             "Written by `python -m studies.measure_readme` (each command of the README run as written, in a fresh copy",
             "of the checkout with a fresh virtual environment). The machine is shared: the load average says how",
             "busy it was (2 cores: a load above 2 means other jobs competed for them); an idle machine is faster.",
             "Installs take their wheels from pip's cache and the machine's package index: no download time.",
             "pip retries: connections pip retried (an index this machine cannot reach) before it went on with",
             "the other sources; they are part of the step's time here.",
             "Regenerate: `python -m studies.measure_readme --out docs/readme_costs.md --readme README.md` (both",
             "parts), or one part with `--parts main` or `--parts tests` (the other part's last measurement, kept in",
             "readme_costs.json beside this file, stays).", ""]
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
            note = f" ({row['pip_retries']} pip retries)" if row.get("pip_retries") else ""
            lines.append(f"| `{row.get('run_as', row['step'])}` | {_fmt_seconds(row['seconds'])}{note} | {row['rc']} | "
                         f"{load} | {size} |")
        ok = all(row.get("rc", 0) == 0 for row in r["steps"])
        lines += ["", f"Total: {_fmt_seconds(total)}{'' if ok else ' (a step FAILED: see its exit code)'}."]
        counts = next((row["pytest"] for row in r["steps"] if row.get("pytest")), None)
        if counts:
            lines.append("Tests: " + ", ".join(f"{n} {kind}" for kind, n in counts.items()) + ".")
        lines.append("")
    return lines


README_MARKS = ("<!-- readme-costs:{part} -->", "<!-- /readme-costs:{part} -->")


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} minutes"


def _machine(result: dict) -> str:
    """'AMD EPYC (2 logical cores)' from the measurement's machine line."""
    line = next((ln for ln in result["machine"] if ln.startswith("- machine:")), "")
    return line.split("CPU: ", 1)[-1] if "CPU: " in line else line.removeprefix("- machine: ")


def readme_sentence(part: str, result: dict | None, readme: str) -> str:
    """The README's cost sentence of `part`, from its measurement; where none was made for the README's
    current command (or a step failed, or it was a --quick run), a sentence that says so and how to measure."""
    steps = steps_of(readme_block(readme, part))
    measured = (result is not None and not result.get("quick") and [r["step"] for r in result["steps"]] == steps
                and all(r.get("rc", 0) == 0 for r in result["steps"]))
    if not measured:
        return (f"Not yet measured for the command below: `python -m studies.measure_readme --parts {part} --out "
                f"docs/readme_costs.md --readme README.md` measures it ([docs/readme_costs.md](docs/readme_costs.md)).")
    timed = [r for r in result["steps"] if "seconds" in r]
    install = [r for r in timed if shlex.split(r["step"])[0] == "pip" or r["step"].startswith("python3 -m venv")]
    run = [r for r in timed if r["step"].startswith("python -m ")]
    size = max((r["venv_bytes"] for r in timed if "venv_bytes" in r), default=0) / 2**30
    loaded = [r for r in timed if "load" in r and r["seconds"] > 0]
    weight = sum(r["seconds"] for r in loaded) or 1.0
    mean = sum(r["load"]["mean"] * r["seconds"] for r in loaded) / weight
    peak = max((r["load"]["max"] for r in loaded), default=0.0)
    retries = sum(r.get("pip_retries", 0) for r in install)
    hosts = sorted({re.sub(r"^https?://([^/]+).*", r"\1", a) for r in install if r.get("pip_retries")
                    for a in shlex.split(r["step"]) if a.startswith("http")})
    retry = (f"; the measuring machine could not reach {', '.join(hosts) or 'an index'} and pip took local wheels "
             f"after {retries} connection retries" if retries else "")
    install_text = (f"{_duration(sum(r['seconds'] for r in install))} to install (a {size:.2f} GiB virtual "
                    f"environment{retry})")
    where = (f"measured by `python -m studies.measure_readme` ([docs/readme_costs.md](docs/readme_costs.md)) on "
             f"{_machine(result)}, {result.get('date', '?')}, load average {mean:.1f} on average (at most {peak:.1f}). "
             "On your machine: about this on 2 free cores, less with more; several times longer on a busy machine, "
             "where the first compile of each table shape takes minutes")
    if part == "tests":
        suite = next(r for r in run if r["step"].startswith("python -m pytest"))
        counts = ", ".join(f"{n} {k}" for k, n in (suite.get("pytest") or {}).items())
        return (f"Cost: {install_text}, and the suite {_duration(suite['seconds'])} ({counts}); {where}.")
    parts = "".join(f", then {_duration(r['seconds'])} for `{r['step'].split()[2]}`" if i == 0 else
                    f", {_duration(r['seconds'])} for `{r['step'].split()[2]}`" for i, r in enumerate(run))
    total = sum(r["seconds"] for r in timed)
    return f"Cost: {_duration(total)} in all: {install_text}{parts}; {where}."


def update_readme(path: Path, results: dict) -> None:
    """Rewrite each part's sentence between its markers; ValueError if a marker is missing."""
    import textwrap

    from lab.common import replace_text_block
    text = path.read_text()
    for part in PARTS:
        begin, end = (m.format(part=part) for m in README_MARKS)
        sentence = textwrap.fill(readme_sentence(part, results.get(part), text), width=110, break_long_words=False,
                                 break_on_hyphens=False)
        new = replace_text_block(text, begin, end, sentence)
        if new is None:
            raise ValueError(f"{path}: no {begin} ... {end} markers")
        text = new
    path.write_text(text)


def readme_marked(text: str, part: str) -> str | None:
    """The README's text between the markers of `part` (whitespace-normalised), or None."""
    begin, end = (m.format(part=part) for m in README_MARKS)
    if begin not in text or end not in text:
        return None
    return " ".join(text.split(begin, 1)[1].split(end, 1)[0].split())


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--parts", nargs="+", choices=list(PARTS), default=list(PARTS))
        ap.add_argument("--readme", default=None, help="also rewrite the cost sentences of this README (not with "
                        "--quick)")
        ap.add_argument("--report-only", action="store_true", help="measure nothing: the report of the parts "
                        "measured so far")
    rep = report_command("studies.measure_readme", "readme_costs.md", __doc__, argv, options=options,
                         quick="the main job in the current environment, training cut short",
                         out_help="the report, its measurements beside it (.json)")
    args, out = rep.args, rep.out
    if args.quick and args.report_only:
        rep.error("--quick and --report-only exclude each other")
    if args.quick and args.readme:
        rep.error("--readme refuses --quick: a quick run never writes the README")
    store = out.with_suffix(".json")
    results = json.loads(store.read_text()) if store.is_file() else {}
    readme = (ROOT / "README.md").read_text()
    parts = [] if args.report_only else ["main"] if args.quick else args.parts
    for part in parts:
        with tempfile.TemporaryDirectory(prefix=f"penny_env-readme-{part}-") as tmp:
            results[part] = run_part(part, readme, copy_checkout(Path(tmp)), quick=args.quick)
        store.parent.mkdir(parents=True, exist_ok=True)
        store.write_text(json.dumps(results, indent=2))  # after each part: a later failure keeps it
    if not results:
        rep.error(f"no part measured yet in {store}: run without --report-only first")
    rep.write(report(results), echo=True)
    if args.readme:
        update_readme(Path(args.readme), results)
        print(f"rewrote the cost sentences of {args.readme}")
    return results


if __name__ == "__main__":
    main()
