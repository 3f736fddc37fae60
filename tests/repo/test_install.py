"""The package as users install it: the wheel's contents, a read-only install run by a user who cannot
write it (a Docker image installed as root and run as ``USER app``, a shared site-packages), and numba's cache
never serving machine code compiled from older sources, wherever numba keeps it (NUMBA_CACHE_DIR)."""
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import textwrap
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def copy_package(dest: Path) -> Path:
    """A copy of the checkout's package sources (no caches) with training/ and lab/ (the wheel must leave them out),
    pyproject.toml, README.md and the files the sdist and the wheel's metadata take (LICENSE, ...)."""
    dest.mkdir(parents=True, exist_ok=True)
    for folder in ("penny_env", "training", "lab"):
        shutil.copytree(ROOT / folder, dest / folder, ignore=shutil.ignore_patterns("__pycache__", "_generated", "*.nbi", "*.nbc",
                                                                                   "*.stamp"))
    for name in ("pyproject.toml", "README.md", "LICENSE", "MANIFEST.in", "CHANGELOG.md", "CITATION.cff"):
        shutil.copy(ROOT / name, dest / name)
    return dest


@pytest.fixture(scope="module")
def workdir():
    """A temporary folder every user can enter (pytest's own tmp folders are private to root)."""
    path = Path(tempfile.mkdtemp(prefix="penny_install_"))
    path.chmod(0o755)
    yield path
    for p in [path, *path.rglob("*")]:  # undo the read-only modes before removing
        if not p.is_symlink():
            p.chmod(p.stat().st_mode | stat.S_IWUSR)
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope="session")
def wheel(tmp_path_factory):
    """The wheel built from a copy of this checkout (pip wheel, no build isolation: no network), once per test run:
    the first test worker to need it builds it in the run's shared temporary folder, under a lock, and the others
    take that one."""
    import fcntl
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # (the workers' common folder)
    dist = shared / "penny_env_wheel"
    with open(shared / "penny_env_wheel.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        built = sorted(dist.glob("penny_env-*.whl"))
        if not built:
            work = Path(tempfile.mkdtemp(prefix="penny_wheel_src_"))
            try:
                out = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                                      "-w", str(dist), str(copy_package(work / "src"))], capture_output=True, text=True,
                                     timeout=300)
            finally:
                shutil.rmtree(work, ignore_errors=True)
            if out.returncode != 0:
                pytest.skip(f"cannot build a wheel here: {out.stderr[-500:]}")
            built = sorted(dist.glob("penny_env-*.whl"))
    return built[0]


def test_the_wheel_ships_penny_env_with_its_data_and_no_top_level_training(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    tops = {n.split("/")[0] for n in names}
    assert tops == {"penny_env", next(t for t in tops if t.endswith(".dist-info"))}, tops  # no training, lab, tests
    # everything the package reads at run time: every module, preset and reference data file of the checkout
    # (not the source the backends generate where they run: backends/_generated, git-ignored)
    needed = {p.relative_to(ROOT).as_posix() for p in (ROOT / "penny_env").rglob("*")
              if p.suffix in (".py", ".yaml", ".json") and "__pycache__" not in p.parts and "_generated" not in p.parts}
    assert needed and needed <= names, sorted(needed - names)
    assert not [n for n in names if "_generated" in n]
    # the metadata: the one version (penny_env.__version__), the license and its file
    import penny_env
    info = next(n for n in names if n.endswith(".dist-info/METADATA"))
    metadata = zipfile.ZipFile(wheel).read(info).decode()
    assert f"\nVersion: {penny_env.__version__}\n" in metadata and "\nLicense-Expression: MIT\n" in metadata
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)


def unprivileged_prefix():
    """The command prefix that runs a process unable to write where file modes forbid it: nothing for a
    normal user; as root (which ignores file modes), setpriv dropping every capability (the interpreter
    may live under /root, which another user could not run, so the uid stays and the privilege goes)."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: cannot drop the privilege to ignore file modes")
    return ["setpriv", "--inh-caps=-all", "--bounding-set=-all", "--"]


def _read_only(path: Path):
    for p in [*path.rglob("*"), path]:
        p.chmod(0o555 if p.is_dir() else 0o444)


# the open plane: the cheapest shape to compile (no wall, no event loop), every entry point of a table (the single
# env, the vector env, the batch loops) all the same
USE = """
    import sys
    import numpy as np
    import gymnasium as gym
    import penny_env, penny_env.batch as pb
    assert penny_env.__file__.startswith(sys.argv[1]), penny_env.__file__  # the installed copy
    env = gym.make("PennyReach-Plane-v0")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    venv = gym.make_vec("PennyReach-Plane-v0", num_envs=8)
    venv.reset(seed=0)
    venv.step(venv.action_space.sample())
    S = np.zeros((8, 6)); S[:, 4] = 8.0; S[:, 3] = np.linspace(0, 6, 8)
    res = pb.simulate(S, table=None, t_final=5.0)
    assert np.isfinite(res.final_states).all() and np.abs(res.final_states[:, :2]).max() > 0.1  # (rolled off)
    print("ok")
