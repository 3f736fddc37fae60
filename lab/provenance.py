"""Which committed reports are older than the code that makes them.

    python -m lab.provenance --check                    # list stale reports, exit 1 if any
    python -m lab.provenance --sources docs/X.md        # the files a report's hash covers, and why each
    python -m lab.provenance --stamp docs/X.md --reason "..."   # accept without a rerun

Rule: every report in docs/ records, in its header, a hash of its **sources**, computed, never listed by hand:

* the import closure of its command's module (the module that ``python -m`` runs in :data:`REPORTS`): every
  ``import`` and ``from ... import`` statement of the module's source, at any depth (inside functions too), resolved
  to a file of the repository's packages (:data:`PACKAGES`), with the ``__init__.py`` of every package on the way,
  and so on from each file found; a module named by a string in a config file it reads (the ladder's
  ``module: training.ppo_heading``, run by importlib) counts as imported;
* the data files it reads: the YAML and JSON files under configs/ or inside the packages that a module of the
  closure names by a path of string literals (``ROOT / "configs" / "ladder" / "cpu.yaml"``,
  ``Path(__file__).parent / "reference_data"``: a folder stands for the data files in it) and the files its command
  line names (``--config configs/train/x.yaml``).

Left out: the report machinery (:data:`MACHINERY`: it writes headers and files, it computes no number), and for a
report whose numbers come from other source trees that its command runs (:data:`OWN_MODULE_ONLY`), everything but
its own module. The hash is SHA-256 over each source's repository path and bytes, in sorted order, so an edit of
any source, or a new import, makes the report stale. A report's command writes the line itself
(``lab.common.header`` calls :func:`stamp_line`); ``--check`` (and tests/lab/test_provenance.py) compare it with
the current sources and name the command that regenerates each stale report.

``--stamp REPORT --reason TEXT`` records the current hash in a report **without** rerunning it, with the date and
the reason in the line itself, for reports whose command takes hours (docs/optimal_control_central.md) after one
has checked that the changes do not reach its numbers. The reason stays visible in the report.
"""
from __future__ import annotations

import argparse
import ast
import datetime as _dt
import functools
import hashlib
import re
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]  # the repository (or source tree) root
PACKAGES = ("penny_env", "lab", "training", "studies", "devtools")  # the import contract's root packages
MACHINERY = ("lab/common.py", "lab/provenance.py")  # the report machinery: formatting, headers, files
DATA_SUFFIXES = (".yaml", ".yml", ".json")
DATA_ROOTS = ("configs",) + PACKAGES  # where a data file a module names may lie (never docs/: reports of their own)

# report -> the command that regenerates it, run from the repository root (its module: the word after -m)
REPORTS = {
    "docs/bench_solvers.md": "python -m studies.bench_solvers --out docs/bench_solvers.md",
    "docs/work_precision.md": "python -m studies.work_precision --out docs/work_precision.md",
    "docs/stability.md": "python -m studies.stability --out docs/stability.md",
    "docs/throughput.md": "python -m devtools.throughput --out docs/throughput.md --readme README.md",
    "docs/baselines.md": "python -m studies.baselines --out docs/baselines.md",
    "docs/paper_figures.md": "python -m studies.paper_figures --out docs/paper_figures.md",
    "docs/dynamics.md": "python -m studies.dynamics --out docs/dynamics.md",
    "docs/controllability.md": "python -m studies.controllability --out docs/controllability.md",
    "docs/optimal_control.md": "python -m studies.impact_oc --pairs 12 --workers 1",
    "docs/optimal_control_central.md": "python -m studies.optimal_control --workers 2",
    "docs/billiards.md": "python -m studies.billiards --out docs/billiards.md",
    "docs/billiards_answer.md": "python -m studies.billiards_answer",
    "docs/lyapunov_spread.md": "python -m studies.lyapunov_spread --out docs/lyapunov_spread.md",
    "docs/witnesses.md": "python -m studies.witness_study --workers 2",
    "docs/contention.md": "python -m devtools.contention --out docs/contention.md",
    "docs/compile_time.md": "python -m devtools.compile_time --out docs/compile_time.md",
    # on a CUDA GPU (docs/gpu.md): the commands need one, so a change of their sources is stamped until one is lent
    "docs/throughput_gpu.md": "python -m devtools.throughput_gpu --variants --out docs/throughput_gpu.md",
    "docs/ppo_torch_gpu.md": "python -m studies.ppo_torch_report --config configs/train/ppo_torch_gpu.yaml "
                             "--env-backend cuda --device cuda --curve-points 5 --cuda-graph off "
                             "--report docs/ppo_torch_gpu.md",
    "docs/ladder.md": "python -m studies.ladder",
    "docs/ppo_speed.md": "python -m devtools.ppo_speed --out docs/ppo_speed.md",
    "docs/throughput_compare.md": "python -m devtools.throughput_compare --before OLD --after NEW "
                                  "--out docs/throughput_compare.md",
    "docs/throughput_compare_busy.md": "python -m devtools.throughput_compare --busy --before OLD --after NEW "
                                       "--out docs/throughput_compare_busy.md",
    # the rare path's share: this tree's certificate beside another tree's (OLD); its numbers come from the step
    "docs/rare_share.md": "python -m devtools.rare_share --train-policies runs/rare_share_policies --before OLD "
                          "--out docs/rare_share.md",
}
# the comparisons of two source trees: their numbers come from the trees they name, so only their own module
# makes them stale
OWN_MODULE_ONLY = ("docs/throughput_compare.md", "docs/throughput_compare_busy.md")
# reports whose command was removed, kept unchanged because another command still reads them: not checked
ARCHIVED: dict = {}


