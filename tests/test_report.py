"""``slam2d ablate`` writes report.html: the table on the page after its script ran, sortable, figures and links."""

from __future__ import annotations

import csv
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from slam2d.evaluation.report import write_report
from slam2d.runs.sweep import run_sweep


def _chromium() -> str:
    """The headless browser; skips without one, fails in CI (SLAM2D_REQUIRE_DATA=1) where it is installed."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        if os.environ.get("SLAM2D_REQUIRE_DATA") == "1":
            pytest.fail("chromium not found (SLAM2D_REQUIRE_DATA=1): apt-get install -y chromium")
        pytest.skip("chromium not found: apt-get install -y chromium")
    return found


def _dom(url: str, tmp_path: Path) -> str:
    """The DOM of ``url`` after its scripts ran, from headless Chromium."""
    profile = tmp_path / "chromium-profile"
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={profile}", "--dump-dom", url]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def _order(dom: str) -> list[str]:
    return re.findall(r'<tr data-variant="([^"]*)"', dom)


@pytest.fixture(scope="module")
def sweep_folder(tmp_path_factory):
    """A finished two-variant sweep on the simulator: more odometry noise in the second variant."""
    tmp = tmp_path_factory.mktemp("sweep")
    base = {"dataset": {"max_scans": 25}, "mapping": {"resolution": 0.1}, "output": {"root": str(tmp / "res")}}
    (tmp / "base.yaml").write_text(yaml.safe_dump(base))
    sweep = tmp / "sweep.yaml"
    sweep.write_text(yaml.safe_dump({"base": "base.yaml", "workers": 2, "variants": [
        {"name": "quiet", "set": {"dataset.simulator.odometry.alpha3": 0.0}},
        {"name": "noisy", "set": {"dataset.simulator.odometry.alpha3": 0.3}}]}))
    folder, rows = run_sweep(sweep, quiet=True)
    assert [r["error"] for r in rows] == ["", ""]
    return folder


def test_report_links_every_variant_and_its_map(sweep_folder):
    page = (sweep_folder / "report.html").read_text()
    with (sweep_folder / "table.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert _order(page) == [r["variant"] for r in table] == ["quiet", "noisy"]
    for row in table:
        assert f'href="{row["folder"]}/"' in page
        assert f'src="{row["folder"]}/map.png"' in page and (sweep_folder / row["folder"] / "map.png").is_file()
    assert "<script" in page and "http" not in page  # self-contained: nothing fetched from elsewhere


def test_report_sorts_in_a_browser(sweep_folder, tmp_path):
    with (sweep_folder / "table.csv").open() as fh:
        table = list(csv.DictReader(fh))
    by_error = [r["variant"] for r in sorted(table, key=lambda r: float(r["odometry_ate.rmse"]), reverse=True)]
    assert by_error == ["noisy", "quiet"]  # the sort must move the rows
    url = (sweep_folder / "report.html").resolve().as_uri()
    dom = _dom(url, tmp_path)
    assert _order(dom) == ["quiet", "noisy"]  # every row on the page, in sweep order
    dom = _dom(url + "#sort=-odometry_ate.rmse", tmp_path)
    assert _order(dom) == by_error
    assert re.search(r'<th data-col="odometry_ate.rmse" aria-sort="descending"', dom)
    dom = _dom(url + "#sort=variant", tmp_path)
    assert _order(dom) == sorted(by_error)


def test_report_of_a_stopped_sweep_keeps_unfinished_rows(tmp_path):
    (tmp_path / "runs" / "a-20250101-000000").mkdir(parents=True)
    (tmp_path / "runs" / "a-20250101-000000" / "labels.png").write_bytes(b"")
    rows = [{"variant": "a", "ate.rmse": 0.5, "error": "", "folder": "runs/a-20250101-000000"},
            {"variant": "b<c", "error": "not run (sweep stopped)", "folder": ""}]
    page = write_report(tmp_path, rows, ("variant", "ate.rmse")).read_text()
    assert _order(page) == ["a", "b&lt;c"]
    assert "labels.png" not in page and "not run (sweep stopped)" in page
    assert 'data-num="0.5"' in page
