"""Write failures are input errors: a read-only output root, a full disk, a name too long in bytes give
one line naming the path and the reason, and leave nothing behind."""

from __future__ import annotations

import errno
import os
import subprocess
import sys

import numpy as np
import pytest

from slam2d import config
from slam2d.errors import InputError
from slam2d.runs import results
from slam2d.runs.commands import command_model


def _map_yaml(folder, stem="map"):
    from PIL import Image

    pixels = np.full((10, 10), 254, np.uint8)
    pixels[0] = 0
    Image.fromarray(pixels).save(folder / f"{stem}.pgm")
    path = folder / f"{stem}.yaml"
    path.write_text(f"image: {stem}.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n"
                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return path


def _map_config(tmp_path, root, map_path=None, *extra):
    return config.load(None, [f"map={map_path or _map_yaml(tmp_path)}", f"output.root={root}", "layers=[sparse]",
                              "output.figures=false", *extra], command_model("map"))


def test_read_only_output_root(tmp_path, monkeypatch):
    from slam2d.runs.map import run_map

    root = tmp_path / "ro"
    root.mkdir()
    if os.geteuid() == 0:  # permissions do not bind root: the file system's refusal is mocked
        def refuse(*args, **kwargs):
            raise PermissionError(errno.EACCES, "Permission denied", str(root))

        monkeypatch.setattr(results.tempfile, "mkdtemp", refuse)
    else:
        root.chmod(0o555)
    cfg = _map_config(tmp_path, root)
    with pytest.raises(InputError, match=rf"^output.root: cannot write in {root} \(Permission denied\)$"):
        run_map(cfg)
    root.chmod(0o755)
    assert list(root.iterdir()) == []


def test_output_root_under_a_file_is_one_line_exit_2(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    done = subprocess.run([sys.executable, "-m", "slam2d.cli", "map", str(_map_yaml(tmp_path)), "--layers", "sparse",
                           "-o", str(afile / "sub")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [f"error: --out: cannot create folder {afile / 'sub'} (Not a directory)"]


def test_disk_full_while_writing(tmp_path, monkeypatch):
    from slam2d.runs.map import run_map

    def full(folder, name):
        raise OSError(errno.ENOSPC, "No space left on device", str(folder / "report.html"))

    monkeypatch.setattr(results, "write_run_report", full)
    root = tmp_path / "res"
    with pytest.raises(InputError, match=r"report.html: cannot write \(No space left on device\)$"):
        run_map(_map_config(tmp_path, root))
    assert list(root.iterdir()) == []


def test_names_are_limited_in_bytes_not_characters(tmp_path):
    from slam2d.runs.map import run_map

    with pytest.raises(InputError, match=r"key 'name': .*1-200 bytes \(UTF-8\)"):
        config.load(None, ["name=" + "é" * 150])  # 150 characters, 300 bytes
    stem = "地" * 80  # 240 bytes: a valid file name, too long for "map-STEM-YYYYmmdd-HHMMSS"
    folder = run_map(_map_config(tmp_path, tmp_path / "res", _map_yaml(tmp_path, stem)))
    assert folder.is_dir() and len(folder.name.encode()) <= 255 and folder.name.startswith("map-地地")


def test_sweep_folder_and_table_write_failures(tmp_path, monkeypatch):
    import yaml

    from slam2d.runs import sweep as sweeps

    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"workers": 1, "variants": [{"name": "a", "set": {"seed": 1}}], "config": {
        "output": {"root": str(tmp_path / "res")}, "mapping": {"resolution": 0.1}, "dataset": {"max_scans": 5}}}))

    def refuse(parent, stem):
        raise PermissionError(errno.EACCES, "Permission denied", str(parent / stem))

    monkeypatch.setattr(sweeps, "new_folder", refuse)
    with pytest.raises(InputError, match=r"res/ablate-sweep-\d+-\d+: cannot write \(Permission denied\)$"):
        sweeps.run_sweep(path, quiet=True)
    monkeypatch.undo()

    def full(rows, stem, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", f"{stem}.md")

    monkeypatch.setattr(sweeps, "write_table", full)
    with pytest.raises(InputError, match=r"table.md: cannot write \(No space left on device\)$"):
        sweeps.run_sweep(path, quiet=True)