def module_of(report: str) -> str:
    """The module that a report's command runs (``python -m MODULE ...``)."""
    words = shlex.split(REPORTS[report])
    return words[words.index("-m") + 1]


# the command modules whose header writes the line (common.header's module argument -> its report: a module with
# two reports, throughput_compare's, has the same sources for both)
MODULE_REPORTS = {}
for _report in REPORTS:
    MODULE_REPORTS.setdefault(module_of(_report), _report)

PREFIX = "- sources: sha256 "
_LINE = re.compile(r"^- sources: sha256 ([0-9a-f]{16})\b")
_MODULE_NAME = re.compile(rf"^(?:{'|'.join(PACKAGES)})(?:\.\w+)*$")


def module_file(name: str, root: Path) -> Path | None:
    """The file of a dotted module name of the repository's packages, or None."""
    if not _MODULE_NAME.match(name):
        return None
    base = root.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _chain(name: str, root: Path) -> list[Path]:
    """The files Python runs to import ``name``: each package's __init__.py on the way, then the module."""
    parts = name.split(".")
    return [f for f in (module_file(".".join(parts[:i + 1]), root) for i in range(len(parts))) if f is not None]


def _package_of(path: Path, root: Path) -> list[str]:
    """The package a module's relative imports start from (a package's __init__.py: the package itself)."""
    return list(path.relative_to(root).parts[:-1])


