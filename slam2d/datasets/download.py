"""``slam2d datasets``: list the catalogue and download its files, resumable and verified by sha256."""

from __future__ import annotations

import hashlib
import http.client
import json
import sys
import urllib.error
import urllib.request
from contextlib import nullcontext
from pathlib import Path

from slam2d.datasets import catalog
from slam2d.datasets.catalog import DataFile
from slam2d.errors import InputError
from slam2d.paths import data_root

CHUNK = 1 << 16
TIMEOUT_S = 30.0


def select(names: list[str]) -> list[DataFile]:
    """Catalogue files by name (``radish/intel.bag``), folder (``radish``) or ``all``, in catalogue order."""
    files = catalog.CATALOGUE
    groups = sorted({f.group for f in files})
    chosen: set[str] = set()
    for name in names:
        found = [f.name for f in files if name in ("all", f.name, f.group)]
        if not found:
            raise InputError(name, f"no such data file or folder (folders: {', '.join(groups)}, or all; "
                                   "'slam2d datasets list' names the files)")
        chosen.update(found)
    return [f for f in files if f.name in chosen]


def sha256_of(path: Path) -> str:
    """Hex sha256 of the file at ``path``."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def status(entry: DataFile, root: Path) -> str:
    """``verified``, ``differs`` (present, other bytes), ``partial`` (a .part file) or ``missing``."""
    path = root / entry.name
    if path.is_file():
        ok = path.stat().st_size == entry.size and sha256_of(path) == entry.sha256
        return "verified" if ok else "differs"
    return "partial" if _part(path).is_file() else "missing"


def download(names: list[str], to: Path | None = None, quiet: bool = False) -> list[Path]:
    """Download the named files under ``to`` (default: the data root); verified files are kept as they are."""
    root = Path(to).expanduser() if to is not None else data_root()
    todo = [f for f in select(names) if status(f, root) != "verified"]
    with _progress(quiet) as progress:
        for entry in todo:
            task = progress.add_task(entry.name, total=entry.size) if progress else None
            _fetch(entry, root / entry.name, lambda n, t=task: progress and progress.advance(t, n))
    return [root / f.name for f in select(names)]


def _progress(quiet: bool):
    if quiet or not sys.stderr.isatty():  # a progress bar on a terminal only
        return nullcontext(None)
    from rich.console import Console
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TransferSpeedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), DownloadColumn(), TransferSpeedColumn(),
                    console=Console(stderr=True))  # stdout carries the results only


def _part(path: Path) -> Path:
    return path.with_name(path.name + ".part")


def _fetch(entry: DataFile, path: Path, advance) -> None:
    """Fetch ``entry`` into ``path.part`` (resuming it by an HTTP Range), verify it, rename it to ``path``.
    A failed fetch keeps the bytes received, and removes the folders it made if they stayed empty."""
    part = _part(path)
    made = [p for p in part.parents if not p.exists()]  # innermost first
    try:
        part.parent.mkdir(parents=True, exist_ok=True)
        part.touch()
    except OSError as err:
        raise InputError(part, f"cannot write ({err.strerror}); choose another folder with --to") from None
    try:
        _fetch_into(entry, part, advance)
    except InputError:
        if part.is_file() and part.stat().st_size == 0:
            part.unlink()
        for folder in made:
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    part.replace(path)


def _fetch_into(entry: DataFile, part: Path, advance) -> None:
    """The bytes of ``entry`` completed in ``part`` and verified."""
    have = part.stat().st_size
    if have > entry.size:
        part.unlink()
        have = 0
    if have < entry.size:
        _receive(entry, part, have, advance)
    else:
        advance(have)
    _verify(entry, part)


def _receive(entry: DataFile, part: Path, have: int, advance) -> None:
    """Append the bytes from offset ``have`` to ``part`` (from 0 if the server ignores the Range)."""
    request = urllib.request.Request(entry.url, headers={"Range": f"bytes={have}-"} if have else {})
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT_S) as response:
            resumed = have > 0 and response.status == 206
            advance(have if resumed else 0)
            with part.open("ab" if resumed else "wb") as out:
                for block in iter(lambda: response.read(CHUNK), b""):
                    out.write(block)
                    advance(len(block))
    except urllib.error.HTTPError as err:
        raise InputError(entry.name, f"HTTP {err.code} {err.reason} from {entry.url}") from None
    except (urllib.error.URLError, http.client.HTTPException, OSError) as err:
        reason = getattr(err, "reason", None) or err
        kept = f"; the {part.stat().st_size} bytes received are kept in {part}" if part.stat().st_size else ""
        raise InputError(entry.name, f"cannot download {entry.url} ({reason}): offline?{kept}") from None


def _verify(entry: DataFile, part: Path) -> None:
    """The sha256 of ``part`` is the catalogue's, else ``part`` is deleted and an InputError names both."""
    got = sha256_of(part)
    if got != entry.sha256:
        part.unlink()
        raise InputError(entry.name, f"sha256 mismatch: expected {entry.sha256}, got {got} (download deleted)")


COLUMNS = ("file", "size", "sha256", "status", "licence", "source", "url", "purpose")
"""The fields of :func:`catalogue_rows` (and the columns of the ``plain`` format)."""
FORMATS = ("table", "plain", "json")
"""How :func:`print_catalogue` prints: a table to read, tab-separated lines or JSON for scripts."""


def catalogue_rows(root: Path | None = None) -> list[dict]:
    """Every catalogued file with its status under ``root`` (default: the data root): file, size (bytes),
    sha256, status, licence, source, url, purpose."""
    root = Path(root).expanduser() if root is not None else data_root()
    return [dict(zip(COLUMNS, (e.name, e.size, e.sha256, status(e, root), e.licence, e.source, e.url, e.purpose)))
            for e in catalog.CATALOGUE]


def print_catalogue(root: Path | None = None, fmt: str = "table") -> None:
    """Print the catalogue, with each file's status under ``root`` (default: the data root): as a table,
    ``plain`` (tab-separated, one file a line, the header first) or ``json`` (a list of objects)."""
    if fmt not in FORMATS:
        raise InputError("--format", f"unknown format '{fmt}' (one of {', '.join(FORMATS)})")
    rows = catalogue_rows(root)
    if fmt == "json":
        print(json.dumps(rows, indent=2))
        return
    if fmt == "plain":
        print("\t".join(COLUMNS))
        for row in rows:
            print("\t".join(" ".join(str(v).split()) for v in row.values()))  # no tab or newline in a field
        return
    from rich.console import Console
    from rich.table import Table

    root = Path(root).expanduser() if root is not None else data_root()
    table = Table(title=f"data files under {root}")
    for column in ("file", "size", "sha256", "status", "licence", "source", "what for"):
        table.add_column(column, no_wrap=column in ("file", "size", "status"), overflow="fold")
    for row in rows:
        table.add_row(row["file"], _size(row["size"]), row["sha256"][:16], row["status"], row["licence"],
                      row["source"], row["purpose"])
    Console().print(table)


def _size(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 1e5 else f"{n / 1e3:.1f} kB"
