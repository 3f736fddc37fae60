"""The witness study and the verdict table: every probe (steer park, drive reach, both park) on every table
(the open plane, ellipse, stadium, circle, rounded rectangle) and every law (elastic, plastic, restitution
e = 0.5), N start/target pairs per cell certified by studies/witness.py, the verdict per (actuation, law,
table) from the theory and the witnesses (studies/verdict.py); the learning agents are the agent study's
(studies/ladder.py). Writes docs/witnesses.md (+ witnesses.csv per cell, witnesses_pairs.csv
per pair, witnesses_run.json) and the README's answer block.

    python -m studies.witness_study [--pairs N] [--workers W]   # -> docs/witnesses.md, README.md
    python -m studies.witness_study --quick                     # 3 cells, 2 pairs -> a temporary folder
    python -m studies.witness_study --report-only               # rewrite the report and README from the CSVs

The open plane has no walls, so its law changes nothing: one plane cell per probe stands for every law.
Beyond the presets, EXTRA_TABLES (tables no preset names, as field overrides) show the theorems applied to a cell
the presets do not cover: a circle of radius 0.5 m, where theorem T2.5 excludes every steer-only pair, and one
of radius 0.35 m, where it excludes some. --quick never writes into docs/ or the README.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

from studies.cells import TABLES, TABLE_NAMES, EXTRA_TABLES, ALL_TABLES, LAWS, PROBE_TASKS, cell_spec, all_cells, table_name
from lab.stats import clopper_pearson
from studies.verdict import CONTEXT, THEORY_DOC, anchor_of, cell_verdict, possible_by_theorem, theorem_of
from studies.witness import PROBES, Witness, positive_int

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
QUICK_CELLS = (("Steer", "circle", "plastic"), ("Drive", "ellipse", "elastic"), ("Drive", "plane", "-"),
               ("Steer", "circle_r0.5", "0.5"))
CELL_FIELDS = ["probe", "table", "law", "env_id", "overrides", "pairs", "witnessed", "rate", "ci_low", "ci_high",
               "seconds", "excluded", "excluded_by", "possible", "possible_by", "verdict"]
PAIR_FIELDS = ["probe", "table", "law", "seed", "witnessed", "steps", "impacts", "params", "theorem", "reason"]
README_BEGIN = "<!-- witness-answer: written by python -m studies.witness_study (studies/witness_study.py) -->"
README_END = "<!-- /witness-answer -->"


_WITNESSES = {}  # per process: the cell's Witness (its envs load compiled code once)


def _run_chunk(task):
    probe, table, law, seeds = task
    key = (probe, table, law)
    if key not in _WITNESSES:
        _WITNESSES[key] = Witness(*cell_spec(probe, table, law))
    w = _WITNESSES[key]
    t0 = time.process_time()
    out = []
    for s in seeds:
        r = w.pair(s)
        out.append({"probe": probe, "table": table, "law": law, "seed": s, "witnessed": int(r.witnessed),
                    "steps": r.steps, "impacts": r.impacts, "params": " ".join(f"{v:.4g}" for v in r.params),
                    "theorem": r.theorem, "reason": r.reason})
    return out, time.process_time() - t0


def run_cells(cells, pairs, seed, workers, theorem_pairs=None):
    """(pair rows, {cell: CPU seconds}) of every cell's pairs, split over `workers` processes. Cells that a
    theorem declares impossible run theorem_pairs pairs (default: pairs): there the witness only checks that
    no episode contradicts the theorem, and its search runs every candidate to the time limit."""
    def n_of(p, t, law):
        return min(pairs, theorem_pairs) if theorem_pairs and theorem_of(p, t, law) else pairs
    tasks = [(p, t, law, list(range(seed + i, seed + n_of(p, t, law), workers)))
             for (p, t, law) in cells for i in range(min(workers, n_of(p, t, law)))]
    rows, seconds = [], {}

    def collect(results):  # (lazily: progress is printed as the chunks finish, in order)
        for task, (part, sec) in zip(tasks, results):
            rows.extend(part)
            seconds[task[:3]] = seconds.get(task[:3], 0.0) + sec
            print(f"{task[0]} {task[1]} {task[2]}: {sum(r['witnessed'] for r in part)}/{len(part)} witnessed "
                  f"({sec:.0f} s CPU)", flush=True)
    if workers == 1:
        collect(_run_chunk(task) for task in tasks)
    else:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(workers) as ex:
            collect(ex.map(_run_chunk, tasks))
    rows.sort(key=lambda r: (*_order(r), r["seed"]))
    return rows, seconds


def _order(r):
    """Sort key of a cell: probe, table, law in PROBES, TABLES, LAWS order."""
    return PROBES.index(r["probe"]), ALL_TABLES.index(r["table"]), list(LAWS).index(r["law"]) if r["law"] in LAWS else -1


def cell_rows(pair_rows, seconds):
    cells = {}
    for r in pair_rows:
        cells.setdefault((r["probe"], r["table"], r["law"]), []).append(r)
    out = []
    for (probe, table, law), rs in cells.items():
        k, n = sum(int(r["witnessed"]) for r in rs), len(rs)
        ex, by = excluded_of(rs)
        pos, pos_by = possible_of(rs)
        lo, hi = clopper_pearson(k, n)
        env_id, over = cell_spec(probe, table, law)
        out.append({"probe": probe, "table": table, "law": law, "env_id": env_id,
                    "overrides": " ".join(f"{a}={b}" for a, b in over.items()), "pairs": n, "witnessed": k,
                    "rate": k / n, "ci_low": lo, "ci_high": hi, "seconds": round(seconds.get((probe, table, law), 0.0), 1),
                    "excluded": ex, "excluded_by": by, "possible": pos, "possible_by": pos_by,
                    "verdict": cell_verdict(probe, table, k, n, law, ex, by, pos, pos_by)})
    return out


def excluded_of(pair_rows):
    """(pairs a theorem excludes, their theorem ids joined by ', ') of one cell's pair rows."""
    ids = [r.get("theorem", "") for r in pair_rows if r.get("theorem", "")]
    return len(ids), ", ".join(sorted(set(ids)))