def _literal_path(node) -> list[str] | None:
    """The string literals of a path built with ``/`` (``ROOT / "configs" / "x.yaml"``), or None."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
        right = _literal_path(node.right)
        if right is None:
            return None
        left = _literal_path(node.left)
        return (left or []) + right  # (a left side that is no literal: ROOT, Path(__file__).parent)
    return None


def _data_files(parts: list[str], near: Path, root: Path) -> list[Path]:
    """The data files a path of literals names, looked for beside the module and in each folder above it up to the
    root; a folder stands for the data files in it."""
    if not parts or any(not p or "\n" in p or len(p) > 100 for p in parts):
        return []
    folder = near
    while True:
        target = folder.joinpath(*parts)
        try:
            rel = target.resolve().relative_to(root.resolve())
        except ValueError:
            rel = None
        if rel is not None and rel.parts and rel.parts[0] in DATA_ROOTS:
            if target.is_file() and target.suffix in DATA_SUFFIXES:
                return [target]
            if target.is_dir() and target != root / rel.parts[0]:
                return sorted(p for p in target.rglob("*") if p.is_file() and p.suffix in DATA_SUFFIXES)
        if folder == root:
            return []
        folder = folder.parent


def _scan(path: Path, root: Path) -> tuple[tuple[Path, ...], tuple[Path, ...]]:
    """(the repository files a module imports, the data files it names)."""
    return _scan_text(path.read_bytes(), path, root)


@functools.lru_cache(maxsize=None)
def _scan_text(text: bytes, path: Path, root: Path) -> tuple[tuple[Path, ...], tuple[Path, ...]]:
    tree = ast.parse(text, filename=str(path))
    imports, data = [], []
    package = _package_of(path, root)
    inner = {id(n.left) for n in ast.walk(tree) if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Div)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                imports += _chain(alias.name, root)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            name = ".".join(base + ([node.module] if node.module else []))
            imports += _chain(name, root)
            for alias in node.names:  # a submodule imported by name: from penny_env import batch
                sub = module_file(f"{name}.{alias.name}", root)
                if sub is not None:
                    imports.append(sub)
        elif isinstance(node, (ast.BinOp, ast.Constant)) and id(node) not in inner:  # (a whole path only)
            parts = _literal_path(node)
            if parts and (isinstance(node, ast.BinOp) or "/" in parts[0]):
                data += _data_files([q for p in parts for q in p.split("/")], path.parent, root)
    return tuple(dict.fromkeys(imports)), tuple(dict.fromkeys(data))


def _config_modules(path: Path, root: Path) -> list[Path]:
    """The modules of the repository a YAML config names by a string (run by importlib)."""
    if path.suffix not in (".yaml", ".yml"):
        return []
    import yaml
    out = []

    def walk(x):
        if isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)
        elif isinstance(x, str) and module_file(x, root) is not None:
            out.extend(_chain(x, root))
    try:
        walk(yaml.safe_load(path.read_text()))
    except yaml.YAMLError:
        pass
    return out


def sources(report: str, root: Path = ROOT) -> list[str]:
    """The repository paths of a report's sources (sorted): its module's import closure and the data it reads."""
    module = module_file(module_of(report), root)
    if module is None:
        raise ValueError(f"{report}: the module of its command {REPORTS[report]!r} is not in the repository")
    if report in OWN_MODULE_ONLY:
        return [module.relative_to(root).as_posix()]
    skip = {root / m for m in MACHINERY}
    words = shlex.split(REPORTS[report])
    todo = _chain(module_of(report), root) + [root / w for w in words if (root / w).is_file()
                                              and (root / w).suffix in DATA_SUFFIXES]
    seen: set[Path] = set()
    while todo:
        path = todo.pop()
        if path in seen or path in skip:
            continue
        seen.add(path)
        if path.suffix == ".py":
            imports, data = _scan(path, root)
            todo += [*imports, *data]
        else:
            todo += _config_modules(path, root)
    return sorted(p.relative_to(root).as_posix() for p in seen)


def sources_hash(report: str, root: Path = ROOT) -> str:
    """The first 16 hex digits of SHA-256 over the report's sources (path and bytes, in sorted order)."""
    h = hashlib.sha256()
    for rel in sources(report, root):
        h.update(rel.encode() + b"\0")
        h.update((root / rel).read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:16]


def stamp_line(report: str, reason: str | None = None, root: Path = ROOT) -> str:
    """The header line of a report: its sources' hash, and where it was stamped without a rerun, why."""
    n = len(sources(report, root))
    what = "its module" if report in OWN_MODULE_ONLY else "the import closure of its module and the data it reads"
    line = (f"{PREFIX}{sources_hash(report, root)} of {n} files, {what} (python -m lab.provenance --sources "
            f"{report} lists them; --check compares)")
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
    ap.add_argument("--sources", metavar="REPORT", choices=sorted(REPORTS), help="list a report's sources")
    ap.add_argument("--stamp", metavar="REPORT", choices=sorted(REPORTS), help="record the current hash without a rerun")
    ap.add_argument("--reason", help="with --stamp: why the report's numbers hold for the current sources")
    args = ap.parse_args(argv)
    if args.sources:
        print("\n".join(sources(args.sources)))
        return 0
    if args.stamp:
        stamp(args.stamp, args.reason or "")
        print(f"{args.stamp}: stamped {sources_hash(args.stamp)}")
        return 0
    bad = stale()
    for report, why in bad:
        print(f"STALE {report}: {why}; regenerate: {REPORTS[report]}")
    if not bad:
        print(f"all {len(REPORTS)} reports match their sources")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
