"""GPU throughput of the vector env, like for like: every column steps the same actions from the same saved state.

``python -m devtools.throughput_gpu [--quick] [--out PATH] [--ids ID ...] [--sizes N ...] [--window 32]
[--steady-after 300] [--variants] [--variant-sizes N ...] [--no-cpu] [--cpu-sizes N ...] [--ppo-sizes N ...]``

For each id (default: PennyReach-Ellipse-v0, PennyImpacts-Stadium-v0 and the single-input probe
PennyProbeSteer-Stadium-Elastic-v0) and each N (default 4096, 65,536, 1M, 4M), a PennyVectorEnv(N, backend="cuda")
with torch outputs is reset with seed 0 and its state saved (the **fresh** window's start); it then steps
``--steady-after`` (>= 300) steps of random actions and its state is saved again (the **steady** window's start).
One sequence of ``--window`` action sets is drawn beforehand (uniform in the action box, float32, on the device;
the same numbers on the host for the CPU). Every column restores the window's saved state and steps that
sequence, timed with a synchronization at each end:

* ``env.step``: the step as users call it (the actions' copy into the env's buffer, the kernels, the outputs and
  the info dict): Isaac Lab's "env only" column;
* kernels alone: the actions' copy on the device and the step's prepared launches (backends/cuda_env.DeviceStep),
  no Python around them;
* graph replay: backends/cuda_env.CudaGraphStep (one step captured in a CUDA graph, replayed per action set);
* env + policy: env.step and, per step, the inference of a 64x64 tanh MLP policy on the step's observation (its
  actions written to a rollout buffer; the env steps the sequence's actions, so that its work is the other columns');
* env + PPO: a rollout of the window (the policy's log-probabilities and values of the sequence's actions, the
  env's step, the buffer's writes), then GAE and a PPO update (PolicyColumns: 4 epochs of 4 minibatches)
  on it, per env-step of the rollout;
* the CPU backend (numba, every core of the machine) from the same state, on the same actions;
* ``--variants``: the kernels alone of the step built other ways (one kernel; the split step without a register
  cap; capped at 64), each restoring the same state and stepping the same actions.

Each window's rare share is the share of its env-steps that the fast kernel left to the rare kernel (the rare
list's length read after each step of an untimed pass over the same steps), and the final states of the columns
are compared bitwise (``same end state``; the CPU's not: on a GPU fused multiply-adds and libdevice's sin and cos
differ from the CPU's in the last bits, docs/gpu.md). Every row names its window in its own text.

Without a GPU the command says so and writes no report; ``--quick`` runs the whole table under numba's CUDA
simulator at tiny N (NUMBA_ENABLE_CUDASIM=1: numba device arrays instead of torch tensors on the GPU, the policy
and PPO columns on the CPU's torch, no graph replay), which the tests use: its numbers time nothing about a GPU.
Targets, steady window: env.step at least 1e9 env-steps/s on PennyReach-Ellipse-v0 and 5e8 on
PennyImpacts-Stadium-v0 at the best N, 1.2e7 at N = 4096, at least 0.8 of its own kernels alone.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np

SIZES = (4096, 65536, 1_048_576, 4_194_304)
IDS = ("PennyReach-Ellipse-v0", "PennyImpacts-Stadium-v0", "PennyProbeSteer-Stadium-Elastic-v0")
VARIANTS = ({"kernels": "one"}, {"kernels": "split", "max_registers": None}, {"kernels": "split", "max_registers": 64})
WINDOW = 32
STEADY_AFTER = 300
PPO_EPOCHS, PPO_MINIBATCHES = 4, 4
TARGETS = {"PennyReach-Ellipse-v0": 1e9, "PennyImpacts-Stadium-v0": 5e8}


def gpu_here() -> str | None:
    """The GPU's name where numba-cuda and torch see a real CUDA device, else None."""
    import importlib.util
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" or importlib.util.find_spec("numba_cuda") is None:
        return None
    try:
        import torch
        from numba import cuda
        if not (cuda.is_available() and torch.cuda.is_available()):
            return None
        return torch.cuda.get_device_name(0)
    except Exception:  # noqa: BLE001 (a broken driver: no GPU)
        return None


def simulated() -> bool:
    return os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"


