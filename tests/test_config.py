"""Configs: defaults, overrides, unknown keys by name, YAML round trip."""

import pytest

from slam2d import config
from slam2d.errors import InputError


def test_defaults_are_the_simulator():
    cfg = config.load()
    assert cfg.dataset.kind == "simulator"
    assert (cfg.frontend.name, cfg.backend.name) == ("icp", "pose_graph")


def test_override_parses_yaml_values():
    cfg = config.load(None, ["mapping.resolution=0.1", "dataset.simulator.route=[[0, 0], [1, 0]]"])
    assert cfg.mapping.resolution == 0.1
    assert cfg.dataset.simulator.route == [(0, 0), (1, 0)]


def test_unknown_key_named(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("mapping:\n  resolutoin: 0.1\n")
    with pytest.raises(InputError, match=r"c\.yaml: unknown key 'mapping\.resolutoin'"):
        config.load(p)


def test_bad_value_named():
    with pytest.raises(InputError, match="mapping.resolution"):
        config.load(None, ["mapping.resolution=-1"])


def test_malformed_yaml_names_line(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: x\nmapping: [1, 2\n")
    with pytest.raises(InputError, match=r"bad\.yaml:\d+: malformed YAML"):
        config.load(p)


def test_round_trip(tmp_path):
    cfg = config.load(None, ["seed=7", "frontend.name=odometry"])
    p = tmp_path / "out.yaml"
    p.write_text(config.dump(cfg))
    assert config.load(p) == cfg


def test_set_without_equals():
    with pytest.raises(InputError, match="KEY=VALUE"):
        config.load(None, ["mapping.resolution"])