"""


def run_unprivileged(code, site: Path, home: Path, cwd: Path):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "XDG_", "PYTHON"))}
    env.update(PYTHONPATH=str(site), HOME=str(home))
    return subprocess.run(unprivileged_prefix() + [sys.executable, "-c", textwrap.dedent(code), str(site)], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
def test_a_read_only_install_run_by_another_user_compiles_caches_and_loads(wheel, workdir):
    pytest.importorskip("numba")
    site = workdir / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=300)
    _read_only(site)
    home = workdir / "home"
    home.mkdir()
    first = run_unprivileged(USE, site, home, home)
    assert first.returncode == 0 and "ok" in first.stdout, first.stderr[-3000:]
    # the first use compiled, said so once per entry point, and cached in numba's user-wide cache directory
    assert first.stderr.count("penny_env: compiling the single env step for table open plane") == 1, first.stderr
    assert "compiling the vector env step for table open plane" in first.stderr
    cached = list((home / ".cache" / "numba").rglob("*.nbi"))
    assert any("plane" in p.name for p in cached), cached
    assert not any(site.rglob("*.nbi"))  # nothing written into the install
    second = run_unprivileged(USE, site, home, home)  # loads the cache: no compile notice
    assert second.returncode == 0 and "ok" in second.stdout, second.stderr[-3000:]
    assert "penny_env: compiling" not in second.stderr, second.stderr


def test_with_no_writable_cache_location_at_all_the_env_still_compiles(workdir):
    """A read-only package and an unwritable home: numba has no cache locator; penny_env compiles
    without the disk cache and says so, rather than raising 'cannot cache function'."""
    pytest.importorskip("numba")
    src = copy_package(workdir / "nocache")
    _read_only(src)
    code = """
        import sys
        import gymnasium as gym
        import penny_env
        assert penny_env.__file__.startswith(sys.argv[1])
        env = gym.make("PennyReach-Plane-v0")
        env.reset(seed=0)
        env.step(env.action_space.sample())
        print("ok")
    """
    home = workdir / "readonly_home"
    home.mkdir()
    home.chmod(0o555)
    out = run_unprivileged(code, src, home, workdir)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr[-3000:]
    assert "no writable cache directory" in out.stderr


REWARD = """
    import gymnasium as gym
    import penny_env
    rewards = []
    for backend in ("numba", "python"):
        env = gym.make("PennyReach-Plane-v0", backend=backend)
        env.reset(seed=0)
        rewards.append(env.step([0.5, 0.5])[1])
    print(repr(rewards[0]), repr(rewards[1]))
"""


@pytest.mark.slow
def test_an_edited_task_module_is_recompiled_with_numba_cache_dir_set(tmp_path):
    """Edit tasks.py's reward in a copy of the package that caches in NUMBA_CACHE_DIR: the compiled env
    gives the new reward, as backend="python" does (it kept the old one when only the cached function's
    own file was checked)."""
    pytest.importorskip("numba")
    src = copy_package(tmp_path / "src")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def rewards():
        out = subprocess.run([sys.executable, "-c", textwrap.dedent(REWARD)], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]
        return [float(v) for v in out.stdout.split()]

    compiled, python = rewards()
    assert compiled == python
    tasks = src / "penny_env" / "step" / "tasks" / "reach.py"
    old = "    return progress(k, before, after) - k.ctrl_cost * ctrl + k.success_bonus * success, success\n"
    assert tasks.read_text().count(old) == 1
    tasks.write_text(tasks.read_text().replace(old, old.replace("success, success", "success + 1000.0, success")))
    compiled2, python2 = rewards()
    assert python2 == python + 1000.0
    assert compiled2 == python2


def test_every_cached_compiled_function_is_named_after_the_sources_it_inlines():
    """Siblings of the NUMBA_CACHE_DIR test: for every table kind, every compiled entry point of the
    physics (batch API) and of the env step (single and vector env) carries the digest of all the
    modules it inlines in its name, after which numba names its cache files."""
    pytest.importorskip("numba")
    from penny_env.backends import batch_entry_points, cache
    from penny_env.backends.env import env_entry_points, env_modules
    from penny_env.backends.physics import physics_modules
    from penny_env.envs.core import Core
    from penny_env.envs.scene import resolve
    from penny_env.physics.tables import COMPILED_FORMULAS

    physics = cache.source_digest(physics_modules())
    for task in ("reach", "park", "impacts"):
        core = Core(*resolve("ellipse", task), backend="python")
        env = cache.source_digest(env_modules(core.task_record))
        assert physics != env
        for kind in range(-1, len(COMPILED_FORMULAS)):
            entry = env_entry_points("cpu", kind, core.task_record, type(core.k))
            fns = [(physics, name, f) for name, f in batch_entry_points("cpu", kind).functions.items()]
            fns += [(env, name, getattr(entry, name)) for name in ("env_step", "initial_state", "observe_state",
                                                                     "step_envs", "reset_rows", "observe_rows")]
            for digest, name, f in fns:
                f = f if hasattr(f, "py_func") else f.__wrapped__  # the parallel calls' lock
                assert f.py_func.__qualname__.endswith(f"_{digest}"), (kind, name, f.py_func.__qualname__)