class Device:
    """What differs between a GPU and numba's CUDA simulator: the actions' arrays, the outputs, synchronization."""

    def __init__(self, sim: bool):
        from numba import cuda
        self.sim, self.cuda = sim, cuda
        try:
            import torch
        except ImportError:
            torch = None
        self.torch = torch
        self.outputs = "device" if sim else "torch"

    def sync(self):
        if self.sim:
            self.cuda.synchronize()
        else:
            self.torch.cuda.synchronize()

    def upload(self, host):
        """A (T, N, k) float32 host array on the device, indexable per step (float64 numba arrays in simulation:
        the env takes numba device actions as float64)."""
        if self.sim:
            return [self.cuda.to_device(np.ascontiguousarray(a, dtype=np.float64)) for a in host]
        return self.torch.as_tensor(host, device="cuda")

    def random_actions(self, n, k, seed):
        """A function t -> random actions on the device (the steps before the steady window)."""
        if self.sim:
            rng = np.random.default_rng(seed)
            return lambda t: self.cuda.to_device(rng.uniform(-1.0, 1.0, (n, k)))
        g = self.torch.Generator(device="cuda").manual_seed(seed)
        return lambda t: self.torch.rand((n, k), device="cuda", generator=g) * 2 - 1

    def to_torch(self, x):
        """A step's output as a torch tensor (on the GPU; the host's torch in simulation)."""
        if self.sim:
            return self.torch.as_tensor(np.asarray(x.copy_to_host(), dtype=np.float32))
        if not isinstance(x, self.torch.Tensor):  # a numba device array (the reset's buffer): zero-copy view
            x = self.torch.as_tensor(x, device="cuda")
        return x.float() if x.dtype != self.torch.float32 else x

    def copy_actions(self, dev, a):
        """The actions' copy into the env's buffer, on the device (what env.step does before its launches)."""
        if self.sim:
            dev.actions.copy_to_device(a, stream=dev.stream())
        else:
            dev._actions_t().copy_(a)

    @property
    def torch_device(self):
        return "cpu" if self.sim else "cuda"


def make(env_id, n, device: Device, **cuda_options):
    import gymnasium as gym

    import penny_env  # noqa: F401 (registers the ids)
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", backend="cuda",
                        outputs=device.outputs, cuda_options=cuda_options or None).unwrapped


def restore(env, state):
    """The env's state set to ``state`` (functional.EnvState of numpy arrays: a copy goes in)."""
    from penny_env.step.functional import EnvState
    env._runner.state_from_host(EnvState(*(np.array(a, copy=True) for a in state)))
    env._limits = None


def end_state(env):
    return env._runner.state_to_host().S.copy()


def saved_states(env, device: Device, steady_after: int) -> dict:
    """{"fresh": the state right after reset(seed=0), "steady": after steady_after random steps}."""
    k = env.single_action_space.shape[0]
    env.reset(seed=0)
    out = {"fresh": env._runner.state_to_host()}
    draw = device.random_actions(env.num_envs, k, seed=12345)
    for t in range(steady_after):
        env.step(draw(t))
    device.sync()
    out["steady"] = env._runner.state_to_host()
    return out


def timed(device: Device, start, step, steps: int) -> float:
    """Seconds of steps calls of step(t) after start(), with a synchronization at both ends."""
    start()
    device.sync()
    t0 = time.perf_counter()
    for t in range(steps):
        step(t)
    device.sync()
    return time.perf_counter() - t0


def rare_share(env, device: Device, state, acts, steps: int) -> float:
    """The share of env-steps the fast kernel left to the rare kernel over the window (an untimed pass)."""
    restore(env, state)
    dev = env._runner
    listed = 0
    for t in range(steps):
        env.step(acts[t])
        listed += int(dev.work_count.copy_to_host()[0])
    return listed / (steps * env.num_envs)


