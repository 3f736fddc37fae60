"""Small promises of the public API (issue 33.7): the batch API after `import penny_env`, docs/envs.md
listing every registered id, and one name for a round table's radius (Circle's old `r` a deprecated alias)."""
import re
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import penny_env as pe

ROOT = Path(__file__).resolve().parents[2]


def test_batch_is_an_attribute_after_import_penny_env():
    """A fresh interpreter: `import penny_env` alone gives penny_env.batch (was AttributeError)."""
    code = ("import penny_env, numpy as np\n"
            "res = penny_env.batch.simulate(np.array([[0, 0, 0, 1.57, 10, 0.2]] * 2), "
            "table={'kind': 'circle', 'radius': 0.2}, law='elastic', t_final=1.0)\n"
            "print(res.final_states.shape)")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "(2, 6)"
    assert "batch" in pe.__all__


def test_docs_envs_lists_every_registered_id():
    text = (ROOT / "docs" / "envs.md").read_text()
    listed = set(re.findall(r"\b(Penny[A-Za-z]+-[A-Za-z0-9]+(?:-[A-Za-z0-9]+)*?-v\d+)\b", text))
    registered = {k for k in gym.registry if k.startswith("Penny")}
    assert registered - listed == set(), sorted(registered - listed)
    assert listed - registered == set(), sorted(listed - registered)


@pytest.mark.fast
def test_every_round_table_calls_its_radius_radius():
    for table in (pe.Circle(0.2), pe.Circle(radius=0.2), pe.Stadium(radius=0.2, length=0.1),
                  pe.RoundedRectangle(0.5, 0.4, radius=0.2)):
        assert table.radius == 0.2
    assert pe.Circle(0.2) == pe.Circle(radius=0.2) and repr(pe.Circle(0.2)) == "Circle(radius=0.2)"
    assert pe.batch.make_table({"kind": "circle", "radius": 0.2}) == pe.Circle(0.2)


@pytest.mark.fast
def test_circle_r_is_a_deprecated_alias():
    with pytest.warns(DeprecationWarning, match=r"Circle\(radius=\.\.\.\)"):
        old = pe.Circle(r=0.2)
    assert old == pe.Circle(radius=0.2)
    with pytest.warns(DeprecationWarning, match="Circle.radius"):
        assert old.r == 0.2
    with pytest.warns(DeprecationWarning):  # the spec dicts and scene YAML of older code
        assert pe.batch.make_table({"kind": "circle", "r": 0.2}) == old
    with pytest.raises(ValueError, match="radius and r"):
        pe.Circle(0.2, r=0.2)
    with pytest.raises(ValueError, match=r"table \(circle\).*radius"):
        pe.batch.make_table({"kind": "circle"})
    with pytest.raises(ValueError, match="Circle.radius"), pytest.warns(DeprecationWarning):
        pe.Circle(r=-1.0)


def test_new_code_raises_no_deprecation_warning():
    """The presets and the package's own specs use `radius`: building the circle envs warns nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        for env_id in ("PennyPark-Circle-v0", "PennyDrive-Circle-v0"):
            env = gym.make(env_id)
            env.reset(seed=0)
            env.close()
    preset = (ROOT / "penny_env" / "presets" / "scenes" / "circle.yaml").read_text()
    assert "radius:" in preset and not re.search(r"\br:", preset)


def test_a_partial_table_override_with_the_old_name_replaces_the_radius():
    """gymnasium.make("PennyPark-Circle-v0", table={"r": ...}) (older code) overrides the preset's radius."""
    with pytest.warns(DeprecationWarning):  # the scene keeps the spec as given: each table built from it warns
        env = gym.make("PennyPark-Circle-v0", table={"r": 0.2})
        table = env.unwrapped.scene.make_table()
    assert table == pe.Circle(0.2)
    env = gym.make("PennyPark-Circle-v0", table={"radius": 0.25})
    assert env.unwrapped.scene.make_table() == pe.Circle(0.25)
    state = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
    assert pe.simulate(state, table=pe.Circle(radius=0.2), law="elastic", n_impacts=3).n_impacts == 3
