"""The command line every agent of the ladder shares (``python -m training.<agent>``), with the protections of
``training.train``:

    --env-id ID  --total-timesteps N  --seed K  --set FIELD=VALUE ...  --hp NAME=VALUE ...  [--demos NPZ]
    [--quick] [--eval] [--out DIR | --resume DIR]

* **Values** are read as YAML 1.2 (``penny_env.envs.yaml_io``: ``3e-4`` is a float) and checked before any work, each
  a usage error (exit status 2) naming its flag: ``--total-timesteps`` a finite whole number >= 1 (``1e8`` allowed),
  ``--seed`` >= 0, ``--env-id`` a registered penny_env id, ``--set`` the env's own fields (its resolver names a bad
  one), ``--hp`` the fields of the agent's ``Args`` with the type its annotation gives and the agent's own ranges
  (``CHECKS``: name -> check, see :func:`positive`, :func:`non_negative`, :func:`unit_interval`); every float finite.
* **Run folders** (``training.run_folder``): ``--out`` that is a file, or a folder holding files, is refused at once
  (never after training); one lock per folder for the whole run, so two runs never write into one folder.
* **Ctrl-C**: with ``--out`` the agent saves ``checkpoint.pt`` at the step it reached and the command prints the
  line that resumes it; without ``--out`` it says that nothing was saved. Exit status 130.
* **--resume DIR** goes on from ``DIR/checkpoint.pt`` (the learner: networks, optimiser, step count, the agent's own
  schedules; the envs start new episodes) with ``DIR/config.json``'s settings; only ``--total-timesteps`` may change.

An agent's ``train(args, checkpoints, on_checkpoint, log, resume)`` writes ``checkpoint.pt`` into ``args.out`` every
``save_every`` env steps and when interrupted (raising :class:`Interrupted`), and reads it back when ``resume`` names it.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shlex
import sys
import types
import typing
from pathlib import Path

CHECKPOINT = "checkpoint.pt"
CONFIG = "config.json"
RESULTS = "results.json"


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during an agent's training: where it stopped and the checkpoint it saved (None: nothing saved)."""

    def __init__(self, env_steps: int, checkpoint: Path | None):
        super().__init__(f"interrupted at {env_steps:,} env steps")
        self.env_steps, self.checkpoint = int(env_steps), checkpoint


# -- value checks an agent declares in CHECKS ---------------------------------------------------------------------
def positive(name, v):
    if not v > 0:
        raise ValueError(f"{name} must be positive, got {v!r}")


def non_negative(name, v):
    if not v >= 0:
        raise ValueError(f"{name} must be non-negative, got {v!r}")


def unit_interval(name, v):
    if not 0 <= v <= 1:
        raise ValueError(f"{name} must be in [0, 1], got {v!r}")


def one_of(*choices):
    def check(name, v):
        if v not in choices:
            raise ValueError(f"{name} must be one of {list(choices)}, got {v!r}")
    return check


COMMON_CHECKS = {"total_timesteps": positive, "seed": non_negative, "torch_threads": positive}


