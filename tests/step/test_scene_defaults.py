"""Scene defaults are written once (penny_env/envs/scene.py); the YAML presets give only what differs."""
import pytest
import yaml

from penny_env.envs.scene import CONFIG_DIR, Scene, resolve


def _repeated(preset: dict, defaults: dict, where: str) -> list[str]:
    out = []
    for key, value in preset.items():
        default = defaults.get(key)
        if isinstance(value, dict) and isinstance(default, dict):
            out += _repeated(value, default, f"{where}.{key}")
        elif value == default:
            out.append(f"{where}.{key}")
    return out


@pytest.mark.fast
def test_scene_presets_do_not_repeat_the_defaults():
    defaults = {name: value for name, value in vars(Scene()).items()}
    for path in sorted((CONFIG_DIR / "scenes").glob("*.yaml")):
        preset = yaml.safe_load(path.read_text())
        preset.pop("table")  # what a scene preset is about, even where it is the default table
        assert not _repeated(preset, defaults, path.stem), f"{path.name} repeats a default of scene.py"


@pytest.mark.fast
def test_the_paper_ellipse_preset_is_the_default_scene():
    scene, _ = resolve("ellipse", "reach")
    assert scene == Scene()
    assert scene.params == {"R": 0.01, "m": 0.0025, "I": 1.25e-7, "J": 6.25e-8}
    assert scene.torque_limits == {"u1": 6.25e-7, "u2": 1.5e-5}
