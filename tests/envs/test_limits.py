"""Numbers at the limits are refused up front with the field's name (issue 31, deliverable 5; envs/limits.py):
integers beyond int64, a num_envs the machine cannot hold (saying how much it needs), torque limits that leave
no room for the scene's initial speeds (blaming the field the user set), and YAML's 1e-2."""
import math
import os
import tracemalloc

import gymnasium as gym
import numpy as np
import pytest

import penny_env as pe
from penny_env.envs import limits
from penny_env.envs.scene import ConfigError, resolve
from penny_env.physics import SolverSettings

BIG = 2 ** 63


@pytest.mark.fast
def test_max_episode_steps_beyond_int64_names_the_field():
    # repro_steps_overflow: passed the check, then "OverflowError: Python int too large to convert to C long"
    with pytest.raises(ConfigError, match=r"task\.max_episode_steps must be <= 2\*\*63 - 1"):
        pe.PennyEnv("ellipse", "reach", max_episode_steps=BIG)
    with pytest.raises(ConfigError, match=r"task\.max_episode_steps must be <= 2\*\*63 - 1"):
        pe.PennyVectorEnv(2, max_episode_steps=BIG)
    with pytest.raises(ConfigError, match=r"task\.impacts_goal must be <= 2\*\*63 - 1"):
        pe.PennyEnv("ellipse", "impacts", impacts_goal=BIG)
    env = pe.PennyEnv("ellipse", "reach", max_episode_steps=BIG - 1, backend="python")  # (int64's max itself works)
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))


@pytest.mark.fast
@pytest.mark.parametrize("n", [10 ** 19, BIG])
def test_num_envs_beyond_int64_names_the_field(n):
    # num_envs = 1e19 gave an OverflowError
    with pytest.raises(ValueError, match=r"num_envs must be <= 2\*\*63 - 1"):
        pe.PennyVectorEnv(n)
    with pytest.raises(ValueError, match=r"num_envs must be <= 2\*\*63 - 1"):
        gym.make_vec("penny_env:PennyReach-Ellipse-v0", num_envs=n)


def test_other_integers_beyond_int64_name_their_field():
    for name in ("max_search_steps", "zeno_impacts", "max_events_per_interval", "max_impacts"):
        with pytest.raises(ValueError, match=rf"SolverSettings\.{name} must be <= 2\*\*63 - 1"):
            SolverSettings(**{name: BIG})
    for cls in (pe.PennyEnv, lambda **kw: pe.PennyVectorEnv(2, **kw)):
        with pytest.raises(ValueError, match=r"max_impacts_in_info must be <= 2\*\*63 - 1"):
            cls(max_impacts_in_info=BIG)
    with pytest.raises(ValueError, match=r"seed must be < 2\*\*64"):
        pe.PennyEnv(backend="python").reset(seed=2 ** 64)
    env = pe.PennyEnv(backend="python")
    assert env.reset(seed=2 ** 64 - 1)[0].shape == (10,)  # (seeds span uint64: the episode keys)


def test_a_num_envs_beyond_the_memory_says_how_much_it_needs(monkeypatch):
    # num_envs = 1e7 allocated 4.5 GiB on the trial's machine, then died in step() with a MemoryError after 87 s
    monkeypatch.setattr(limits, "available_memory", lambda: 2 ** 30)
    per = limits.vector_env_bytes(10, 8)
    with pytest.raises(ValueError, match=r"num_envs = 10000000: a PennyVectorEnv of that many envs \(\d+ B per env "
                                         r"with max_impacts_in_info = 8; use fewer envs per process\) needs about "
                                         r"[0-9.]+ GiB, more than the 1 GiB of memory available"):
        pe.PennyVectorEnv(10 ** 7)
    assert per * 10 ** 7 > 2 ** 30
    with pytest.raises(ValueError, match=r"max_impacts_in_info = 8000000000: PennyEnv's impact buffers needs"):
        pe.PennyEnv(max_impacts_in_info=8 * 10 ** 9)
    pe.PennyVectorEnv(1000, backend="python")  # (what fits is built)


def test_the_available_memory_is_read():
    have = limits.available_memory()
    assert have is None or 2 ** 20 < have < 2 ** 50


