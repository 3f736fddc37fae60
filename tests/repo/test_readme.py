"""The README stays true: its simulator snippet runs, its ids are registered, its commands exist."""
import re
from pathlib import Path

import gymnasium as gym

import penny_env  # noqa: F401

README = (Path(__file__).parents[2] / "README.md").read_text()


def test_simulator_snippet_runs():
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    snippet = next(b for b in blocks if "pe.simulate(" in b)
    namespace = {}
    exec(compile(snippet, "README.md", "exec"), namespace)
    assert namespace["tr"].n_impacts > 0 and namespace["post"][4] < 0  # bounced back out


def test_every_id_in_the_readme_is_registered_and_vice_versa():
    listed = set(re.findall(r"`(Penny[A-Za-z]+-[A-Za-z]+-v\d+)`", README))
    registered = {k for k in gym.registry if k.startswith("Penny") and not k.startswith("PennyProbe")}
    assert listed == registered
    # the study's probe grid is listed in docs/study_probes.md, which the README links
    probes_doc = (Path(__file__).parents[2] / "docs" / "study_probes.md").read_text()
    assert "docs/study_probes.md" in README
    assert set(re.findall(r"`(PennyProbe[A-Za-z]+-[A-Za-z0-9-]+?-v\d+)`", probes_doc)) == {
        k for k in gym.registry if k.startswith("PennyProbe")}


def test_commands_in_the_readme_exist():
    import importlib.util
    for module in set(re.findall(r"python -m ((?:penny_env|training|studies|devtools|lab)[\w.]*)", README)):
        assert importlib.util.find_spec(module) is not None, module
    for config in re.findall(r"(configs/[\w/]+\.yaml)", README):
        assert (Path(__file__).parents[2] / config).exists(), config


def test_ppo_snippet_runs(monkeypatch):
    """The README's PPO snippet runs as written; learn() is cut to one rollout here (the full 100,000 steps
    are timed by `python -m studies.time_readme_snippet`, whose numbers the README quotes)."""
    import pytest
    pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")
    import torch
    from stable_baselines3 import PPO
    from studies.time_readme_snippet import ppo_snippet

    snippet = ppo_snippet()
    assert ".learn(100_000)" in snippet and "n_steps=128" in snippet
    learn = PPO.learn
    calls = []

    def one_rollout(self, total_timesteps, **kwargs):
        calls.append(total_timesteps)
        return learn(self, self.n_steps * self.n_envs, **kwargs)

    monkeypatch.setattr(PPO, "learn", one_rollout)
    threads = torch.get_num_threads()
    try:
        namespace = {}
        exec(compile(snippet, "README.md", "exec"), namespace)
    finally:
        torch.set_num_threads(threads)
    assert calls == [100_000] and namespace["model"].num_timesteps == 128 * 32
    assert "SNIPPET_" not in README, "the README quotes the numbers of python -m studies.time_readme_snippet"
