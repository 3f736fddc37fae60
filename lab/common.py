"""Shared helpers of the report commands: :func:`report_command` (what every report command repeats: its
arguments, the refusal of --quick into docs/, the header, the writes), machine description, timing, progress
bars, Markdown."""
from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _version(module: str) -> str:
    try:
        from importlib.metadata import version
        return version(module)
    except Exception:  # not installed
        return "not installed"


def load_line() -> str:
    """The machine's load averages when the report's header is made (most commands make it at the
    end of their run, so the 5-minute average covers the run): timings taken beside other work are
    slower."""
    try:
        one, five, _ = os.getloadavg()
    except OSError:  # (not available on this platform)
        return "- load when this header was written: unknown"
    return (f"- load when this header was written: {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} "
            "logical cores; timings taken under load are slower than on a quiet machine")


def machine_lines() -> list[str]:
    return [
        f"- machine: {platform.platform()}, CPU: {cpu_model()} ({os.cpu_count()} logical cores)",
        f"- Python {platform.python_version()}, numpy {np.__version__}, scipy {_version('scipy')}",
        f"- date: {_dt.datetime.now().astimezone().strftime('%Y-%m-%d %H:%M %Z')}",
        load_line(),
    ]


def command_line(module: str, argv: list[str]) -> str:
    return "python -m " + module + ("" if not argv else " " + " ".join(shlex.quote(a) for a in argv))


def header(title: str, module: str, argv: list[str]) -> list[str]:
    """A report's first lines: title, machine, command and (for the committed reports) the hash of
    the sources that make its numbers (analysis/provenance.py)."""
    from lab.provenance import MODULE_REPORTS, stamp_line

    sources = [stamp_line(MODULE_REPORTS[module])] if module in MODULE_REPORTS else []
    return [f"# {title}", "", *machine_lines(), f"- command: `{command_line(module, argv)}`",
            "- regenerate: run the command above from the repository root", *sources, ""]


def best_time(fn, repeats: int = 3, min_total: float = 0.0, warmup: bool = True):
    """(best wall time of fn() over repeats, last result); repeats continue until min_total s were spent.
    warmup: one unmeasured call first (imports, caches)."""
    if warmup:
        fn()
    best = math.inf
    result = None
    total = 0.0
    k = 0
    while k < repeats or total < min_total:
        t0 = time.perf_counter()
        result = fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        total += dt
        k += 1
        if k >= 50:
            break
    return best, result


def progress(iterable, desc: str = "", total=None, disable=None):
    """tqdm progress bar on a TTY (stderr), plain iteration otherwise."""
    if disable is None:
        disable = not sys.stderr.isatty()
    try:
        from tqdm import tqdm
    except ImportError:  # tqdm is in the [train] and [bench] extras: without it, no bar
        return iterable
    return tqdm(iterable, desc=desc, total=total, disable=disable, leave=False)


def fmt(x, digits: int = 2) -> str:
    """Compact number for tables: 1.2e-09, 0.35, nan -> '-'."""
    if x is None:
        return "-"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    if math.isnan(x):
        return "-"
    if math.isinf(x):
        return "inf"
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e4:
        return f"{x:.{digits + 1}g}"
    return f"{x:.{digits}e}".replace("e-0", "e-").replace("e+0", "e+")


