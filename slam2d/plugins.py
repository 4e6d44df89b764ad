"""Plugins by path: Python files or modules imported before a run, so the frontends they
register (``@register_frontend``) can be named in a config, a sweep or ``--set``.

A config lists them under ``plugins``: a ``.py`` file (relative paths resolve against the
config file's folder, then the working directory) or a dotted module name. Each is
imported once per process; the forked frontend worker inherits them, and every run,
sweep variant and Ray task imports them again through :func:`load_plugins`.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

from slam2d.errors import InputError

_LOADED: set[str] = set()


def load_plugins(specs) -> None:
    """Import every plugin in ``specs`` (file paths or module names) not yet imported here."""
    for spec in specs:
        if spec not in _LOADED:
            _import(spec)
            _LOADED.add(spec)


def resolve(spec: str, base: Path | None) -> str:
    """``spec`` with a relative ``.py`` path made absolute against ``base`` (a config's folder) if it is there."""
    if spec.endswith(".py") and base is not None and not Path(spec).is_absolute() and (base / spec).is_file():
        return str((base / spec).resolve())
    return spec


def _import(spec: str) -> None:
    where = f"plugins: {spec}"
    if spec.endswith(".py"):
        path = Path(spec).expanduser().resolve()
        if not path.is_file():
            raise InputError(where, "no such Python file")
        name = f"slam2d_plugin_{abs(hash(str(path))):x}"
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module  # pickling of its classes (worker processes) finds it
        run = lambda: module_spec.loader.exec_module(module)  # noqa: E731
    else:
        run = lambda: importlib.import_module(spec)  # noqa: E731
    try:
        run()
    except ModuleNotFoundError as err:
        raise InputError(where, f"cannot import it ({err})") from None
    except InputError:
        raise
    except Exception as err:  # a plugin's own error: name the file and the first line of the cause
        raise InputError(where, f"importing it failed: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}") from None
