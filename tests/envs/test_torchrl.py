"""TorchRL: GymEnv on the registered ids, GymWrapper on the vector env (DISABLED and SAME_STEP
autoreset, fixed-width info arrays), short rollouts through the single-process collector (SyncDataCollector,
Collector since 0.11)."""
import numpy as np
import pytest

torchrl = pytest.importorskip("torchrl", reason="TorchRL is an optional extra")
import torch  # noqa: E402  (torchrl needs torch)
from gymnasium.vector import AutoresetMode  # noqa: E402
try:  # torchrl >= 0.11 names the single-process collector Collector
    from torchrl.collectors import Collector as SyncDataCollector  # noqa: E402
except ImportError:
    from torchrl.collectors import SyncDataCollector  # noqa: E402
from torchrl.envs import GymEnv, GymWrapper  # noqa: E402

import penny_env  # noqa: E402,F401  (registers the ids)
from penny_env import PennyVectorEnv  # noqa: E402


def test_gymenv_on_a_registered_id_and_a_collector():
    env = GymEnv("PennyImpacts-Stadium-v0")  # TorchRL probes a 'frameskip' keyword (a TypeError says no)
    td = env.rollout(20)
    assert td["next", "observation"].shape == (20, 11) and td["action"].shape == (20, 2)
    collector = SyncDataCollector(env, None, frames_per_batch=50, total_frames=100)
    frames = sum(batch.numel() for batch in collector)
    collector.shutdown()
    assert frames == 100


@pytest.mark.parametrize("mode", [AutoresetMode.DISABLED, AutoresetMode.SAME_STEP])
def test_vector_env_through_gymwrapper_and_a_collector(mode):
    venv = PennyVectorEnv(4, "stadium", "impacts", autoreset_mode=mode, max_episode_steps=6, max_impacts_in_info=3)
    env = GymWrapper(venv)
    if mode == AutoresetMode.DISABLED:  # TorchRL reads the info there only when asked to
        env.auto_register_info_dict()
    td = env.rollout(15, break_when_any_done=False)
    assert td["next", "impact_times"].shape == (4, 15, 3) and td["next", "impacts"].shape == (4, 15)
    assert td["next", "truncated"].any()
    collector = SyncDataCollector(env, None, frames_per_batch=40, total_frames=120)
    batches = list(collector)
    collector.shutdown()
    assert sum(b.numel() for b in batches) == 120
    last = batches[-1]
    # episodes are reset by TorchRL (DISABLED) or by the env (SAME_STEP): never longer than 6 steps
    assert (last["next", "time"] <= 6 * venv.scene.control_dt + 1e-9).all()
    assert torch.isfinite(last["next", "observation"]).all()


def test_disabled_autoreset_resets_only_the_masked_envs():
    venv = PennyVectorEnv(3, "ellipse", "reach", autoreset_mode=AutoresetMode.DISABLED, max_episode_steps=2)
    venv.reset(seed=0)
    for _ in range(2):
        obs, r, term, trunc, info = venv.step(np.zeros((3, 2)))
    assert trunc.all() and (info["time"] > 0).all()
    obs, r, term, trunc, info = venv.step(np.zeros((3, 2)))  # nothing resets by itself
    assert (info["time"] > 0).all() and "final_obs" not in info
    before = venv.states
    obs, info = venv.reset(options={"reset_mask": np.array([True, False, False])})
    assert info["time"][0] == 0 and np.array_equal(before[1:], venv.states[1:])
    assert not np.array_equal(before[0], venv.states[0])