def _typed(name: str, value, hint):
    """``value`` as the field's annotated type (an int where a float is asked is taken); TypeError naming the field."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(hint)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in (o for o in options if o is not type(None)):
            try:
                return _typed(name, value, option)
            except TypeError as exc:
                errors.append(str(exc))
        raise TypeError(errors[0] if errors else f"{name}: unexpected {value!r}")
    base = origin or hint
    if base is bool:
        ok = isinstance(value, bool)
    elif base is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif base is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif base in (list, tuple):
        ok = isinstance(value, (list, tuple))
        value = base(value) if ok else value
    elif base in (dict, str):
        ok = isinstance(value, base)
    else:
        ok = True
    if not ok:
        want = {int: "an integer", float: "a number", bool: "true or false", str: "a string", dict: "a mapping",
                list: "a list", tuple: "a list"}.get(base, str(hint))
        raise TypeError(f"{name} must be {want}, got {type(value).__name__} {value!r}")
    return value


def check_args(args, checks: dict | None = None) -> None:
    """TypeError or ValueError naming the first field of ``args`` whose type or value is wrong: the annotations of
    its dataclass, finite floats, :data:`COMMON_CHECKS` and the agent's ``checks`` (name -> check(name, value); the
    key None: check(args), for rules between fields); the env id and its fields."""
    hints = typing.get_type_hints(type(args))
    for f in dataclasses.fields(args):
        v = _typed(f.name, getattr(args, f.name), hints.get(f.name, typing.Any))
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{f.name} must be finite, got {v!r}")
        check = {**COMMON_CHECKS, **(checks or {})}.get(f.name)
        if check is not None and v is not None:
            check(f.name, v)
    if (checks or {}).get(None) is not None:
        checks[None](args)
    check_env(args.env_id, args.env_kwargs)


def check_env(env_id, env_kwargs) -> None:
    """ValueError naming an unknown id or a bad field override (the env's own resolver's message)."""
    import penny_env  # noqa: F401  (registers the ids)
    from penny_env.envs.registration import env_ids
    from penny_env.envs.scene import env_presets, resolve
    if env_id not in env_ids():
        raise ValueError(f"env_id {env_id!r} is not a registered penny_env id; known: {', '.join(env_ids())}")
    if not isinstance(env_kwargs, dict):
        raise TypeError(f"env_kwargs must be a mapping of the env's fields, got {env_kwargs!r}")
    fields = {**env_presets()[env_id], **env_kwargs}  # (a field may replace the scene itself)
    try:
        resolve(fields.pop("scene"), fields.pop("task"), **fields)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"env field: {exc}") from None


def parse_pairs(items, flag: str) -> dict:
    """{NAME: value} from NAME=VALUE strings, each value read as YAML 1.2; ValueError naming the flag and item."""
    import yaml

    from penny_env.envs.yaml_io import safe_load
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name.strip():
            raise ValueError(f"{flag}: expected NAME=VALUE, got {item!r}")
        try:
            out[name.strip()] = safe_load(value)
        except yaml.YAMLError as exc:
            raise ValueError(f"{flag} {item!r}: the value {value!r} is not valid YAML ({' '.join(str(exc).split())}); "
                             "quote it in the shell") from None
    return out


def whole_number(text: str, flag: str) -> int:
    """A finite whole number >= 1 from ``1e8``, ``100000000`` or ``1_000``; ValueError naming the flag."""
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{flag} must be a number, got {text!r}") from None
    if not math.isfinite(v) or v < 1 or v != int(v):
        raise ValueError(f"{flag} must be a finite whole number >= 1, got {text!r}")
    return int(v)


# -- the command --------------------------------------------------------------------------------------------------
def parser(prog: str, args_class) -> argparse.ArgumentParser:
    fields = {f.name for f in dataclasses.fields(args_class)}
    ap = argparse.ArgumentParser(prog=f"python -m {prog}")
    ap.add_argument("--env-id", default=None, help=f"a registered penny_env id (default {args_class.env_id})")
    ap.add_argument("--total-timesteps", default=None, help="env steps (default: the agent's; 1e8 allowed)")
    ap.add_argument("--seed", type=int, default=None, help="the run's seed (>= 0; default 0)")
    ap.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="env field overrides (YAML values)")
    ap.add_argument("--hp", nargs="*", default=[], metavar="NAME=VALUE", help="fields of the agent's Args (YAML values)")
    if "demos" in fields:
        ap.add_argument("--demos", default=None, help="demonstrations (.npz of training.protocol.save_demos)")
    ap.add_argument("--quick", action="store_true", help="a few seconds: checks the pipeline, learns nothing")
    ap.add_argument("--eval", action="store_true", help="evaluate the final policy on the pair seeds 0..199")
    ap.add_argument("--out", default=None, help="a new or empty folder for the run's files")
    ap.add_argument("--resume", default=None, metavar="DIR", help="go on from DIR/checkpoint.pt with DIR's settings")
    return ap


def build_args(ap, a, args_class, checks, quick_args):
    """The run's Args from the parsed flags (and, with --resume, the folder's config.json); usage errors via ``ap``."""
    fields = {f.name for f in dataclasses.fields(args_class)}
    try:
        if a.resume is not None:
            folder = Path(a.resume)
            if not (folder / CHECKPOINT).is_file() or not (folder / CONFIG).is_file():
                raise ValueError(f"--resume {folder}: no {CHECKPOINT} and {CONFIG} there (a run of this command "
                                 "with --out writes them)")
            if a.out is not None and Path(a.out).resolve() != folder.resolve():
                raise ValueError("--out and --resume name different folders: a resumed run writes into its own")
            changed = [flag for flag, v in (("--env-id", a.env_id), ("--seed", a.seed), ("--set", a.set),
                                            ("--hp", a.hp), ("--demos", getattr(a, "demos", None)),
                                            ("--quick", a.quick)) if v]
            if changed:
                raise ValueError(f"--resume goes on with {folder / CONFIG}'s settings; only --total-timesteps may "
                                 f"change, not {', '.join(changed)}")
            saved = json.loads((folder / CONFIG).read_text())
            unknown = sorted(set(saved) - fields)
            if not isinstance(saved, dict) or unknown:
                raise ValueError(f"--resume {folder}: {CONFIG} is not a config of {ap.prog} (fields {unknown})")
            args = dataclasses.replace(args_class(), **saved)
            if a.total_timesteps is not None:
                args = dataclasses.replace(args, total_timesteps=whole_number(a.total_timesteps, "--total-timesteps"))
            args = dataclasses.replace(args, out=str(folder))
        else:
            hp = parse_pairs(a.hp, "--hp")
            unknown = sorted(set(hp) - fields)
            if unknown:
                raise ValueError(f"--hp: {unknown} are not fields of {ap.prog}.Args; fields: {sorted(fields)}")
            given = {"env_kwargs": parse_pairs(a.set, "--set"), "out": a.out}
            if a.env_id is not None:
                given["env_id"] = a.env_id
            if a.seed is not None:
                given["seed"] = a.seed
            if a.total_timesteps is not None:
                given["total_timesteps"] = whole_number(a.total_timesteps, "--total-timesteps")
            if getattr(a, "demos", None) is not None:
                demos = Path(a.demos)
                if not demos.is_file():
                    raise ValueError(f"--demos {demos}: no such file")
                given["demos"] = str(demos)
            args = dataclasses.replace(args_class(), **given, **hp)
            if a.quick:
                if quick_args is None:
                    raise ValueError(f"{ap.prog} has no --quick mode")
                args = quick_args(args)
        check_args(args, checks)
        if getattr(args, "demos", None):
            from training.protocol import load_demos
            load_demos(args.demos)  # (a damaged file is named now, not after the training it would follow)
        if a.resume is None and args.out is not None:
            from training.run_folder import check_new_folder
            check_new_folder(args.out)
    except (TypeError, ValueError, OSError) as exc:
        ap.error(str(exc))
    return args


def cli(prog: str, args_class, train, argv=None, quick_args=None, checks=None) -> dict:
    """Parse, check, hold the run folder's lock, train, evaluate (--eval), write results.json; returns ``train``'s
    dict (with ``eval`` after --eval). The env steps on one numba thread unless NUMBA_NUM_THREADS says otherwise
    (torch's: ``--hp torch_threads=N``). The thread count in use is set, never the variable: numba refuses a changed
    NUMBA_NUM_THREADS once its threads run (an agent called in a process that stepped a vector env before)."""
    if "NUMBA_NUM_THREADS" not in os.environ:
        import numba
        numba.set_num_threads(1)
    ap = parser(prog, args_class)
    argv = list(sys.argv[1:] if argv is None else argv)
    a = ap.parse_args(argv)
    args = build_args(ap, a, args_class, checks, quick_args)
    out = Path(args.out) if args.out else None
    if out is None:
        return _run(prog, args, train, a, None, argv)
    from training.run_folder import RunFolderError, run_lock
    try:
        with run_lock(out):
            (out / CONFIG).write_text(json.dumps(dataclasses.asdict(args), indent=1, default=str))
            return _run(prog, args, train, a, out, argv)
    except RunFolderError as exc:  # another run holds the folder: a usage error
        ap.error(str(exc))


def _run(prog, args, train, a, out, argv) -> dict:
    from training.protocol import evaluate
    final = []
    resume = str(out / CHECKPOINT) if a.resume is not None else None
    try:
        res = train(args, on_checkpoint=lambda steps, policy: final.append(policy),
                    log=lambda s: print(s, flush=True), resume=resume)
    except KeyboardInterrupt as exc:
        steps = getattr(exc, "env_steps", None)
        where = f" at {steps:,} env steps" if steps is not None else ""
        ckpt = getattr(exc, "checkpoint", None)
        if ckpt is not None:
            print(f"[{prog}] interrupted{where}; saved {ckpt}; go on with: python -m {prog} --resume "
                  f"{shlex.quote(str(out))}" + (f" --total-timesteps {args.total_timesteps}" if a.resume else ""),
                  file=sys.stderr, flush=True)
        else:
            print(f"[{prog}] interrupted{where}; nothing was saved"
                  + (" (give --out to keep a checkpoint)" if out is None else ""), file=sys.stderr, flush=True)
        raise SystemExit(130) from None
    res = dict(res or {})
    if a.eval:
        ev = evaluate(final[-1], args.env_id, args.env_kwargs)
        res["eval"] = {"successes": ev["successes"], "episodes": ev["episodes"]}
        print(f"[{prog}] evaluation (seeds 0..199, deterministic): {ev['successes']}/{ev['episodes']}", flush=True)
    if out is not None:
        plain = {k: v for k, v in res.items() if k not in ("policy", "agent", "actor", "state")}
        tmp = out / (RESULTS + ".tmp")
        tmp.write_text(json.dumps({**plain, "args": dataclasses.asdict(args)}, default=str, indent=1))
        tmp.replace(out / RESULTS)
    return res