class PolicyColumns:
    """The policy of the env + policy and env + PPO columns: a PPO agent of CleanRL's shape, written out here (the
    tools measure the env beside an agent's work and import no agent): 64x64 tanh MLPs for the actions' mean and
    the value, a state-independent log std, GAE, and PPO_EPOCHS epochs of PPO_MINIBATCHES clipped-objective
    minibatch updates (Adam 3e-4, gradient norm 0.5), the work per step of the ladder's training.ppo_torch."""

    def __init__(self, device: Device, obs_dim: int, act_dim: int, n: int, steps: int, rollout: bool):
        torch = device.torch
        nn = torch.nn
        self.torch, self.device = torch, device
        torch.manual_seed(0)

        def mlp(n_out, gain):
            layers = [nn.Linear(obs_dim, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, n_out)]
            for k, layer in enumerate(x for x in layers if isinstance(x, nn.Linear)):
                nn.init.orthogonal_(layer.weight, gain if k == 2 else 2 ** 0.5)
                nn.init.zeros_(layer.bias)
            return nn.Sequential(*layers).to(device.torch_device)
        self.mean, self.value = mlp(act_dim, 0.01), mlp(1, 1.0)
        self.log_std = nn.Parameter(torch.zeros(1, act_dim, device=device.torch_device))
        params = [*self.mean.parameters(), *self.value.parameters(), self.log_std]
        self.params, self.optimizer = params, torch.optim.Adam(params, lr=3e-4, eps=1e-5)
        self.minibatch = max(1, steps * n // PPO_MINIBATCHES)
        z = lambda *shape: torch.zeros(shape, device=device.torch_device)  # noqa: E731
        self.out = z(n, act_dim)
        if not rollout:
            return
        self.obs, self.actions = z(steps, n, obs_dim), z(steps, n, act_dim)
        self.logprobs, self.values, self.rewards, self.dones = z(steps, n), z(steps, n), z(steps, n), z(steps, n)

    def _logprob_value(self, x, a):
        dist = self.torch.distributions.Normal(self.mean(x), self.log_std.exp())
        return dist.log_prob(a).sum(-1), dist.entropy().sum(-1), self.value(x).squeeze(-1)

    def infer(self, obs):
        with self.torch.no_grad():
            self.out.copy_(self.mean(self.device.to_torch(obs)).clamp(-1.0, 1.0))

    def record(self, t, obs, acts_t):
        """The rollout's writes before step t: the observation, the sequence's action, its log-probability and value."""
        x = self.device.to_torch(obs)
        a = self.device.to_torch(acts_t) if self.device.sim else acts_t.float()
        with self.torch.no_grad():
            logprob, _, value = self._logprob_value(x, a)
        self.obs[t].copy_(x)
        self.actions[t].copy_(a)
        self.logprobs[t].copy_(logprob)
        self.values[t].copy_(value)

    def after_step(self, t, reward, terminated, truncated):
        r, te, tu = (self.device.to_torch(v) for v in (reward, terminated, truncated))
        self.rewards[t].copy_(r)
        self.dones[t].copy_(self.torch.maximum(te, tu))

    def update(self, last_obs, gamma=0.99, lam=0.95, clip=0.2):
        torch = self.torch
        with torch.no_grad():  # GAE, backwards over the window
            adv = torch.zeros_like(self.rewards)
            last = torch.zeros_like(self.rewards[0])
            following = self.value(self.device.to_torch(last_obs)).squeeze(-1)
            for t in reversed(range(self.rewards.shape[0])):
                keep = 1.0 - self.dones[t]
                last = self.rewards[t] + gamma * following * keep - self.values[t] + gamma * lam * keep * last
                adv[t], following = last, self.values[t]
            ret = adv + self.values
        d = self.obs.shape[-1]
        obs, acts = self.obs.reshape(-1, d), self.actions.reshape(-1, self.actions.shape[-1])
        old, adv, ret = self.logprobs.reshape(-1), adv.reshape(-1), ret.reshape(-1)
        for _ in range(PPO_EPOCHS):
            order = torch.randperm(obs.shape[0], device=obs.device)
            for mb in order.split(self.minibatch):
                logprob, entropy, value = self._logprob_value(obs[mb], acts[mb])
                ratio = (logprob - old[mb]).exp()
                a = (adv[mb] - adv[mb].mean()) / (adv[mb].std() + 1e-8) if len(mb) > 1 else adv[mb]
                loss = (torch.max(-a * ratio, -a * ratio.clamp(1 - clip, 1 + clip)).mean()
                        + 0.5 * ((value - ret[mb]) ** 2).mean())
                self.optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(self.params, 0.5)
                self.optimizer.step()
        return float(loss.detach())


def columns(env_id, n, window, steady_after, device: Device, cpu: bool, ppo: bool, variants) -> list:
    """One row per window (fresh, steady): {column: env-steps/s} and the window's rare share."""
    env = make(env_id, n, device)
    dev = env._runner
    k, d = env.single_action_space.shape[0], env.single_observation_space.shape[0]
    states = saved_states(env, device, steady_after)
    host = np.random.default_rng(7).uniform(-1.0, 1.0, (window, n, k)).astype(np.float32)
    acts = device.upload(host)
    rows = []
    graphed = None
    if not device.sim:
        from penny_env.backends.cuda_env import CudaGraphStep
        graphed = CudaGraphStep(env)  # (its warm-up steps move the envs: every column restores its state below)
    policy = PolicyColumns(device, d, k, n, window, ppo) if device.torch is not None else None
    cpu_env = None
    if cpu:
        import gymnasium as gym
        cpu_env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point").unwrapped
        cpu_env.reset(seed=0)
    variant_envs = [(opts, make(env_id, n, device, **opts)) for opts in variants]
    for venv in (v for _, v in variant_envs):
        venv.reset(seed=0)
    for window_name in ("fresh", "steady"):
        state = states[window_name]
        first = 0 if window_name == "fresh" else steady_after
        text = (f"fresh: steps {first + 1}-{first + window} after reset(seed=0)" if window_name == "fresh" else
                f"steady: steps {first + 1}-{first + window} (after {steady_after} random steps)")
        r = {"window": window_name, "text": text, "rare": rare_share(env, device, state, acts, window)}
        ends = {}

        def go(name, fn, on=env, start=None):
            try:
                r[name] = n * window / timed(device, start or (lambda: restore(on, state)), fn, window)
                ends[name] = end_state(on)
            except Exception as exc:  # noqa: BLE001 (one failing column must not cost the rows of a lent GPU)
                r.setdefault("errors", {})[name] = f"{type(exc).__name__}: {exc}"
                print(f"{env_id} N={n:,} {window_name} {name}: failed: {type(exc).__name__}: {exc}", flush=True)
        go("env.step", lambda t: env.step(acts[t]))
        parity = [0]

        def kernels(t, e=env):
            device.copy_actions(e._runner, acts[t])
            e._runner.launch(parity[0])
            parity[0] ^= 1
        go("kernels alone", kernels)
        if graphed is not None:
            go("graph replay", lambda t: graphed(acts[t]))
        if policy is not None:
            go("env + policy", lambda t: policy.infer(env.step(acts[t])[0]))
            if ppo:
                last = {}

                def start_ppo():
                    restore(env, state)
                    last["obs"] = dev.reset_obs  # (the window's first observation: the reset's buffer, same shape)

                def ppo_step(t):
                    policy.record(t, last["obs"], acts[t])
                    obs, reward, term, trunc, _ = env.step(acts[t])
                    policy.after_step(t, reward, term, trunc)
                    last["obs"] = obs
                    if t == window - 1:
                        policy.update(obs)
                go("env + PPO", ppo_step, start=start_ppo)
        for opts, venv in variant_envs:
            vp = [0]

            def vkernels(t, e=venv, vp=vp):
                device.copy_actions(e._runner, acts[t])
                e._runner.launch(vp[0])
                vp[0] ^= 1
            go(variant_label(opts), vkernels, on=venv)
        if cpu_env is not None:
            t0_state = state

            def cpu_start():
                restore(cpu_env, t0_state)
            r["CPU"] = n * window / timed_cpu(cpu_start, lambda t: cpu_env.step(host[t]), window)
        ref = ends.get("env.step")
        r["same end state"] = ({name: bool(np.array_equal(ref.view(np.int64), s.view(np.int64)))
                                for name, s in ends.items()} if ref is not None else {"env.step": False})
        rows.append(r)
    arrays = list(dev.st) + [dev.actions, dev.work, dev.reset_obs] + [a for s in dev.sets for part in s for a in part]
    for row in rows:
        row["bytes per env"] = sum(a.nbytes for a in arrays) / n
        row["prepared"] = all(p.fast for pair in dev.launches for p in pair)
    for e in [env] + [v for _, v in variant_envs] + ([cpu_env] if cpu_env is not None else []):
        e.close()
    return rows


def timed_cpu(start, step, steps):
    start()
    t0 = time.perf_counter()
    for t in range(steps):
        step(t)
    return time.perf_counter() - t0


def variant_label(opts) -> str:
    if opts["kernels"] == "one":
        return "one kernel"
    return f"split, {'no cap' if opts['max_registers'] is None else str(opts['max_registers']) + ' registers'}"


def fmt(v):
    return "-" if v is None else f"{v:,.0f}"


def report(a, rep, name, results, sim) -> list:
    from penny_env.backends.env import FAST_MAX_REGISTERS
    lines = rep.header("GPU throughput of the vector env, like for like")
    lines += [f"- device: {name}; CPU backend (numba) on {os.cpu_count()} cores of the same machine", ""]
    if sim:
        lines += ["**Run under numba's CUDA simulator (`--quick`): these numbers time the simulator, nothing about a "
                  "GPU.**", ""]
    lines += [f"Each row: one window of {a.window} steps of one sequence of random action sets (uniform, float32, drawn "
              "beforehand), every column from the same saved state on the same actions (module docstring): env-steps "
              "per second. Fresh: the window starts right after reset(seed=0); steady: it starts after "
              f"{a.steady_after} random steps. Rare: the share of the window's env-steps that went to the rare kernel. "
              "Kernels alone: the action copy on the device and the three prepared launches; env + policy: a 64x64 "
              f"MLP's inference per step; env + PPO: the rollout, GAE and a PPO update ({PPO_EPOCHS} epochs of "
              f"{PPO_MINIBATCHES} minibatches) per env-step. Same end state: every column ended the window in the "
              "same states, bit for bit, as env.step.", ""]
    heads = ["id", "N", "window", "rare", "env.step", "kernels alone", "env.step / kernels", "graph replay",
             "env + policy", "env + PPO", "CPU (numba, all cores)", "env.step / CPU", "same end state"]
    body, var_rows = [], []
    for (env_id, n), rows in results.items():
        for r in rows:
            cpu = r.get("CPU")
            same = r["same end state"]
            step, kern = r.get("env.step"), r.get("kernels alone")
            body.append([env_id, f"{n:,}", r["text"], f"{100 * r['rare']:.2f} %", fmt(step),
                         fmt(kern), f"{step / kern:.2f}" if step and kern else "-", fmt(r.get("graph replay")),
                         fmt(r.get("env + policy")), fmt(r.get("env + PPO")), fmt(cpu),
                         "-" if cpu is None or step is None else f"{step / cpu:.1f}x",
                         "yes" if all(same.values()) else "no: " + ", ".join(k for k, v in same.items() if not v)])
            labels = [variant_label(o) for o in VARIANTS]
            if any(lab in r for lab in labels):
                var_rows.append([env_id, f"{n:,}", r["text"], f"{100 * r['rare']:.2f} %", fmt(r["kernels alone"])]
                                + [fmt(r.get(lab)) for lab in labels])
    lines += table(heads, body)
    errors = [f"- {env_id} N = {n:,}, {r['window']}, {col}: {err}" for (env_id, n), rows in results.items()
              for r in rows for col, err in r.get("errors", {}).items()]
    if errors:
        lines += ["", "Columns that failed (shown as -):", "", *errors]
    first = next(iter(results.values()))[0]
    lines += ["", f"Device memory per env (state, buffers, two output sets): {first['bytes per env']:.0f} B at the first "
              f"id. Launches: " + ("prepared once (builder.PreparedLaunch)." if first["prepared"]
                                   else "through numba's dispatcher (the prepared path failed here).")]
    if var_rows:
        lines += ["", "The step's kernels alone built other ways, same state and actions (env-steps/s):", "",
                  *table(["id", "N", "window", "rare", f"split, fast kernel capped at {FAST_MAX_REGISTERS} (the default)"]
                         + [variant_label(o) for o in VARIANTS], var_rows)]
    lines += ["", "Targets (steady windows):"]
    for env_id in dict.fromkeys(k[0] for k in results):
        steady = [(r["env.step"], n, r) for (i, n), rows in results.items() if i == env_id for r in rows
                  if r["window"] == "steady" and r.get("env.step") and r.get("kernels alone")]
        if not steady:
            continue
        best, n_best, r = max(steady, key=lambda v: v[0])
        goal = TARGETS.get(env_id)
        lines.append(f"- {env_id}: best steady env.step {best:,.0f} env-steps/s at N = {n_best:,}"
                     + (f" (target {goal:.0e}: {'met' if best >= goal else 'not met'})" if goal else "")
                     + "; env.step / kernels alone, steady: "
                     + ", ".join(f"{r['env.step'] / r['kernels alone']:.2f} at {n:,}"
                                 for _, n, r in sorted(steady, key=lambda v: v[1]))
                     + " (target 0.8)")
        at4096 = [v for v in steady if v[1] == 4096]
        if at4096:
            lines.append(f"  at N = 4,096, steady: {at4096[0][0]:,.0f} (target 1.2e7: "
                         f"{'met' if at4096[0][0] >= 1.2e7 else 'not met'})")
    return lines


def table(headers, rows):
    from lab.common import table as t
    return t(headers, rows)


def _options(ap) -> None:
    ap.add_argument("--ids", nargs="+", default=None, help=f"env ids (default {' '.join(IDS)})")
    ap.add_argument("--sizes", nargs="+", type=int, default=None, help=f"numbers of envs (default {SIZES})")
    ap.add_argument("--window", type=int, default=None, help=f"steps per window (default {WINDOW})")
    ap.add_argument("--steady-after", type=int, default=None,
                    help=f"random steps before the steady window (default {STEADY_AFTER}; at least 300 but with --quick)")
    ap.add_argument("--variants", action="store_true", help="also time the other ways to build the step's kernels")
    ap.add_argument("--variant-sizes", nargs="+", type=int, default=[1_048_576],
                    help="the N at which --variants times them (default 1048576)")
    ap.add_argument("--variant-ids", nargs="+", default=None, help="the ids --variants times (default: the first)")
    ap.add_argument("--no-cpu", action="store_true", help="skip the CPU backend's column")
    ap.add_argument("--cpu-sizes", nargs="+", type=int, default=None, help="the N of the CPU column (default: all)")
    ap.add_argument("--ppo-sizes", nargs="+", type=int, default=[4096, 65536, 1_048_576],
                    help="the N of the env + PPO column (default 4096 65536 1048576)")


def main(argv: list[str] | None = None) -> int:
    from lab.common import report_command
    rep = report_command("devtools.throughput_gpu", "throughput_gpu.md", __doc__.splitlines()[0], argv,
                         options=_options, quick="tiny N and windows under numba's CUDA simulator where there is no "
                         "GPU (a smoke run: the tests)")
    a, argv, ap = rep.args, rep.argv, rep
    if any(n < 1 for n in (a.sizes or ())) or (a.window is not None and a.window < 1):  # (bad input first, GPU or not)
        ap.error("--sizes and --window must be positive")
    name = gpu_here()
    if name is None and a.quick and not simulated():
        # (numba reads NUMBA_ENABLE_CUDASIM when it is first imported: a fresh process under the simulator)
        env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
        return subprocess.run([sys.executable, "-m", "devtools.throughput_gpu", *argv], env=env).returncode
    sim = name is None and simulated() and a.quick
    if name is None and not sim:
        print("throughput_gpu: no CUDA GPU here (numba-cuda and torch see no device; the CUDA simulator does not "
              "count): nothing measured, no report written. --quick runs the table under the simulator.")
        return 0
    if sim:
        name = "numba's CUDA simulator (no GPU)"
    ids = a.ids or (list(IDS[:1]) + [IDS[2]] if a.quick else list(IDS))
    sizes = a.sizes or ([6] if a.quick else list(SIZES))
    window = a.window or (3 if a.quick else WINDOW)
    a.window = window
    a.steady_after = a.steady_after if a.steady_after is not None else (4 if a.quick else STEADY_AFTER)
    if a.steady_after < 300 and not a.quick:
        ap.error("--steady-after must be at least 300 (the steady window)")
    if any(n < 1 for n in sizes) or window < 1:
        ap.error("--sizes and --window must be positive")
    device = Device(sim)
    variant_ids = a.variant_ids or ids[:1]
    results = {}
    for env_id in ids:
        for n in sizes:
            variants = VARIANTS if a.variants and env_id in variant_ids and (n in a.variant_sizes or a.quick) else ()
            cpu = not a.no_cpu and (a.cpu_sizes is None or n in a.cpu_sizes)
            ppo = device.torch is not None and (a.quick or n in a.ppo_sizes)
            rows = columns(env_id, n, window, a.steady_after, device, cpu, ppo, variants)
            results[(env_id, n)] = rows
            for r in rows:
                print(f"{env_id} N={n:,} {r['text']}: rare {100 * r['rare']:.2f} %, "
                      + ", ".join(f"{k} {v:,.0f}" for k, v in r.items() if isinstance(v, float) and k != "rare"
                                  and k != "bytes per env"), flush=True)
            rep.write(report(a, rep, name, results, sim))  # (after every row: a time limit keeps the rows done)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