def possible_of(pair_rows):
    """(pairs a theorem proves possible given enough time, their theorem ids) of one cell's pair rows: recomputed from
    the pairs' seeds by the theory's code (studies/verdict.possible_by_theorem), never read from a CSV."""
    r0 = pair_rows[0]
    return possible_by_theorem(r0["probe"], r0["table"], r0["law"], tuple(int(r["seed"]) for r in pair_rows))


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def write_csv(path, rows, fields):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)


def _key(r):
    return r["probe"], r["table"], r["law"]


def verdict_grid(cells):
    """Markdown rows: one per (probe, law), one column per table, the verdict in each."""
    by = {_key(c): c for c in cells}
    lines = ["| actuation | law | " + " | ".join(TABLE_NAMES[t] for t in TABLES) + " |",
             "| --- | --- |" + " --- |" * len(TABLES)]
    for probe in PROBES:
        for law in LAWS:
            row = []
            for t in TABLES:
                c = by.get((probe, t, "-" if t == "plane" else law))
                row.append(_verdict_md(c) if c else "not run")
            lines.append(f"| {PROBE_TASKS[probe]} | {LAWS[law].lower() if law != '0.5' else 'e = 0.5'} | "
                         + " | ".join(row) + " |")
    return lines


def _verdict_md(c, link=f"{THEORY_DOC}"):
    v = c["verdict"]
    if v.startswith("impossible"):
        thm = theorem_of(c["probe"], c["table"], c["law"])[0]
        return f"impossible ([theorem {thm}]({link}#{anchor_of(thm)}))"
    return v


