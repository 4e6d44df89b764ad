"""``slam2d ablate --executor ray``: the same table as the local executor, run folders gathered in one place."""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest
import yaml

from slam2d import config as config_mod
from slam2d.errors import InputError
from slam2d.runs.sweep import _collect, run_sweep, _run_variant_anywhere

try:
    import ray
except ImportError:  # CI installs the [ray] extra: there a missing ray is a failure
    if os.environ.get("CI") == "true" or os.environ.get("SLAM2D_REQUIRE_DATA") == "1":
        raise
    pytest.skip("ray is not installed: pip install -e '.[ray]'", allow_module_level=True)

MEASURED = ("cpu_ms_per_scan", "runtime_s", "peak_rss_mb", "timings_s.")  # wall clock and memory: vary run to run


@pytest.fixture(scope="module")
def local_ray():
    """A new local Ray instance on two CPUs, whatever RAY_ADDRESS or a running `ray start` say."""
    address = os.environ.pop("RAY_ADDRESS", None)
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()
    if address is not None:
        os.environ["RAY_ADDRESS"] = address


def _sweep(tmp_path: Path) -> Path:
    base = {"dataset": {"max_scans": 20}, "mapping": {"resolution": 0.1}, "output": {"root": str(tmp_path / "res")}}
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(yaml.safe_dump(
        {"base": "base.yaml", "workers": 2, "grid": {"dataset.simulator.odometry.alpha3": [0.0, 0.2]}}))
    return sweep


def _table(folder: Path) -> list[dict[str, str]]:
    """table.csv without the measured columns; each row's folder checked and replaced by its variant's name."""
    with (folder / "table.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    for row in rows:
        run = folder / row.pop("folder")
        assert run.parent == folder / "runs" and (run / "metrics.json").is_file() and (run / "config.yaml").is_file()
        row["folder"] = run.name.rsplit("-", 2)[0]
    return [{k: v for k, v in row.items() if not k.startswith(MEASURED)} for row in rows]


def test_ray_sweep_gives_the_local_table(tmp_path, local_ray):
    sweep = _sweep(tmp_path)
    local_folder, local_rows = run_sweep(sweep, executor="local", quiet=True)
    ray_folder, ray_rows = run_sweep(sweep, executor="ray", quiet=True)
    assert ray_folder != local_folder
    assert [r["error"] for r in ray_rows] == ["", ""]
    local_table, ray_table = _table(local_folder), _table(ray_folder)
    assert [r["variant"] for r in ray_table] == ["alpha3=0.0", "alpha3=0.2"]
    assert ray_table == local_table
    assert float(ray_table[1]["odometry_ate.rmse"]) > float(ray_table[0]["odometry_ate.rmse"])  # real numbers


def test_task_on_another_machine_sends_its_folder_back(tmp_path):
    """A runs folder the task cannot see (another machine): it runs elsewhere and the folder is unpacked here."""
    unreachable = tmp_path / "on-the-driver" / "runs"
    cfg = config_mod.validate({"name": "far", "dataset": {"max_scans": 10}, "output": {"root": str(unreachable)}})
    outcome = _run_variant_anywhere(cfg)
    assert outcome[3] is not None and not unreachable.exists()
    runs = tmp_path / "gathered"
    runs.mkdir()
    folder, metrics, error = _collect(runs, outcome)
    assert error is None and Path(folder).parent == runs
    assert json.loads((Path(folder) / "metrics.json").read_text()) == metrics
    assert (Path(folder) / "trajectory.tum").is_file()
    resolved = yaml.safe_load((Path(folder) / "config.yaml").read_text())
    assert (resolved["name"], resolved["output"]["root"]) == ("far", str(runs))


def test_unreachable_cluster_is_one_line_error_and_no_folder(tmp_path, monkeypatch):
    def refuse(*args, **kwargs):
        raise ConnectionError("Failed to connect to Ray cluster at 10.9.8.7:6379")

    monkeypatch.setattr(ray, "init", refuse)
    with pytest.raises(InputError, match=r"RAY_ADDRESS: cannot reach the Ray cluster \(Failed to connect"):
        run_sweep(_sweep(tmp_path), executor="ray", quiet=True)
    assert not (tmp_path / "res").exists()