def _fake_machine(root, meminfo_kib, cgroup=None, v1=None, vmsize_kib=None):
    """A /proc and /sys under root: MemAvailable, the process's cgroup file and limits."""
    (root / "proc/self").mkdir(parents=True)
    (root / "proc/meminfo").write_text(f"MemTotal: 99999999 kB\nMemAvailable: {meminfo_kib} kB\n")
    (root / "proc/self/status").write_text(f"Name: python\nVmSize: {vmsize_kib or 0} kB\n")
    lines = ["0::/job"] + (["4:memory:/batch/job"] if v1 else [])
    (root / "proc/self/cgroup").write_text("\n".join(lines) + "\n")
    if cgroup is not None:  # v2: the job's cgroup under a parent without a limit
        d = root / "sys/fs/cgroup/job"
        d.mkdir(parents=True)
        (root / "sys/fs/cgroup/memory.max").write_text("max\n")
        (d / "memory.max").write_text(f"{cgroup[0]}\n")
        (d / "memory.current").write_text(f"{cgroup[1]}\n")
    if v1 is not None:  # v1: the limit is set on the parent cgroup (batch), the job's own says "no limit"
        for rel, limit, usage in (("batch", v1[0], v1[1]), ("batch/job", 9223372036854771712, v1[1])):
            d = root / "sys/fs/cgroup/memory" / rel
            d.mkdir(parents=True)
            (d / "memory.limit_in_bytes").write_text(f"{limit}\n")
            (d / "memory.usage_in_bytes").write_text(f"{usage}\n")


