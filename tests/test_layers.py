"""The floors of the house (DESIGN.md) as an import-linter contract: an algorithm package never imports
the runs layer, the CLI or the live view, and each floor imports only from its own floor or below."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_import_floors_contract_is_kept():
    lint = Path(sys.executable).with_name("lint-imports")
    done = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert "1 kept, 0 broken" in done.stdout


def test_every_package_exports_what_its_all_names():
    """``from slam2d.PACKAGE import NAME`` works for every public name of every algorithm package."""
    import importlib

    for package in ("datasets", "frontends", "backend", "mapping", "segmentation", "planning", "navigation",
                    "localization", "exploration", "evaluation", "sim", "slam"):
        module = importlib.import_module(f"slam2d.{package}")
        for name in getattr(module, "__all__", ()):
            assert getattr(module, name) is not None, f"slam2d.{package}.{name}"
