"""A run folder is written by one run at a time, and a resumed run goes on from an intact checkpoint of the same
run.

* :func:`run_lock` holds an exclusive lock (``RUN_DIR/.lock``, filelock: flock on POSIX, msvcrt on Windows) while a
  run writes. A second run into the same folder is refused at once, naming the folder: two runs used to interleave
  progress.csv with shifted columns, overwrite each other's checkpoints and leave results.json naming one seed. The
  lock is released by the OS if the process dies, so a killed run never leaves the folder locked.
* :func:`check_new_folder`: training.train refuses a non-empty ``--out`` without ``--resume``.
* :func:`intact_checkpoint`: the newest checkpoint whose zip is whole (a run killed while saving leaves a truncated
  one), saying which it skipped.
* :func:`resume_changes`: what a resumed run would change against the run it goes on from (num_envs, env_id, algo,
  seed, hyperparameters), which SB3 would otherwise take silently or ignore.

Every refusal is a :class:`RunFolderError` (a ValueError), which the commands print as a usage error.
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

LOCK_NAME = ".lock"
_LOCKS: dict = {}  # resolved folder -> its FileLock: one object per folder, so a process re-enters its own lock


class RunFolderError(ValueError):
    """A run folder that this run must not write into or resume from, with what to do instead."""


def run_lock(run_dir):
    """A context manager holding RUN_DIR's lock (re-entrant within a process); RunFolderError at once when another
    process holds it."""
    from contextlib import contextmanager

    from filelock import FileLock, Timeout

    folder = Path(run_dir).resolve()

    @contextmanager
    def held():
        folder.mkdir(parents=True, exist_ok=True)
        lock = _LOCKS.setdefault(folder, FileLock(str(folder / LOCK_NAME)))
        try:
            lock.acquire(timeout=0)
        except Timeout:
            raise RunFolderError(f"another training run is writing into {folder} (it holds {folder / LOCK_NAME}); wait "
                                 "for it to end, or give this run another --out") from None
        try:
            yield folder
        finally:
            lock.release()
    return held()


def check_new_folder(out) -> None:
    """RunFolderError when ``out`` holds files (other than the lock) and the run is not a resume."""
    out = Path(out)
    if not out.exists():
        return
    if not out.is_dir():
        raise RunFolderError(f"--out {out} is a file, not a folder")
    found = sorted(p.name for p in out.iterdir() if p.name != LOCK_NAME)
    if found:
        shown = ", ".join(found[:4]) + (", ..." if len(found) > 4 else "")
        raise RunFolderError(f"--out {out} is not empty ({shown}): a new run would overwrite that run's files; "
                             f"go on with it (--resume {out}), or give an empty or new folder")


def checkpoint_steps(path: Path) -> int:
    part = Path(path).stem.split("_")[-2]
    return int(part) if part.isdigit() else -1


def damage(path: Path) -> str | None:
    """Why the checkpoint zip at ``path`` cannot be loaded (truncated, not a zip, a member failing its CRC), or
    None when it is whole."""
    try:
        with zipfile.ZipFile(path) as z:
            bad = z.testzip()
            if bad is not None:
                return f"its member {bad} fails its checksum"
            if "data" not in z.namelist():
                return "it holds no SB3 model data"
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        return f"{type(exc).__name__}: {exc}"
    return None


def intact_checkpoint(path, say=print) -> Path:
    """The checkpoint to resume from: PATH itself (a .zip, which must be whole), or the newest whole checkpoint of a
    run folder (PATH/checkpoints/model_<steps>_steps.zip, by steps), saying through ``say`` which newer ones it
    skipped and why. RunFolderError if there is none."""
    path = Path(path)
    if path.is_file():
        why = damage(path)
        if why is not None:
            raise RunFolderError(f"resume: {path} cannot be loaded ({why}); give a run folder to resume from its "
                                 "newest intact checkpoint")
        return path
    found = sorted(Path(path, "checkpoints").glob("model_*_steps.zip"), key=checkpoint_steps, reverse=True)
    if not found:
        raise RunFolderError(f"resume: {path} is neither a model .zip nor a run folder with "
                             "checkpoints/model_*_steps.zip")
    for ckpt in found:
        why = damage(ckpt)
        if why is None:
            return ckpt
        say(f"[train] checkpoint {ckpt.name} is damaged ({why}; a run stopped while saving it?): "
            "falling back to the one before")
    raise RunFolderError(f"resume: every checkpoint under {Path(path, 'checkpoints')} is damaged; start a new run")


def _saved_n_envs(checkpoint: Path) -> int | None:
    """n_envs as SB3 saved it in the checkpoint's data (None if unreadable)."""
    try:
        with zipfile.ZipFile(checkpoint) as z:
            return int(json.loads(z.read("data"))["n_envs"])
    except (KeyError, ValueError, TypeError, OSError, zipfile.BadZipFile):
        return None


def resume_changes(checkpoint: Path, run: dict) -> list[str]:
    """What this run (``run``: env_id, algo, seed, num_envs, hyperparameters, as training.runner's config.json)
    would change against the run that wrote ``checkpoint`` (its folder's config.json, and the n_envs saved in the
    zip): one line per field. A resumed SB3 model keeps its saved hyperparameters and rollout size whatever the new
    run asks, so a change would be ignored, or mix two runs in one."""
    changes = []
    n_envs = _saved_n_envs(checkpoint)
    if n_envs is not None and n_envs != run["num_envs"]:
        changes.append(f"num_envs: the checkpoint was trained with {n_envs} envs, this run asks for {run['num_envs']} "
                       f"(PPO's rollout n_steps x num_envs, the envs' seeds and SAC's steps per update would change)")
    saved = Path(checkpoint).resolve().parent.parent / "config.json"
    try:
        before = json.loads(saved.read_text())
    except (OSError, ValueError):
        return changes
    now = json.loads(json.dumps(run))  # (as config.json holds it: tuples as lists)
    for key in ("env_id", "algo", "seed", "hyperparameters"):
        if key in before and before[key] != now.get(key):
            changes.append(f"{key}: {before[key]!r} in {saved}, {now.get(key)!r} now")
    if "num_envs" in before and before["num_envs"] != now["num_envs"] and n_envs is None:
        changes.append(f"num_envs: {before['num_envs']} in {saved}, {now['num_envs']} now")
    return changes


def check_resume(checkpoint: Path, run: dict) -> None:
    """RunFolderError listing :func:`resume_changes`, with what to do."""
    changes = resume_changes(checkpoint, run)
    if changes:
        raise RunFolderError(f"--resume {checkpoint}: this run differs from the one it goes on from: "
                             + "; ".join(changes) + ". Resume with the same settings (only total_timesteps may change), "
                             "or start a new run in another --out")