def test_the_memory_left_reads_the_cgroup_limits_too(tmp_path):
    # MemAvailable 64 GiB, but the job's cgroup allows 2 GiB with 0.5 GiB used: 1.5 GiB left
    from penny_env.backends.memory import memory_left
    gib = 2 ** 30
    _fake_machine(tmp_path / "v2", 64 * 2 ** 20, cgroup=(2 * gib, gib // 2))
    assert memory_left(tmp_path / "v2") == (3 * gib // 2, "the cgroup's memory limit")
    _fake_machine(tmp_path / "v1", 64 * 2 ** 20, v1=(3 * gib, gib))
    assert memory_left(tmp_path / "v1") == (2 * gib, "the cgroup's memory limit")
    _fake_machine(tmp_path / "none", 64 * 2 ** 20)
    assert memory_left(tmp_path / "none") == (64 * gib, "MemAvailable")


def test_the_memory_left_reads_the_address_space_limit(tmp_path, monkeypatch):
    # ulimit -v 4 GiB with 1 GiB mapped: 3 GiB left, though MemAvailable says 64 GiB
    resource = pytest.importorskip("resource", reason="RLIMIT_AS is POSIX")
    from penny_env.backends.memory import memory_left
    gib = 2 ** 30
    _fake_machine(tmp_path, 64 * 2 ** 20, vmsize_kib=2 ** 20)
    monkeypatch.setattr(resource, "getrlimit", lambda which: (4 * gib, resource.RLIM_INFINITY))
    assert memory_left(tmp_path) == (3 * gib, "the address-space limit RLIMIT_AS, ulimit -v")


def test_a_num_envs_beyond_the_address_space_limit_is_refused_up_front(monkeypatch):
    # the run: under ulimit -v, num_envs = 5e6 was accepted and numpy's MemoryError came 137 s later
    resource = pytest.importorskip("resource", reason="RLIMIT_AS is POSIX")
    if not os.path.exists("/proc/self/status"):
        pytest.skip("the mapped size is read from /proc/self/status (Linux)")
    with open("/proc/self/status") as f:
        mapped = next(int(ln.split()[1]) * 1024 for ln in f if ln.startswith("VmSize:"))
    monkeypatch.setattr(resource, "getrlimit", lambda which: (mapped + 2 ** 30, resource.RLIM_INFINITY))
    with pytest.raises(ValueError, match=r"num_envs = 5000000: .* more than the [0-9.]+ [GM]iB of memory available to "
                                         r"this process .*ulimit -v"):
        pe.PennyVectorEnv(5 * 10 ** 6, backend="python")


@pytest.mark.parametrize("scene, task, K", [("ellipse", "reach", 8), ("stadium", "impacts", 32)])
def test_the_memory_estimate_matches_what_the_env_allocates(scene, task, K):
    # tracemalloc (numpy reports its buffers) over construction, a reset and steps, per env, against the estimate
    n = 20000
    # compiled code and caches outside the measure: the same size's loops (the parallel ones above SERIAL_BELOW) run
    # once first, so that no compile (its Python objects) falls inside it whatever ran before in the process
    warm = pe.PennyVectorEnv(n, scene, task, max_impacts_in_info=K)
    warm.reset(seed=1)
    warm.step(np.full((n, 2), 0.5))
    warm.close()
    del warm
    tracemalloc.start()
    try:
        env = pe.PennyVectorEnv(n, scene, task, max_impacts_in_info=K)
        env.reset(seed=0)
        kept = [env.step(np.full((n, 2), 0.5)) for _ in range(2)]  # (the caller keeps the previous step's outputs)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    estimate = limits.vector_env_bytes(11 if task == "impacts" else 10, K)
    measured = peak / n
    assert kept and 0.6 * estimate < measured < 1.4 * estimate, (measured, estimate)


def test_a_torque_limit_at_the_steered_phase_limit_blames_the_torque():
    # repro_phase_msg: accepted by its own check, then "scene.init.phi_dot = [-1.0, 1.0] rad/s: |phi_dot| must be
    # <= -2.27374e-13 rad/s", blaming a field the user never set
    with pytest.raises(ConfigError, match=r"scene\.torque_limits\.u1 = 1\.25e-05 N m sweeps 20000 rad of heading in one "
                                          r"control_dt, at or beyond the limit MAX_STEERED_PHASE"):
        gym.make("penny_env:PennySteer-Plane-v0", control_dt=10.0, torque_limits={"u1": 1.25e-5})


def test_a_torque_limit_that_leaves_too_little_room_blames_the_torque_unless_init_was_set():
    kw = dict(control_dt=10.0, torque_limits={"u1": 1.2499e-5})
    with pytest.raises(ConfigError, match=r"scene\.torque_limits\.u1 = 1\.2499e-05 N m with control_dt = 10\.0 s leaves "
                                          r"room for \|phi_dot\| <= 0\.16 rad/s only.*default init\.phi_dot"):
        resolve("plane", "reach", actuation="steer", **kw)
    with pytest.raises(ConfigError, match=r"scene\.init\.phi_dot = \[-2\.0, 2\.0\] rad/s: \|phi_dot\| must be <= 0\.16 "
                                          r"rad/s, so that a step at torque_limits\.u1 = 1\.2499e-05 N m"):
        resolve("plane", "reach", actuation="steer", init={"phi_dot": [-2.0, 2.0]}, **kw)
    resolve("plane", "reach", actuation="steer", init={"phi_dot": [-0.1, 0.1]}, **kw)  # (room enough)
    with pytest.raises(ConfigError, match=r"scene\.torque_limits\.u2 = 0\.0375 N m with control_dt = 1\.0 s leaves room "
                                          r"for \|theta_dot\| <= 0 rad/s only"):
        resolve("circle", "reach", actuation="drive", control_dt=1.0, torque_limits={"u2": 0.0375})


@pytest.mark.fast
def test_yaml_1e_minus_2_reads_as_a_float(tmp_path):
    # PyYAML (YAML 1.1) reads 1e-2 as the string '1e-2': "scene.control_dt must be a number, got '1e-2'"
    path = tmp_path / "scene.yaml"
    path.write_text("table: {kind: circle, r: 15e-2}\ncontrol_dt: 1e-2\ntorque_limits: {u1: 6.25E-7}\n")
    scene, _ = resolve(str(path), "reach")
    assert scene.control_dt == 0.01 and scene.table["r"] == 0.15 and scene.torque_limits["u1"] == 6.25e-7
    from penny_env.envs.yaml_io import safe_load
    assert safe_load("a: 1e-2\nb: 3\nc: '1e-2'\nd: .inf\ne: 1_000\n") == {"a": 0.01, "b": 3, "c": "1e-2", "d": math.inf,
                                                                          "e": 1000}


@pytest.mark.fast
def test_a_number_given_as_a_string_says_so():
    with pytest.raises(ConfigError, match=r"scene\.control_dt must be a number, got '1e-2' \(a string: write the number "
                                          r"unquoted"):
        resolve("ellipse", "reach", control_dt="1e-2")


def test_training_configs_read_1e_minus_2_as_a_float(tmp_path):
    from training.train import load_config
    path = tmp_path / "run.yaml"
    path.write_text("env_id: PennyReach-Ellipse-v0\nalgo: ppo\nalgo_kwargs: {learning_rate: 3e-4}\n")
    assert load_config(path)["algo_kwargs"]["learning_rate"] == 3e-4
    from studies.witness import parse_overrides
    assert parse_overrides(["tolerance=1e-2"]) == {"tolerance": 0.01}
