"""The commands that look things up or compare: plugins, frontends, datasets list / download, compare."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from slam2d.cli.common import PLUGIN_OPT, QUIET_OPT, _command, _fail, _stoppable, app
from slam2d.errors import InputError


@app.command()
def plugins(
    role: Optional[str] = typer.Argument(None, help="one role (e.g. exploration_strategies); default: every role"),
    plugin: list[str] = PLUGIN_OPT,
) -> None:
    """List every swappable part by role: its names and what each is (with those of --plugin files)."""
    from slam2d import registry
    from slam2d.plugins import load_plugins

    try:
        load_plugins(str(Path(p).resolve()) if p.endswith(".py") else p for p in plugin)
        roles = registry.roles()
        if role is not None and role not in roles:
            raise InputError("role", f"unknown role '{role}' (available: {', '.join(roles)})")
        for name in [role] if role else roles:
            typer.echo(f"{name}:")
            for entry, about in registry.role(name).catalog().items():
                typer.echo(f"  {entry:<22} {about}")
    except InputError as err:
        _fail(err)


@app.command()
def frontends(plugin: list[str] = PLUGIN_OPT) -> None:
    """List the registered frontends (with those of --plugin files or modules)."""
    from slam2d.frontends import available_frontends
    from slam2d.plugins import load_plugins

    try:
        load_plugins(str(Path(p).resolve()) if p.endswith(".py") else p for p in plugin)
    except InputError as err:
        _fail(err)
    for name in available_frontends():
        typer.echo(name)


datasets_app = typer.Typer(no_args_is_help=True, help="The public data files: list them, download them.")
app.add_typer(datasets_app, name="datasets")


@datasets_app.command("list")
def datasets_list(
    root: Optional[Path] = typer.Option(None, "--root", help="data folder to check (default: $SLAM2D_DATA)"),
    fmt: Optional[str] = typer.Option(None, "--format", help="table, plain (tab-separated, header first) or json "
                                      "(default: table on a terminal, else plain)"),
) -> None:
    """List every data file: size, sha256, licence, source, purpose, and whether it is here and verified."""
    import sys

    from slam2d.datasets.download import print_catalogue

    try:
        print_catalogue(root, fmt or ("table" if sys.stdout.isatty() else "plain"))
    except InputError as err:
        _fail(err)


@datasets_app.command("download")
def datasets_download(
    names: list[str] = typer.Argument(..., help="files (radish/intel.bag), folders (radish, rooms...) or all"),
    to: Optional[Path] = typer.Option(None, "--to", help="download here (default: $SLAM2D_DATA)"),
    quiet: bool = QUIET_OPT,
) -> None:
    """Download data files from their public sources, resuming partial ones and checking sha256."""
    from slam2d.datasets.download import download
    from slam2d.paths import data_root

    with _stoppable("partial downloads kept as .part files, resumed next time"):
        try:
            paths = download(names, to, quiet=quiet)
        except InputError as err:
            _fail(err)
    typer.echo(f"verified: {len(paths)} file(s) in {to or data_root()}")


@app.command()
def compare(
    runs: list[Path] = typer.Argument(..., help="results folders of any command, or sweep folders (their runs)"),
    metric: list[str] = typer.Option([], "--metric", "-m", help="a metric column (dotted key of metrics.json); "
                                     "default: the commands' main metrics"),
    root: Optional[Path] = typer.Option(None, "--out", "-o", help="also write table.md/.csv/.tex, "
                                        "trajectories.png, errors.png and report.html into a new folder under this"),
    quiet: bool = QUIET_OPT,
) -> None:
    """Several runs side by side: one table of their metrics, their trajectories overlaid and their error
    distributions (as evo_res)."""
    from slam2d.evaluation.tables import to_markdown
    from slam2d.runs.compare import compare_rows, run_folders, write_comparison
    from slam2d.runs.results import results_folder

    with _command(quiet):
        folders = run_folders(runs)
        if root is None:
            table = to_markdown(*compare_rows(folders, metric))
        else:
            with results_folder(root, "compare", "--out") as (work, published):
                table = write_comparison(folders, work, metric)
    typer.echo(table, nl=False)
    if root is not None:
        typer.echo(f"results: {published[0]}")