def extra_rows(cells):
    """Markdown rows of the cells on tables no preset names (EXTRA_TABLES): the theorems applied to overrides."""
    lines = ["| actuation | table (override) | law | pairs | witnessed | impossible by theorem (pairs) | verdict |",
             "| --- | --- | --- | ---: | ---: | --- | --- |"]
    for c in cells:
        if c["table"] in EXTRA_TABLES:
            ex = f"{c['excluded']}/{c['pairs']} ({c['excluded_by']})" if int(c["excluded"]) else "0"
            lines.append(f"| {PROBE_TASKS[c['probe']]} | {table_name(c['table'])} (`table={EXTRA_TABLES[c['table']]}`) | "
                         f"{c['law']} | {c['pairs']} | {c['witnessed']} | {ex} | {_verdict_md(c)} |")
    return lines


def failures(pair_rows):
    """Markdown lines: per cell, the pairs not witnessed grouped by reason."""
    lines = []
    groups = {}
    for r in pair_rows:
        if not int(r["witnessed"]):
            groups.setdefault(_key(r), {}).setdefault(r["reason"], []).append(str(r["seed"]))
    for key, reasons in groups.items():
        for reason, seeds in reasons.items():
            lines.append(f"- {PROBE_TASKS[key[0]]}, {table_name(key[1])}, law {key[2]}: seeds {', '.join(seeds)}: {reason}")
    return lines or ["- none: every pair of every cell that no theorem forbids was witnessed"]


def summary(cells):
    """Per probe: (impossible tables, witnessed cells as (k, N), open cells), over the preset tables (TABLES; the
    override cells of EXTRA_TABLES are reported on their own)."""
    out = {}
    for probe in PROBES:
        cs = [c for c in cells if c["probe"] == probe and c["table"] in TABLES]
        imp = [c for c in cs if c["verdict"].startswith("impossible")]
        wit = [c for c in cs if c["verdict"].startswith("possible")]
        opn = [c for c in cs if c["verdict"].startswith("open")]
        out[probe] = (imp, wit, opn)
    return out


def readme_answer(cells, report="docs/witnesses.md") -> str:
    """The README's answer, computed from the verdict table (never typed): a grid of the verdicts (per table, the
    laws' k/N), then per actuation the range of witnessed shares and what the theorems prove; the learning agents
    are the agent study's (studies/ladder.py), which writes the README's one answer about them."""
    by = {_key(c): c for c in cells}
    law_names = " · ".join(LAWS[law].lower() if law != "0.5" else "e = 0.5" for law in LAWS)
    lines = [f"Answer from theorems and certified witness episodes ([{report}]({report}); theory: "
             f"[docs/{THEORY_DOC}](docs/{THEORY_DOC})). Per table: **impossible (theorem)**, or the pairs witnessed "
             f"k/N per law ({law_names}; the plane has no walls, one run for every law), with the pairs a **theorem** "
             "proves possible given enough time (T8: steer only on the tables with parallel flat sides, from starts "
             "with room), **open** where none was:", "",
             "| actuation | " + " | ".join(TABLE_NAMES[t] for t in TABLES) + " |",
             "| --- |" + " --- |" * len(TABLES)]
    for probe in PROBES:
        row = []
        for t in TABLES:
            cs = [by.get((probe, t, "-" if t == "plane" else law)) for law in (("-",) if t == "plane" else LAWS)]
            if any(c is None for c in cs):
                row.append("not run")
            elif cs[0]["verdict"].startswith("impossible"):
                thm = theorem_of(probe, t)[0]
                row.append(f"**impossible** (theorem {thm})")
            else:
                row.append(" · ".join(_count_md(c) for c in cs))
        lines.append(f"| {PROBE_TASKS[probe]} | " + " | ".join(row) + " |")
    lines.append("")
    sentences = []
    for probe, (imp, wit, opn) in summary(cells).items():
        bits = []
        if wit:
            rates = [int(c["witnessed"]) / int(c["pairs"]) for c in wit]
            low = min(clopper_pearson(int(c["witnessed"]), int(c["pairs"]))[0] for c in wit)
            bits.append(f"possible in {len(wit)} cells, witnessed in {_span(rates, '.0%')} of the "
                        f"pairs per cell (lowest exact 95 % lower bound {low:.2f})")
        thm = [c for c in wit if int(c.get("possible", 0) or 0)]
        if thm:
            ids = sorted({i.strip() for c in thm for i in c["possible_by"].split(",")})
            names = sorted({table_name(c["table"]) for c in thm}, key=[table_name(x) for x in ALL_TABLES].index)
            shares = [int(c["possible"]) / int(c["pairs"]) for c in thm]
            bits.append(f"given enough time, a theorem ({', '.join(ids)}) proves it possible in {len(thm)} of these "
                        f"cells ({' and '.join(names)}) for {_span(shares, '.0%')} of the pairs per cell (the starts "
                        f"with room to aim)")
        if opn:
            bits.append(f"open in {len(opn)} cells")
        if bits:
            sentences.append(f"**{PROBE_TASKS[probe]}**: " + "; ".join(bits) + ".")
    lines.append(" ".join(sentences) + " Whether learning agents find these controls: the agent study, "
                 "[docs/ladder.md](docs/ladder.md).")
    extra = [c for c in cells if c["table"] in EXTRA_TABLES]
    if extra:
        lines += ["", "The theorems apply to every cell, overrides and user tables included (steer only, e = 0.5): "
                  + "; ".join(f"{table_name(c['table'])}: "
                              + (f"**impossible** (theorem {theorem_of(c['probe'], c['table'], c['law'])[0]})"
                                 if c["verdict"].startswith("impossible") else _count_md(c)) for c in extra) + "."]
    return "\n".join(lines)


