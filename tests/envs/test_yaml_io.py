"""penny_env's YAML reader (penny_env/envs/yaml_io.py), which every config file goes through (scenes, tasks,
training.train, the ladder): aliases are checked as the shared values they are, never walked
expanded."""

import pytest
import yaml

from penny_env.envs.yaml_io import safe_load


def laughs(levels: int) -> str:
    """A "billion laughs" file: ``levels`` lists of nine aliases, each of the one before (9**levels values)."""
    lines = ['a0: &a0 ["x","x","x","x","x","x","x","x","x"]']
    lines += [f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 9)}]" for k in range(1, levels)]
    return "\n".join(lines + ["env_id: PennyReach-Ellipse-v0", "algo: ppo"]) + "\n"


@pytest.mark.fast
def test_aliases_that_expand_to_too_many_values_are_refused_at_once():
    # the 364-byte file of nine levels took 124-199 s of CPU before it was refused (the depth was counted node by node
    # over the expanded tree); seven levels (4.8e6 values) were accepted, for any reader downstream to expand
    # (refused by a count of the values the aliases expand to, made before anything is expanded)
    for levels in (7, 9):
        with pytest.raises(yaml.YAMLError, match=r"its aliases expand to \d+ values; a configuration holds at most 100000"):
            safe_load(laughs(levels))


@pytest.mark.fast
def test_aliases_within_the_bounds_and_merge_keys_still_read():
    data = safe_load(laughs(4))  # (6561 values)
    assert data["a3"][0][0][0] == ["x"] * 9 and data["a3"][8] is data["a2"]
    merged = safe_load("base: &b {scene: plane, init: {theta_dot: [3.0, 5.0]}}\nother: {<<: *b, scene: ellipse}\n")
    assert merged["other"] == {"scene": "ellipse", "init": {"theta_dot": [3.0, 5.0]}}


@pytest.mark.fast
def test_a_value_that_contains_itself_is_refused():
    with pytest.raises(yaml.YAMLError, match="an alias refers to a list or mapping that contains it"):
        safe_load("a: &a [1, *a]\n")
    with pytest.raises(yaml.YAMLError, match="contains it"):
        safe_load("a: &a {b: [2, *a]}\n")


@pytest.mark.fast
def test_nesting_is_still_measured_through_shared_values():
    deep = "x: &x " + "[" * 40 + "1" + "]" * 40 + "\ny: " + "[" * 30 + "*x" + "]" * 30 + "\n"
    with pytest.raises(yaml.YAMLError, match="nested more than 64 levels deep"):
        safe_load(deep)  # (the shared list is 40 deep, reached at depth 31: 71 levels)
    assert safe_load("x: &x [[1]]\ny: [*x, [*x]]\n")["y"][1][0] == [[1]]
