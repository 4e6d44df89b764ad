"""What the command line prints where: the log and progress on stderr, on stdout the results line only
(or with ``--json`` one JSON object), so that ``$(slam2d run ...)`` and ``slam2d run --json | jq`` work."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from slam2d.cli import app

ROOT = Path(__file__).resolve().parents[1]


def _slam2d(*args: str) -> subprocess.CompletedProcess:
    """``slam2d ARGS`` in a subprocess (this checkout's slam2d), stdout and stderr apart."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "slam2d.cli", *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)


def _floor_plan(tmp_path: Path) -> Path:
    """Two 6 m x 6 m rooms (0.05 m/px) joined by a door, as a floor-plan PNG."""
    free = np.zeros((130, 255), bool)
    free[5:125, 5:125] = True
    free[5:125, 130:250] = True
    free[51:69, 125:130] = True
    Image.fromarray(np.where(free, 255, 0).astype(np.uint8)).save(tmp_path / "plan.png")
    return tmp_path / "plan.png"


def test_run_json_is_one_object_and_plain_stdout_one_line(tmp_path):
    done = _slam2d("run", "-q", "--json", "--set", "dataset.max_scans=5", "-o", str(tmp_path / "json"))
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout)
    assert set(out) == {"folder", "metrics"} and Path(out["folder"]).is_dir()
    assert out["metrics"]["scans"] == 5 and "ate.rmse" in out["metrics"]  # dotted keys, flattened
    written = json.loads((Path(out["folder"]) / "metrics.json").read_text())
    assert out["metrics"]["ate.rmse"] == written["ate"]["rmse"]

    done = _slam2d("run", "--set", "dataset.max_scans=5", "-o", str(tmp_path / "plain"))
    assert done.returncode == 0, done.stderr[-2000:]
    (line,) = done.stdout.splitlines()
    assert line.startswith("results: ") and Path(line.removeprefix("results: ")).is_dir()
    assert "scans processed" in done.stderr and "done in" in done.stderr  # the log, on stderr


def test_metrics_echo_on_stderr_json_on_stdout(tmp_path):
    plan = _floor_plan(tmp_path)
    runner = CliRunner()
    plain = runner.invoke(app, ["segment", str(plan), "--method", "morphological", "-o", str(tmp_path)])
    assert plain.exit_code == 0, plain.output
    assert plain.stdout.splitlines() == [line for line in plain.stdout.splitlines() if line.startswith("results: ")]
    assert len(plain.stdout.splitlines()) == 1 and "rooms=" in plain.stderr
    as_json = runner.invoke(app, ["map", str(plan), "--layers", "sparse,lines", "--json", "-o", str(tmp_path)])
    assert as_json.exit_code == 0, as_json.output
    out = json.loads(as_json.stdout)
    assert Path(out["folder"]).name.startswith("map-")
    assert {"sparse.bytes", "lines.bytes"} <= set(out["metrics"]) and "mesh.bytes" not in out["metrics"]


def test_ablate_json(tmp_path):
    plan = _floor_plan(tmp_path)
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(f"command: segment\nconfig: {{map: {plan}}}\n"
                     "grid: {segmentation.method: [morphological, distance]}\n")
    runner = CliRunner()
    dry = runner.invoke(app, ["ablate", str(sweep), "--dry-run", "--json"])
    assert dry.exit_code == 0, dry.output
    assert [v["overrides"] for v in json.loads(dry.stdout)["variants"]] == [
        {"segmentation.method": "morphological"}, {"segmentation.method": "distance"}]
    ran = runner.invoke(app, ["ablate", str(sweep), "--json", "-j", "1", "-o", str(tmp_path / "out")])
    assert ran.exit_code == 0, ran.output
    out = json.loads(ran.stdout)
    assert Path(out["table_md"]).is_file() and Path(out["table_csv"]).is_file()
    assert Path(out["folder"]).is_dir() and out["failed"] == []
    assert "| variant" in ran.stderr  # the table itself, for a reader, on stderr


