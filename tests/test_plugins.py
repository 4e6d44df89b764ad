"""Plugins by path: a frontend written in a script is usable from the CLI, in sweeps and in worker processes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from slam2d import config
from slam2d.errors import InputError
from slam2d.plugins import load_plugins

PLUGIN = '''
import numpy as np
from slam2d.frontends import FrontendResult, register_frontend


@register_frontend("halved_odometry_{tag}")
class HalvedOdometry:
    """Odometry with half its translation."""

    def process(self, scan, odom_delta):
        delta = np.array([0.5 * odom_delta[0], 0.5 * odom_delta[1], odom_delta[2]])
        return FrontendResult(delta=delta, information=np.diag([400.0, 400.0, 3000.0]), confidence=1.0)
'''


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """``slam2d ARGS`` in a fresh process (nothing registered beforehand)."""
    return subprocess.run([sys.executable, "-m", "slam2d.cli", *args], cwd=cwd, capture_output=True, text=True)


def experiment(tmp_path: Path, tag: str) -> Path:
    """A plugin file in a subfolder and a config beside it naming it relatively."""
    folder = tmp_path / "exp"
    folder.mkdir()
    (folder / "my_frontend.py").write_text(PLUGIN.format(tag=tag))
    (folder / "exp.yaml").write_text(
        "name: plug\nplugins: [my_frontend.py]\n"
        f"frontend: {{name: halved_odometry_{tag}}}\nbackend: {{name: none}}\n"
        f"dataset: {{max_scans: 40}}\noutput: {{root: {tmp_path / 'results'}, figures: false}}\n"
    )
    return folder / "exp.yaml"


def test_a_script_frontend_runs_from_the_cli_by_a_relative_plugin_path(tmp_path):
    cfg = experiment(tmp_path, "cli")
    done = cli("run", str(cfg), "-q", cwd=tmp_path)  # the working directory is not the config's folder
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.split("results:")[1].strip())
    assert json.loads((folder / "metrics.json").read_text())["scans"] == 40
    assert "halved_odometry_cli" in (folder / "config.yaml").read_text()


def test_plugin_option_and_frontends_listing(tmp_path):
    plugin = tmp_path / "extra.py"
    plugin.write_text(PLUGIN.format(tag="opt"))
    listed = cli("frontends", "--plugin", str(plugin), cwd=tmp_path)
    assert "halved_odometry_opt" in listed.stdout.split()
    assert "halved_odometry_opt" not in cli("frontends", cwd=tmp_path).stdout.split()
    done = cli("run", "-q", "--plugin", str(plugin), "--set", "frontend.name=halved_odometry_opt",
               "--set", "dataset.max_scans=30", "--set", f"output.root={tmp_path / 'r'}", cwd=tmp_path)
    assert done.returncode == 0, done.stderr


def test_a_sweep_runs_the_plugin_frontend_in_its_worker_processes(tmp_path):
    cfg = experiment(tmp_path, "sweep")
    sweep = tmp_path / "exp" / "sweep.yaml"
    sweep.write_text("name: plugsweep\nbase: exp.yaml\nworkers: 2\n"
                     "grid:\n  dataset.max_scans: [20, 30]\n  parallel: [true]\n")
    done = cli("ablate", str(sweep), "-q", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "failed" not in done.stderr
    table = Path(done.stdout.split("table:")[1].split(" and ")[0].strip())
    runs = sorted(p for p in (table.parent / "runs").iterdir() if p.is_dir())
    assert len(runs) == 2
    assert sorted(json.loads((r / "metrics.json").read_text())["scans"] for r in runs) == [20, 30]
    assert cfg.exists()


def test_missing_or_broken_plugins_are_one_line_errors(tmp_path):
    with pytest.raises(InputError, match="no such Python file"):
        load_plugins([str(tmp_path / "absent.py")])
    with pytest.raises(InputError, match="cannot import"):
        load_plugins(["slam2d_no_such_module"])
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('half written\\nsecond line')\n")
    with pytest.raises(InputError, match="RuntimeError: half written$"):
        load_plugins([str(broken)])
    bad = experiment(tmp_path, "bad")
    bad.write_text(bad.read_text().replace("my_frontend.py", "typo.py"))
    done = cli("run", str(bad), "-q", cwd=tmp_path)
    assert done.returncode != 0 and "typo.py" in done.stderr and "Traceback" not in done.stderr


def test_relative_plugin_paths_resolve_against_the_config_folder(tmp_path):
    cfg = config.load(experiment(tmp_path, "rel"))
    assert cfg.plugins == [str((tmp_path / "exp" / "my_frontend.py").resolve())]