def _count_md(c) -> str:
    """'k/N' of a cell, with the pairs a theorem excludes ('k/N, m impossible (T2.5)') or proves possible given enough
    time ('k/N (theorem T8.1: p/N)'), or 'open'."""
    ex = int(c.get("excluded", 0) or 0)
    pos = int(c.get("possible", 0) or 0)
    tail = f", {ex} impossible ({c['excluded_by']})" if ex else ""
    tail += f" (**theorem** {c['possible_by']}: {pos}/{c['pairs']})" if pos else ""
    if c["verdict"].startswith("open"):
        return f"open (0/{c['pairs']}{tail})"
    return f"{c['witnessed']}/{c['pairs']}{tail}"


def update_readme(path: Path, answer: str) -> bool:
    """The text between this report's README_BEGIN and README_END markers of a file (the README, a report that quotes
    the block) rewritten; False where the file has none (lab/common.replace_block)."""
    from lab.common import replace_block
    return replace_block(path, README_BEGIN, README_END, answer)


def _span(values, fmt: str) -> str:
    """'a to b' of the values' range as formatted, or one value where both ends read the same."""
    lo, hi = format(min(values), fmt), format(max(values), fmt)
    return lo if lo == hi else f"{lo} to {hi}"


def write_report(out: Path, cells, pair_rows, meta):
    from lab.common import machine_lines
    lines = ["# Which actuations and walls make the penny controllable: theorems and certified witnesses", "",
             *meta["machine"], f"- command: `{meta['command']}` ({meta['wall_s']:.0f} s wall, "
             f"{sum(float(c['seconds']) for c in cells):.0f} s CPU in the witness searches, finished {meta['date']})",
             f"- pairs per cell: N = {meta.get('pairs', '?')}; in the cells a theorem declares impossible "
             f"{meta.get('theorem_pairs', '?')} (a check that no episode contradicts it: the search runs every "
             "candidate to the time limit there)",
             "- regenerate: run the command above from the repository root; "
             "`python -m studies.witness_study --report-only` rewrites this report and the README from the CSVs",
             *([meta["sources"]] if meta.get("sources") else []),
             f"- report rewritten with --report-only, {machine_lines()[2].lstrip('- ')}" if meta.get("rewritten") else "",
             "",
             "## The verdict", "",
             f"Per (actuation, law, table): **impossible (theorem Tk)** where [{THEORY_DOC}]({THEORY_DOC}) proves "
             "the probe's task unreachable from every start/target pair the cell can draw (its table, spawn and target "
             "regions, time limit and speeds); where a theorem excludes only some of the N pairs drawn, the count "
             "follows the witnessed one (\"m/N impossible, theorem Tk\"); **possible (theorem Tk for p/N pairs, given enough "
             "time; witnessed k/N)** where a theorem proves the task possible, without a time limit but within the probe's "
             "own control rows and torque limit, for p of the N pairs (T8.1 and T8.2: steer only on the tables with "
             "parallel flat sides, from starts with room to aim; the circle's T7.2 and T7.4, stated for torques that "
             "switch at any instant, are not counted here); **possible (witnessed k/N)** where at least one of N "
             "start/target pairs of the probe's own distribution was solved by an episode of the package's "
             "environment ending with `is_success` (studies/witness.py); **open** otherwise. A witness in a "
             "theorem's cell would be a contradiction and stops the report (studies/verdict.py). The open plane "
             "has no walls: one run stands for every law. Theory beside the witnessed cells: "
             + ", ".join(f"{PROBE_TASKS[p]}: {t}" for p, t in CONTEXT.items()) + ".", "",
             *verdict_grid(cells), "",
             "Tables no preset names (field overrides of the probe ids): the same theorems, read from the cell's table, "
             "spawn and target regions, time limit and speeds (penny_env/analysis/controllability_theorems.py); a pair "
             "that a theorem excludes is still searched (a witness there would stop the report):", "",
             *extra_rows(cells), "",
             "## Learning agents", "",
             "Whether learning agents find the controls that these witnesses prove to exist is the agent study's "
             "question: [ladder.md](ladder.md) (python -m studies.ladder), each agent's success beside the witnessed "
             "rate of the same pair seeds.", "",
             "## Witnesses per cell", "",
             "k/N: pairs witnessed (pair i: the probe's reset with seed i); 95 % exact Clopper-Pearson interval of "
             "the witnessable share; CPU seconds of the cell's searches and certifications.", "",
             "| actuation | table | law | env id and overrides | witnessed | rate [95 % CI] | CPU s |",
             "| --- | --- | --- | --- | --- | --- | ---: |"]
    for c in cells:
        ident = f"`{c['env_id']}`" + (f" `{c['overrides']}`" if c["overrides"] else "")
        lines.append(f"| {PROBE_TASKS[c['probe']]} | {table_name(c['table'])} | {c['law']} | {ident} | "
                     f"{c['witnessed']}/{c['pairs']} | {float(c['rate']):.2f} [{float(c['ci_low']):.3f}, "
                     f"{float(c['ci_high']):.3f}] | {float(c['seconds']):.0f} |")
    lines += ["", "## Pairs not witnessed, and why", "", *failures(pair_rows), "",
              "## How the witnesses work", "",
              "studies/witness.py: per pair, a small family of state-feedback controllers (steer: 48 headings "
              "into the first impact x 12 turns after a fast impact, then steer at the target once an impact left "
              "the roll under the park tolerance; drive: roll into the wall forwards or backwards at 4 speeds, then "
              "drive along the turning heading at k (target - contact point) . heading; both: the study's feedback "
              "controller at 3 top speeds) is simulated from the pair's exact start on a PennyVectorEnv (one row "
              "per candidate, the compiled step), and the first candidate that succeeds is run as a controller in "
              "the real episode (gymnasium.make of the id, reset with the pair's seed): the pair counts only if "
              "that episode ends with `is_success`. `python -m studies.witness ENV_ID [--pairs N] [field=value ...]` "
              "runs one cell. A pair the family does not solve is not shown impossible (the family is small and "
              "the search stops at its first success): the witnessed share is a lower bound of the solvable share "
              "of the probe's start/target distribution, and only a theorem says impossible.", ""]
    out.write_text("\n".join(x for x in lines if x is not None))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.witness_study", description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=positive_int("--pairs"), default=200, help="start/target pairs per cell")
    ap.add_argument("--theorem-pairs", type=positive_int("--theorem-pairs"), default=5,
                    help="pairs in the cells a theorem declares impossible (a consistency check)")
    ap.add_argument("--seed", type=positive_int("--seed", 0), default=0, help="first pair's seed")
    ap.add_argument("--workers", type=positive_int("--workers"), default=2, help="processes")
    ap.add_argument("--quick", action="store_true", help="3 cells, 2 pairs, into --out-dir (never docs/)")
    ap.add_argument("--out-dir", type=Path, default=None, help="report folder (default docs/; --quick: a new "
                    "temporary folder)")
    ap.add_argument("--report-only", action="store_true", help="rewrite the report and README from the CSVs")
    args = ap.parse_args(argv)
    if args.out_dir is not None:
        out_dir = args.out_dir.resolve()
    elif args.quick:
        from lab.common import report_path
        out_dir = report_path(None, True, "witnesses.md").parent
    else:
        out_dir = DOCS
    if args.quick and out_dir.resolve() == DOCS.resolve():
        ap.error("--quick never writes into docs/; give another --out-dir")
    out_dir.mkdir(parents=True, exist_ok=True)
    cells_csv, pairs_csv, meta_json = out_dir / "witnesses.csv", out_dir / "witnesses_pairs.csv", out_dir / "witnesses_run.json"
    if args.report_only:
        if not cells_csv.is_file() or not pairs_csv.is_file() or not meta_json.is_file():
            ap.error(f"--report-only needs {cells_csv.name}, {pairs_csv.name} and {meta_json.name} in {out_dir}")
        cells, pair_rows = read_csv(cells_csv), read_csv(pairs_csv)
        meta = dict(json.loads(meta_json.read_text()), rewritten=True)
    else:
        from lab.common import command_line, machine_lines
        from lab.provenance import stamp_line
        cells_todo = QUICK_CELLS if args.quick else all_cells()
        pairs = 2 if args.quick else args.pairs
        t0 = time.perf_counter()
        pair_rows, seconds = run_cells(cells_todo, pairs, args.seed, args.workers, args.theorem_pairs)
        cells = cell_rows(pair_rows, seconds)
        meta = {"command": command_line("studies.witness_study", list(sys.argv[1:] if argv is None else argv)),
                "machine": machine_lines(), "wall_s": time.perf_counter() - t0,
                "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "pairs": pairs,
                "theorem_pairs": min(pairs, args.theorem_pairs),
                # the sources that made these searches (a later --report-only keeps it: a rewrite is no rerun)
                "sources": stamp_line("docs/witnesses.md")}
        write_csv(cells_csv, cells, CELL_FIELDS)
        write_csv(pairs_csv, pair_rows, PAIR_FIELDS)
        meta_json.write_text(json.dumps(meta, indent=1))
    cells.sort(key=_order)
    for c in cells:  # the verdict recomputed from the counts (a CSV edited by hand cannot carry another)
        mine = [r for r in pair_rows if _key(r) == _key(c)]
        c["excluded"], c["excluded_by"] = excluded_of(mine)
        c["possible"], c["possible_by"] = possible_of(mine)
        c["verdict"] = cell_verdict(c["probe"], c["table"], int(c["witnessed"]), int(c["pairs"]), c["law"],
                                    c["excluded"], c["excluded_by"], c["possible"], c["possible_by"])
    if args.report_only:  # (the cells' CSV carries the recomputed verdicts; the pairs' CSV and the counts are kept)
        write_csv(cells_csv, cells, CELL_FIELDS)
    write_report(out_dir / "witnesses.md", cells, pair_rows, meta)
    print(f"wrote {out_dir / 'witnesses.md'}")
    if out_dir.resolve() == DOCS.resolve() and not args.quick:
        if update_readme(ROOT / "README.md", readme_answer(cells)):
            print("README.md: the answer updated from the verdict table")
    return cells


if __name__ == "__main__":
    main()
