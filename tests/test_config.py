from pathlib import Path

import pytest

from song.config import SongConfig, config_hash, load_config
from song.errors import ConfigError


def test_defaults_are_paper_values() -> None:
    cfg = SongConfig()
    assert cfg.crowd.fps == 30
    assert (cfg.intents.speed_min_mps, cfg.intents.speed_max_mps) == (0.5, 1.0)
    assert cfg.grading.n_episodes == 500
    assert cfg.robot.max_speed_mps == 0.5 and cfg.robot.max_yaw_rate_deg_s == 45.0
    assert cfg.robot.max_steps == 200 and cfg.robot.goal_radius_m == 1.0
    assert cfg.robot.eta_col == 5 and cfg.robot.max_obstacle_collisions == 5
    assert (cfg.camera.width_px, cfg.camera.height_px, cfg.camera.hfov_deg) == (960, 540, 70.0)
    assert cfg.motion.prompt.startswith("A person is casually walking forward")


def test_toml_and_yaml_load_and_hash(tmp_path: Path) -> None:
    toml = tmp_path / "c.toml"
    toml.write_text("seed = 7\n[crowd]\nagent_radius_m = 0.3\n")
    yaml = tmp_path / "c.yaml"
    yaml.write_text("seed: 7\ncrowd:\n  agent_radius_m: 0.3\n")
    a, b = load_config(toml), load_config(yaml)
    assert a == b and a.seed == 7 and a.crowd.agent_radius_m == 0.3
    assert config_hash(a) == config_hash(b) != config_hash(SongConfig())


def test_overrides_merge_sections(tmp_path: Path) -> None:
    toml = tmp_path / "c.toml"
    toml.write_text("[crowd]\nagent_radius_m = 0.3\n")
    cfg = load_config(toml, seed=3, crowd={"fps": 60})
    assert cfg.seed == 3 and cfg.crowd.fps == 60 and cfg.crowd.agent_radius_m == 0.3


@pytest.mark.parametrize(
    ("text", "field"),
    [("[crowd]\nagent_radius_m = -1\n", "crowd.agent_radius_m"), ("[crowd]\nbogus = 1\n", "crowd.bogus")],
)
def test_bad_config_names_field(tmp_path: Path, text: str, field: str) -> None:
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(path) in str(info.value) and field in str(info.value)
    assert "\n" not in str(info.value)


def test_unreadable_config(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("seed = [")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(path)