def table(headers: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    for r in rows:
        out.append("| " + " | ".join(str(c) for c in r) + " |")
    return out


def refuse_quick_into_docs(out, quick: bool) -> None:
    """A --quick run's numbers are a smoke test's: they never replace a committed report (docs/ or the README):
    SystemExit naming the path."""
    if not quick or out is None:
        return
    root = Path(__file__).resolve().parents[1]
    path, docs = Path(out).resolve(), (root / "docs").resolve()
    if path == docs or docs in path.parents or path == (root / "README.md").resolve():
        raise SystemExit(f"--quick never writes into docs/ or the README (the committed reports): --out {out}")


def report_path(out: str | None, quick: bool, name: str, docs: bool = False) -> Path:
    """Where a report command writes its Markdown file (its PNGs go next to it).

    ``--out`` when given (a path relative to the working directory, as any command-line path;
    ``--out docs/<name>`` from the repository root regenerates the committed report). Without it a
    ``--quick`` run writes into a new temporary directory and a full run into ``runs/reports/<name>``
    under the working directory (``runs/`` is git-ignored), or, with ``docs``, into the committed report
    ``docs/<name>`` of the repository (the hours-long studies, whose run is the committed report)."""
    if out is not None:
        refuse_quick_into_docs(out, quick)
        return Path(out).resolve()
    if quick:
        return Path(tempfile.mkdtemp(prefix="penny_env-quick-")) / name
    if docs:
        return Path(__file__).resolve().parents[1] / "docs" / name
    return (Path("runs") / "reports" / name).resolve()


class Report:
    """One run of a report command (:func:`report_command`): its parsed arguments, where its Markdown goes
    (``out``; its figures and tables beside it, :meth:`beside`), its header and its writes."""

    def __init__(self, module: str, parser: argparse.ArgumentParser, args, argv: list[str], out: Path):
        self.module, self.parser, self.args, self.argv, self.out = module, parser, args, argv, out

    @property
    def quick(self) -> bool:
        return bool(self.args.quick)

    def error(self, message: str):
        """A usage error (exit status 2, the message after the usage line), as argparse reports one."""
        self.parser.error(message)

    def beside(self, suffix: str) -> Path:
        """A file next to the report: ``beside("_scenes.png")`` of docs/x.md is docs/x_scenes.png."""
        self.out.parent.mkdir(parents=True, exist_ok=True)
        return self.out.with_name(self.out.stem + suffix)

    def header(self, title: str) -> list[str]:
        return header(title, self.module, self.argv)

    def figure(self, fig, suffix: str, dpi: int = 110, rect=None) -> Path:
        """A matplotlib figure laid out (tight, within ``rect``), saved beside the report and closed; its path."""
        import matplotlib.pyplot as plt
        fig.tight_layout(**({} if rect is None else {"rect": rect}))
        path = self.beside(suffix)
        fig.savefig(path, dpi=dpi)
        plt.close(fig)
        return path

    def write(self, lines, echo: bool = False) -> Path:
        """The report's text (lines, or one string) into ``out``; ``echo`` prints it too. Says where it wrote."""
        text = lines if isinstance(lines, str) else "\n".join(lines)
        if echo:
            print(text)
        write(str(self.out), [text])
        print(f"wrote {self.out}")
        return self.out

    def readme(self, path, begin: str, end: str, block: str) -> bool:
        """Replace the README's block between the markers (False where it lacks them); never from a --quick run."""
        if self.quick:
            raise SystemExit(f"--quick never writes into docs/ or the README (the committed reports): {path}")
        return replace_block(path, begin, end, block)


def report_command(module: str, name: str, doc: str | None, argv=None, *, quick: str, options=None,
                   docs_default: bool = False, out_help: str = "the Markdown report, its figures beside it",
                   out_flag: str = "--out", rest: bool = False) -> Report:
    """The start of every report command's main: ``python -m MODULE [--quick] [--out PATH]`` and the arguments
    ``options(parser)`` adds, parsed from ``argv`` (the command line when None); ``--quick`` is refused before any
    work (SystemExit naming the path) when ``--out`` points into docs/ or at the README; the report's path (:func:`report_path`:
    runs/reports/NAME by default, docs/NAME with ``docs_default``, a new temporary folder for --quick). ``out_flag``
    names the report's flag where --out means something else; with ``rest`` the arguments it does not know are
    left in ``Report.rest`` (for a command whose other arguments another parser reads)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    where = f"docs/{name}" if docs_default else f"runs/reports/{name} under the working directory"
    ap = argparse.ArgumentParser(prog=f"python -m {module}", description=doc,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true",
                    help=f"{quick}; never into docs/: without --out, into a new temporary folder")
    ap.add_argument(out_flag, dest="out", default=None, help=f"{out_help} (default {where})")
    if options is not None:
        options(ap)
    args, others = ap.parse_known_args(argv) if rest else (ap.parse_args(argv), [])
    report = Report(module, ap, args, argv, report_path(args.out, args.quick, name, docs=docs_default))
    report.rest = others
    return report


def write(path: str, lines: list[str]) -> None:
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    with open(path, "w") as f:
        f.write("\n".join(lines).rstrip() + "\n")


def replace_text_block(text: str, begin: str, end: str, block: str) -> str | None:
    """``text`` with what lies between the markers ``begin`` and ``end`` replaced by ``block`` (on lines of its own),
    or None where it lacks them."""
    if begin not in text or end not in text:
        return None
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{begin}\n{block}\n{end}{tail}"


def replace_block(path, begin: str, end: str, block: str) -> bool:
    """The file's text between the markers replaced by ``block`` (the README's answer blocks, the reports that quote
    them); False where the file lacks the markers (nothing written)."""
    path = Path(path)
    new = replace_text_block(path.read_text(), begin, end, block)
    if new is None:
        return False
    path.write_text(new)
    return True
