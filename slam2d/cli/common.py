"""What every slam2d command shares: the typer app, the common options, the logging set-up, the frame that
turns bad input into one line and exit 2 and a signal into exit 130 (SIGINT) or 143 (SIGTERM), and building a
command's config.

Heavy imports happen inside the commands so that ``slam2d --help`` is instant.
"""

from __future__ import annotations

import json
import logging
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

import typer

from slam2d.errors import InputError

app = typer.Typer(add_completion=False, no_args_is_help=True, help="2D laser SLAM research framework.")

CONFIG_ARG = typer.Argument(None, help="experiment YAML; omitted: the built-in simulator default")
SET_OPT = typer.Option([], "--set", "-s", help="override a config key, e.g. --set seed=1 (dump-config lists the keys)")
QUIET_OPT = typer.Option(False, "--quiet", "-q", help="no progress bars, warnings and errors only")
PLUGIN_OPT = typer.Option([], "--plugin", "-p", help="Python file or module to import first (its frontends)")
JSON_OPT = typer.Option(False, "--json", help="print one JSON object on stdout: the results folder and its main "
                        "metrics")


def _version(shown: bool) -> None:
    if shown:
        from slam2d import __version__

        typer.echo(f"slam2d {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="print the version of slam2d and exit"),
) -> None:
    """2D laser SLAM research framework."""


class _LogHandler(logging.Handler):
    """The log on stderr through rich's handler, made (and rich imported) at the first record shown: a quiet
    command that warns of nothing does not load rich."""

    def __init__(self, level: int) -> None:
        super().__init__(level)
        self._rich = None

    def emit(self, record: logging.LogRecord) -> None:
        if self._rich is None:
            from rich.console import Console
            from rich.logging import RichHandler

            self._rich = RichHandler(console=Console(stderr=True), show_path=False, show_time=False, level=self.level)
        self._rich.handle(record)


def _setup_logging(quiet: bool) -> None:
    """The log on stderr (stdout carries the results only)."""
    logger = logging.getLogger("slam2d")
    logger.handlers[:] = [h for h in logger.handlers if not isinstance(h, _LogHandler)]
    logger.addHandler(_LogHandler(logging.WARNING if quiet else logging.INFO))
    logger.setLevel(logging.INFO)
    logger.propagate = False


def _fail(err: Exception) -> None:
    typer.secho(f"error: {err}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


STOPPED_CODES = (130, 143)  # stopped by SIGINT, by SIGTERM
NOT_REACHED = 3  # navigate: the goal was not reached (its results are written)


def _stopped(what: str) -> None:
    """Report a SIGINT / SIGTERM; exit 130 or 143 as shells do."""
    from slam2d.runs.signals import exit_code

    typer.secho(f"stopped: {what}", fg=typer.colors.RED, err=True)
    raise typer.Exit(exit_code())


@contextmanager
def _stoppable(what: str):
    """SIGINT or SIGTERM in the block: "stopped: WHAT" and exit 130 or 143, whatever error the signal became."""
    from slam2d.runs.signals import stop_on_signals, stopped

    try:
        with stop_on_signals():
            yield
    except (typer.Exit, SystemExit):
        raise
    except BaseException:
        if not stopped():
            raise
        _stopped(what)


@contextmanager
def _command(quiet: bool, what: str = "no results folder written"):
    """A command's frame: logging set up; bad input -> "error: ..." and exit 2; a signal -> "stopped: WHAT" and
    exit 130 / 143."""
    _setup_logging(quiet)
    with _stoppable(what):
        try:
            yield
        except InputError as err:
            _fail(err)


VIZ_OPT = typer.Option(False, "--viz", help="stream the run to the rerun viewer (the \\[viz] extra)")
VIZ_SAVE_OPT = typer.Option(None, "--viz-save", help="record the live view to FILE.rrd instead")


def _viz_target(viz: bool, viz_save: Optional[Path]):
    """What the live view streams to: ``"viewer"``, the ``.rrd`` file, or None (no view)."""
    if viz and viz_save:
        raise InputError("--viz-save", "give --viz (a live viewer) or --viz-save FILE.rrd, not both")
    return viz_save or ("viewer" if viz else None)


CONFIG_OPT = typer.Option(None, "--config", "-c", help="the command's YAML config (slam2d dump-config --command ...)")
OUT_SET_OPT = typer.Option(None, "--out", "-o", help="results folders are created under this (output.root)")


def _config_file(positional: Optional[Path], option: Optional[Path]) -> Optional[Path]:
    """The config file given positionally or with ``-c`` (not both)."""
    if positional is not None and option is not None:
        raise InputError("--config", f"give the config once: {positional} or -c {option}")
    return positional if positional is not None else option


def _command_config(command: str, config: Optional[Path], set_: list[str], flags: dict, plugins: list[str] = ()):
    """The config of ``command`` from ``config`` (or defaults), ``--set`` overrides, then the short
    flags given (``flags``: dotted key -> value or None), then ``--plugin`` files or modules."""
    from slam2d import config as config_mod
    from slam2d.plugins import load_plugins
    from slam2d.runs.commands import command_model
    from slam2d.runs.results import output_root

    if flags.get("output.root") is not None:
        output_root(flags["output.root"], "--out")  # its error names the option
    plugins = [str(Path(p).resolve()) if p.endswith(".py") else p for p in plugins]
    load_plugins(plugins)  # before the config: a name a plugin registers is then known when it is checked
    overrides = dict(map(config_mod.parse_override, set_))
    overrides.update({k: str(v) if isinstance(v, Path) else v for k, v in flags.items() if v is not None})
    cfg = config_mod.load(config, overrides, command_model(command))
    if plugins:
        cfg.plugins = [*cfg.plugins, *plugins]
    return cfg


def _echo_metrics(folder: Path, keys: tuple[str, ...], digits: int = 4) -> None:
    """Some metrics of ``folder`` on one line, on stderr (stdout carries the results only)."""
    metrics = json.loads((folder / "metrics.json").read_text())
    typer.echo(" ".join(f"{k}={metrics[k]:.{digits}g}" if isinstance(metrics[k], float) else f"{k}={metrics[k]}"
                        for k in keys if metrics.get(k) is not None), err=True)  # fmt: skip


def main_metrics(command: str, folder: Path) -> dict:
    """The main metrics of ``command`` (see ``slam2d.runs.commands``) present in ``folder``'s metrics.json,
    by dotted key."""
    from slam2d.evaluation.tables import flatten_metrics
    from slam2d.runs.commands import command_of

    path = folder / "metrics.json"
    flat = flatten_metrics(json.loads(path.read_text())) if path.is_file() else {}
    return {k: flat[k] for k in command_of(command).main_metrics if k in flat}


def _results(command: str, folder: Path, as_json: bool) -> None:
    """The command's stdout: ``results: FOLDER``, or with ``--json`` one JSON object (folder, main metrics)."""
    if as_json:
        typer.echo(json.dumps({"folder": str(folder), "metrics": main_metrics(command, folder)}))
    else:
        typer.echo(f"results: {folder}")


def _xy(text: str | None, name: str):
    if text is None:
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--{name}", f"expected x,y in metres, got '{text}'") from None
    return [x, y]


def _layer_names(text: str | None) -> list[str] | None:
    from slam2d.mapping.layers import LAYERS

    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in LAYERS]
    if unknown or not names:
        raise InputError("--layers", f"unknown layer '{unknown[0] if unknown else ''}' (one of {', '.join(LAYERS)})")
    return names