def test_version():
    from slam2d import __version__

    done = CliRunner().invoke(app, ["--version"])
    assert done.exit_code == 0 and done.stdout == f"slam2d {__version__}\n"
    code = ("import sys\nfrom slam2d.cli import main\nsys.argv = ['slam2d', '--version']\n"
            "try:\n    main()\nexcept SystemExit as done:\n    assert not done.code, done.code\n"
            "heavy = {'numpy', 'gtsam', 'matplotlib', 'scipy'} & {m.split('.')[0] for m in sys.modules}\n"
            "assert not heavy, heavy\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout == f"slam2d {__version__}\n", done.stderr[-2000:]


def test_the_program_exits_without_the_interpreters_teardown(tmp_path):
    """``slam2d`` as a program: exit functions run and streams are flushed, objects are not torn down (that took
    0.7-0.8 s after ``slam2d optimize`` on M3500, loaded); its exit code is the command's."""
    from slam2d import __version__

    code = ("import atexit, sys\nfrom slam2d.cli import entry\n"
            "class Late:\n    def __del__(self):\n        print('torn down')\n"
            "late = Late()\natexit.register(print, 'exit functions')\n"
            "sys.argv = ['slam2d'] + sys.argv[1:]\nprint('buffered', end=' ')\nentry()\n")
    done = subprocess.run([sys.executable, "-c", code, "--version"], cwd=ROOT, capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 0 and done.stdout == f"buffered slam2d {__version__}\nexit functions\n", done
    done = subprocess.run([sys.executable, "-c", code, "optimize", str(tmp_path / "none.g2o")], cwd=ROOT,
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2 and "none.g2o" in done.stderr and "torn down" not in done.stdout, done


def test_optimize_loads_only_what_a_clean_graph_needs(tmp_path):
    """Building the app imports no command's implementation; ``slam2d optimize -q`` on a clean graph loads no
    plotting, learning, mesh or graph library, and, warning of nothing, not rich (the log's handler); nor scipy,
    with or without vertex lines: the start and the certificate run in a worker process that imports it
    (``lm.sparse_worker``), an edges-only file's poses are chained by numpy."""
    from slam2d import geometry
    from slam2d.datasets.g2o import PoseGraphFile, write_g2o

    angle = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
    poses = np.column_stack([5 * np.cos(angle), 5 * np.sin(angle), angle + np.pi / 2])
    i, j = np.r_[np.arange(12), 0, 3], np.r_[(np.arange(12) + 1) % 12, 6, 9]  # a ring and two chords
    delta = geometry.between(poses[i], poses[j]) + np.random.default_rng(0).normal(0, 0.01, (len(i), 3))
    write_g2o(tmp_path / "ring.g2o", PoseGraphFile(np.arange(12), poses, i, j, delta,
                                                   np.broadcast_to(np.diag([100.0, 100.0, 400.0]), (len(i), 3, 3))))
    edges = "".join(line for line in (tmp_path / "ring.g2o").open() if line.startswith("EDGE"))
    (tmp_path / "edges.g2o").write_text(edges)  # no vertex lines: the poses chained along the edges
    code = ("import sys\nimport slam2d.cli\nloaded = lambda: {m.split('.')[0] for m in sys.modules}\n"
            "early = {'numpy', 'scipy', 'gtsam', 'pydantic', 'PIL', 'jinja2', 'rich', 'yaml'} & loaded()\n"
            "assert not early, f'building the app loaded {early}'\n")
    for name in ("ring", "edges"):
        argv = ["slam2d", "optimize", str(tmp_path / f"{name}.g2o"), "-q", "-o", str(tmp_path)]
        code += (f"sys.argv = {argv!r}\n"
                 "try:\n    slam2d.cli.main()\nexcept SystemExit as done:\n    assert not done.code, done.code\n")
    code += ("late = {'matplotlib', 'sklearn', 'open3d', 'numba', 'networkx', 'rich', 'scipy'} & loaded()\n"
             "assert not late, f'optimize loaded {late}'\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    for name in ("ring", "edges"):
        (folder,) = tmp_path.glob(f"optimize-{name}-*")
        metrics = json.loads((folder / "metrics.json").read_text())
        assert metrics["certified"] and metrics["verified"] and (folder / "overlay.png").is_file()


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bars_on_a_terminal_only_never_quiet(monkeypatch):
    from slam2d.runs.results import progress_bar, shows_progress

    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert not shows_progress(False) and not shows_progress(True)
    with progress_bar("working", 10, False) as update:
        update(10)
    assert sys.stderr.getvalue() == ""
    monkeypatch.setattr(sys, "stderr", _Terminal())
    assert shows_progress(False) and not shows_progress(True)
    with progress_bar("working", 10, True) as update:
        update(10)
    assert sys.stderr.getvalue() == ""
    with progress_bar("working", 10, False) as update:
        update(10)
    assert "working" in sys.stderr.getvalue()


class _Bars:
    """Stands in for ``progress_bar``: records each bar's description, total and updates."""

    def __init__(self):
        self.bars: list[tuple[str, float | None, bool, list]] = []

    @contextlib.contextmanager
    def __call__(self, description, total, quiet):
        done: list = []
        self.bars.append((description, total, quiet, done))
        yield lambda value, note="": done.append(value)


def test_localize_and_navigate_show_progress_results_unchanged(monkeypatch, tmp_path):
    from slam2d import config
    from slam2d.localization.config import LocalizeConfig
    from slam2d.runs import localize, navigate

    def metrics(folder: Path) -> dict:
        m = json.loads((folder / "metrics.json").read_text())
        return {k: v for k, v in m.items() if not k.endswith(("_ms_median", "_ms_p95", "wall_s", "real_time_factor", "hz"))}

    cfg = LocalizeConfig(map="office", seconds=4, output={"root": str(tmp_path), "figures": False})
    quiet = metrics(localize.run_localize(cfg, quiet=True))
    bars = _Bars()
    monkeypatch.setattr(localize, "progress_bar", bars)
    shown = metrics(localize.run_localize(cfg))
    ((description, total, was_quiet, done),) = bars.bars
    assert description.startswith("localising") and not was_quiet and done == list(range(1, total + 1))
    assert shown == quiet

    cfg = config.load(None, [f"output.root={tmp_path}", "navigation.goal=[10.0, 4.5]", "navigation.slam=false",
                             "output.figures=false"])
    quiet = metrics(navigate.run_navigate(cfg, quiet=True))
    monkeypatch.setattr(navigate, "progress_bar", bars)
    shown = metrics(navigate.run_navigate(cfg))
    description, total, was_quiet, done = bars.bars[-1]
    assert description.startswith("navigating") and total == 300 and not was_quiet
    assert done == sorted(done) and done[0] == 0 and done[-1] == pytest.approx(shown["time"], abs=0.2)
    assert shown == quiet


def test_install_script_installs_what_the_quick_start_uses():
    """The Quick start's --viz needs the viz extra, installed by default; Ray stays optional."""
    import re

    script = (ROOT / "scripts" / "install.sh").read_text()
    (default,) = re.findall(r"\$\{SLAM2D_EXTRAS:-([a-z,]+)\}", script)
    assert {"dev", "viz"} <= set(default.split(",")) and "ray" not in default.split(",")
    readme = (ROOT / "README.md").read_text()
    assert "bash scripts/install.sh && .venv/bin/slam2d run\n" in readme
    assert "--executor ray" in readme and "SLAM2D_EXTRAS=dev,viz,ray bash scripts/install.sh" in readme
