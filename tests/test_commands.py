"""``slam2d segment`` and ``slam2d plan`` as experiments: YAML configs (unknown keys named, --set,
dump-config), atomic results folders, the short flag forms, and sweeps with ``slam2d ablate``."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image
from typer.testing import CliRunner

from slam2d import config
from slam2d.cli import app
from slam2d.errors import InputError
from slam2d.runs.commands import run_command
from slam2d.runs.sweep import read_sweep, run_sweep, SweepStopped
from slam2d.planning.config import PlanConfig
from slam2d.segmentation.config import SegmentConfig


def _write_plan(tmp_path: Path, stem: str = "plan") -> Path:
    """Two 6 m x 6 m rooms (0.05 m/px) joined by a 0.9 m door, as a floor-plan PNG with its ground truth."""
    free = np.zeros((130, 255), bool)
    free[5:125, 5:125] = True
    free[5:125, 130:250] = True
    free[51:69, 125:130] = True
    Image.fromarray(np.where(free, 255, 0).astype(np.uint8)).save(tmp_path / f"{stem}.png")
    gt = free.copy()
    gt[:, 125:130] = False
    Image.fromarray(np.where(gt, 255, 0).astype(np.uint8)).save(tmp_path / f"{stem}_gt_segmentation.png")
    return tmp_path / f"{stem}.png"


def _cli(*args: str):
    out = CliRunner().invoke(app, list(args))
    return out.exit_code, out.output


def _csv(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_segment_config_errors_name_the_key(tmp_path):
    bad = tmp_path / "seg.yaml"
    bad.write_text("segmentation: {methd: spectral}\n")
    code, out = _cli("segment", "-c", str(bad))
    assert code == 2 and f"{bad}: unknown key 'segmentation.methd'" in out
    code, out = _cli("segment", str(tmp_path / "x.png"), "--set", "segmentation.similarity=hausdorf")
    assert code == 2 and "key 'segmentation.similarity'" in out and "hausdorf" in out
    code, out = _cli("segment", "-o", str(tmp_path))
    assert code == 2 and "map: no map given" in out
    code, out = _cli("plan", "--set", "map=m.png", "--start", "1,1")
    assert code == 2 and "give both start and goal" in out
    assert not [p for p in tmp_path.iterdir() if p.is_dir()]


def test_dump_config_of_each_command():
    code, out = _cli("dump-config", "--command", "segment", "--set", "segmentation.method=voronoi")
    dumped = yaml.safe_load(out)
    assert code == 0 and dumped["segmentation"]["method"] == "voronoi" and "ground_truth" in dumped
    code, out = _cli("dump-config", "--command", "plan")
    dumped = yaml.safe_load(out)
    assert code == 0 and dumped["planning"]["hierarchy"] == "none"
    assert dumped["segmentation"]["method"] == "morphological"
    code, out = _cli("dump-config", "--command", "explore", "--set", "exploration.strategy=utility")
    assert code == 0 and yaml.safe_load(out)["exploration"]["strategy"] == "utility"
    code, out = _cli("dump-config", "--command", "localize", "--set", "preset=amcl", "--set", "figures=false")
    dumped = yaml.safe_load(out)  # the short keys land in their sections
    assert code == 0 and dumped["localization"]["preset"] == "amcl" and dumped["output"]["figures"] is False
    code, out = _cli("dump-config", "--command", "localise")
    assert code == 2 and "--command: unknown command 'localise'" in out


def test_segment_config_and_flags_give_one_result(tmp_path):
    plan = _write_plan(tmp_path)
    cfg_file = tmp_path / "seg.yaml"
    cfg_file.write_text(yaml.safe_dump({"map": str(plan), "segmentation": {"method": "distance"},
                                        "output": {"root": str(tmp_path / "a")}}))
    code, out = _cli("segment", "-c", str(cfg_file), "-q")
    assert code == 0, out
    (folder,) = (tmp_path / "a").iterdir()
    assert folder.name.startswith("segment-plan-distance-")
    assert {"config.yaml", "metrics.json", "labels.png", "rooms.png", "rooms_graph.json", "run.log"} <= {
        p.name for p in folder.iterdir()}
    again = config.load(folder / "config.yaml", model=SegmentConfig)  # the resolved config runs again
    assert again.segmentation.method == "distance" and again.map == str(plan)
    code, out = _cli("segment", str(plan), "--method", "distance", "-o", str(tmp_path / "b"), "-q")
    assert code == 0, out
    (flags,) = (tmp_path / "b").iterdir()
    assert np.array_equal(np.asarray(Image.open(folder / "labels.png")), np.asarray(Image.open(flags / "labels.png")))
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["rooms"] == 2 and metrics["recall"] > 90 and metrics["furnished"] is False


def _plan_config(tmp_path, **planning) -> PlanConfig:
    plan = _write_plan(tmp_path)
    return config.load(None, {"map": str(plan), "output.root": str(tmp_path / "res"),
                              **{f"planning.{k}": v for k, v in planning.items()}}, PlanConfig)


def test_plan_queries_against_astar(tmp_path):
    folder = run_command(_plan_config(tmp_path, queries=6, min_distance=5.0, hierarchy="none"))
    m = json.loads((folder / "metrics.json").read_text())
    assert m["queries"] == 6 and m["failures"] == 0
    assert m["mean_subopt_pct"] == 0.0 and m["max_subopt_pct"] == 0.0  # A* against itself
    assert m["min_query_m"] >= 5.0
    folder = run_command(_plan_config(tmp_path, queries=6, min_distance=5.0, hierarchy="rooms"))
    rooms = json.loads((folder / "metrics.json").read_text())
    assert rooms["queries"] == 6 and rooms["failures"] == 0 and rooms["rooms"] == 2
    assert -1e-9 <= rooms["mean_subopt_pct"] <= rooms["max_subopt_pct"] + 1e-9  # float sums of equal lengths
    assert (folder / "config.yaml").is_file() and (folder / "run.log").is_file()


def test_plan_one_query_from_a_config(tmp_path):
    cfg = _plan_config(tmp_path, start=[1.0, 3.0], goal=[11.5, 3.0], hierarchy="rooms")
    folder = run_command(cfg)
    m = json.loads((folder / "metrics.json").read_text())
    assert m["found"] and m["planner"] == "rooms" and m["rooms"] == 2 and m["length_m"] >= 10.5
    assert {"path.png", "velocity.png", "trajectory.csv", "config.yaml"} <= {p.name for p in folder.iterdir()}


def _segment_sweep(tmp_path, maps: list[str], summary=True) -> Path:
    sweep = {"name": "seg", "command": "segment", "workers": 2,
             "config": {"output": {"root": str(tmp_path / "res"), "figures": False}},
             "variants": [{"name": "distance", "set": {"segmentation.method": "distance"}},
                          {"name": "morphological", "set": {"segmentation.method": "morphological"}}],
             "grid": {"map": maps}}
    if summary:
        sweep["summary"] = {"by": ["segmentation.method"], "mean": ["recall"], "sum": ["rooms"]}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(sweep, sort_keys=False))
    return path


def test_segment_sweep_variants_times_grid_with_summary(tmp_path):
    a, b = _write_plan(tmp_path, "one"), _write_plan(tmp_path, "two")
    folder, rows = run_sweep(_segment_sweep(tmp_path, [str(a), str(b)]), quiet=True)
    assert [r["error"] for r in rows] == [""] * 4
    table = _csv(folder / "table.csv")
    assert [(r["segmentation.method"], Path(r["map"]).stem) for r in table] == [
        ("distance", "one"), ("distance", "two"), ("morphological", "one"), ("morphological", "two")]
    summary = _csv(folder / "summary.csv")
    assert [s["segmentation.method"] for s in summary] == ["distance", "morphological"]
    for s in summary:
        mine = [r for r in table if r["segmentation.method"] == s["segmentation.method"]]
        assert int(s["variants"]) == 2 and int(s["failed"]) == 0
        assert float(s["mean recall"]) == pytest.approx(np.mean([float(r["recall"]) for r in mine]))
        assert float(s["sum rooms"]) == sum(int(r["rooms"]) for r in mine)
    assert "<h2>Summary</h2>" in (folder / "report.html").read_text()


def test_sweep_checks_command_and_summary(tmp_path):
    path = _segment_sweep(tmp_path, ["m.png"])
    data = yaml.safe_load(path.read_text())
    for key, value, message in [("command", "localise", "command: unknown command 'localise'"),
                                ("summary", {"mean": ["recall"]}, "summary: expected a mapping with 'by'"),
                                ("summary", {"by": ["map"], "avg": ["recall"]}, "summary: unknown key 'avg'")]:
        path.write_text(yaml.safe_dump({**data, key: value}))
        with pytest.raises(InputError, match=message):
            read_sweep(path)
    path.write_text(yaml.safe_dump({**data, "variants": [{"name": "x", "set": {"segmentation.methd": "voronoi"}}]}))
    with pytest.raises(InputError, match="variant 'x.*unknown key 'segmentation.methd'"):
        read_sweep(path)


def test_navigate_sweep_runs_each_planner_and_explore_sweeps_are_checked(tmp_path):
    """`command: navigate` drives the robot once per variant (the navigation metrics in the table);
    an explore sweep validates its exploration section before running anything."""
    sweep = tmp_path / "nav.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "nav", "command": "navigate", "workers": 1,
        "config": {"navigation": {"slam": False, "goal": [10.0, 4.5]}, "output": {"figures": False}},
        "grid": {"navigation.planner": ["dwa", "fsm"]}}))
    folder, rows = run_sweep(sweep, quiet=True)
    assert [r["error"] for r in rows] == ["", ""]
    table = _csv(folder / "table.csv")
    assert sorted(r["navigation.planner"] for r in table) == ["dwa", "fsm"]
    assert all(r["status"] == "reached" for r in table), table
    for r in rows:
        written = yaml.safe_load((folder / r["folder"] / "config.yaml").read_text())
        assert written["navigation"]["planner"] in r["variant"]
    sweep.write_text(yaml.safe_dump({"command": "explore", "grid": {"exploration.strategy": ["utility", "bogus"]}}))
    with pytest.raises(InputError, match="exploration.strategy"):
        read_sweep(sweep)


def test_localize_sweep_runs_each_preset(tmp_path):
    """`command: localize` localises once per variant on a small floor plan: both presets track the
    simulated robot, each with its own update trigger and particle count (amcl keeps its maximum)."""
    plan = _write_plan(tmp_path)
    sweep = tmp_path / "loc.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "loc", "command": "localize", "workers": 2,
        "config": {"map": str(plan), "localization": {"mode": "tracking", "seconds": 10},
                   "output": {"figures": False, "root": str(tmp_path / "out")}},
        "grid": {"localization.preset": ["slam2d", "amcl"]}}))
    folder, rows = run_sweep(sweep, quiet=True)
    table = {r["localization.preset"]: r for r in _csv(folder / "table.csv")}
    assert sorted(table) == ["amcl", "slam2d"] and [r["error"] for r in rows] == ["", ""]
    for row in table.values():
        assert 0 < float(row["position_rmse"]) < 0.2 and int(row["updates"]) > 0
    assert int(table["amcl"]["updates"]) < int(table["slam2d"]["updates"])  # 0.2 m between updates, not 0.1 m
    assert float(table["amcl"]["particles_median"]) == 5000 > float(table["slam2d"]["particles_median"])
    written = yaml.safe_load((folder / table["amcl"]["folder"] / "config.yaml").read_text())
    assert written["localization"]["mcl"]["max_particles"] == 5000  # the preset resolved
    sweep.write_text(yaml.safe_dump({"command": "localize", "grid": {"localization.preset": ["amcl", "bogus"]}}))
    with pytest.raises(InputError, match="localization.preset"):
        read_sweep(sweep)


def test_localize_sweep_after_a_localisation_in_the_same_process(tmp_path):
    """The sweep's workers do not inherit the OpenMP state of numba's parallel kernels run here first
    (a forked worker running them again aborted, and the sweep reported itself stopped)."""
    from slam2d.localization.config import LocalizeConfig
    from slam2d.runs.localize import run_localize

    plan = _write_plan(tmp_path)
    run_localize(LocalizeConfig(map=str(plan), localization={"mode": "tracking", "seconds": 2},
                                output={"figures": False, "root": str(tmp_path / "first")}))
    sweep = tmp_path / "loc.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "loc", "command": "localize", "workers": 1,
        "config": {"map": str(plan), "localization": {"mode": "tracking", "seconds": 2},
                   "output": {"figures": False, "root": str(tmp_path / "out")}},
        "variants": [{"name": "one", "set": {"localization.preset": "slam2d"}}]}))
    try:
        _, rows = run_sweep(sweep, quiet=True)
    except SweepStopped as stop:  # a KeyboardInterrupt: it would end the whole test session
        pytest.fail(f"the sweep's worker died: {stop}")
    assert [r["error"] for r in rows] == [""] and float(rows[0]["position_rmse"]) < 0.2


def test_sweep_of_real_floor_plans_matches_single_runs(tmp_path, data_file):
    """The sweep's rows are the numbers `slam2d segment` gives for the same map and method."""
    maps = [str(data_file("rooms/office_a.png")), str(data_file("rooms/office_a_furnitures.png"))]
    folder, rows = run_sweep(_segment_sweep(tmp_path, maps, summary=False), quiet=True)
    single = run_command(config.load(None, {"map": maps[1], "segmentation.method": "morphological",
                                            "output.root": str(tmp_path / "one")}, SegmentConfig))
    one = json.loads((single / "metrics.json").read_text())
    row = next(r for r in rows if r["variant"].startswith("morphological") and "furnitures" in r["variant"])
    assert (row["recall"], row["precision"], row["rooms"], row["furnished"]) == (
        one["recall"], one["precision"], one["rooms"], True)


def test_segment_command_loads_no_plotting_or_learning_library(tmp_path):
    """A short command pays for what it uses: the rooms figure is drawn without matplotlib."""
    import subprocess
    import sys

    plan = _write_plan(tmp_path)
    argv = ["slam2d", "segment", str(plan), "--method", "morphological", "-q", "-o", str(tmp_path)]
    code = ("import sys\nfrom slam2d.cli import main\n"
            f"sys.argv = {argv!r}\n"
            "try:\n    main()\nexcept SystemExit as done:\n    assert not done.code, done.code\n"
            "heavy = {'matplotlib', 'sklearn', 'gtsam', 'numba', 'open3d'} & {m.split('.')[0] for m in sys.modules}\n"
            "assert not heavy, heavy\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    (folder,) = [p for p in tmp_path.iterdir() if p.name.startswith("segment-")]
    figure = np.asarray(Image.open(folder / "rooms.png").convert("RGB"))
    assert figure.shape[1] >= 1000
    colours = {tuple(c) for c in figure.reshape(-1, 3)[::7].tolist()}
    assert {(31, 119, 180), (255, 127, 14)} <= colours  # the two rooms in the first two palette colours
