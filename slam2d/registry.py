"""One registry per swappable part (a role): the names a config chooses implementations by.

Each role's package defines its :class:`Registry` in its ``base.py``, beside the Protocol its
implementations follow, and a decorator to register them (``@register_frontend("icp")``).
A registry finds an implementation

- among its built-ins, imported on first use (name -> module), so ``import slam2d`` stays light;
- among those registered so far: by a module of this package, a plugin file or module
  (``plugins:`` of a config, :mod:`slam2d.plugins`) or any code;
- in the entry-point group ``slam2d.<role>`` of installed packages.

An implementation's parameters are a pydantic model: a class's nested ``Config`` (its instance
is the last positional argument of the constructor), the ``config`` given at registration, or
for a function without one the parameters it has defaults for (given as keywords).
:meth:`Registry.create` checks the options against it (an unknown key names the full dotted key
and the valid ones) and builds the implementation; :meth:`Registry.resolve_options` returns the
completed model, so that a resolved config shows every default. :class:`Choice` marks the config
field naming an implementation. :func:`validation_error` is the one formatter of pydantic errors.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from importlib import import_module
from importlib.metadata import entry_points
from importlib.util import find_spec
from typing import Any, get_type_hints

from pydantic import BaseModel, ConfigDict, ValidationError, create_model
from pydantic_core import PydanticCustomError, core_schema

from slam2d.errors import InputError, short_repr

__all__ = [
    "ROLES", "Registry", "Choice", "role", "roles", "catalog", "options_model", "resolve_config",
    "validation_error", "check_choices", "lazy_exports",
]

ROLES = {
    "datasets": "slam2d.datasets.base",
    "frontends": "slam2d.frontends.base",
    "backends": "slam2d.backend.base",
    "global_planners": "slam2d.planning.base",
    "local_planners": "slam2d.navigation.base",
    "recovery_behaviours": "slam2d.navigation.base",
    "exploration_strategies": "slam2d.exploration.base",
    "similarity_measures": "slam2d.segmentation.base",
    "segmentation_methods": "slam2d.segmentation.base",
    "map_layers": "slam2d.mapping.base",
    "localizers": "slam2d.localization.base",
    "mcl_presets": "slam2d.localization.base",
    "commands": "slam2d.runs.commands",
}
"""The built-in roles: role -> the module defining its registry (imported on first use)."""

UNKNOWN_NAME = "unknown_name"
"""Type of the pydantic error of a :class:`Choice` no registry knows."""
BAD_OPTIONS = "bad_options"
"""Type of the pydantic error of options an implementation refuses (the original error in its context)."""

_REGISTRIES: dict[str, Registry] = {}


class _NoOptions(BaseModel):
    """The options of an implementation that takes none."""

    model_config = ConfigDict(extra="forbid")


@dataclass(frozen=True)
class Entry:
    """One implementation: the object registered, its options model (None: it takes none), the role's
    inputs it takes (keywords of :meth:`Registry.create`), and whether the checked model is passed whole."""

    obj: Any
    config: type[BaseModel] | None
    takes: tuple[str, ...] = ()
    whole: bool = True


class Registry:
    """Implementations of one ``role`` by name; ``what`` names one in messages ("frontend").

    ``builtins``: name -> module registering it when imported; ``aliases``: other name -> name;
    ``key`` and ``options_key``: the config keys of the name and of the options, named in errors.
    Iterating gives the names (built-ins first, in their order), ``in`` accepts aliases too.
    """

    def __init__(self, role: str, what: str, builtins: Mapping[str, str] | None = None,
                 aliases: Mapping[str, str] | None = None, key: str | None = None,
                 options_key: str | None = None, group: str | None = None):  # fmt: skip
        self.role, self.what = role, what
        self.key = key or role
        self.options_key = options_key or f"{self.key}.options"
        self.group = group or f"slam2d.{role}"
        self.builtins = dict(builtins or {})
        self.aliases = dict(aliases or {})
        self._entries: dict[str, Entry] = {}
        _REGISTRIES[role] = self

    def __repr__(self) -> str:
        return f"Registry({self.role!r}: {', '.join(self.names())})"

    # -- registering

    def register(self, name: str, *, aliases: Iterable[str] = (), config: type[BaseModel] | None = None,
                 options_of: Iterable = (), takes: Iterable[str] = ()):  # fmt: skip
        """Decorator of a class or function: make it available as ``name`` (see :meth:`add`)."""

        def decorate(obj):
            self.add(name, obj, aliases=aliases, config=config, options_of=options_of, takes=takes)
            return obj

        return decorate

    def add(self, name: str, obj, *, aliases: Iterable[str] = (), config: type[BaseModel] | None = None,
            options_of: Iterable = (), takes: Iterable[str] = ()) -> None:  # fmt: skip
        """Register ``obj`` as ``name`` (and ``aliases``). ``config``: its options model (default: a class's
        nested pydantic ``Config``; for a function, its parameters with defaults and those of the functions
        ``options_of`` its ``**kwargs`` go to). ``takes``: the role's inputs it is given, never options."""
        takes = tuple(takes)
        if config is None and inspect.isclass(obj):
            nested = getattr(obj, "Config", None)
            config = nested if inspect.isclass(nested) and issubclass(nested, BaseModel) else None
        whole = config is not None or inspect.isclass(obj)
        if config is None and callable(obj) and not inspect.isclass(obj):  # an object that is no callable: none
            config = options_model(obj, *options_of, skip=takes, name=f"{name}_options")
        self._entries[name] = Entry(obj, config, takes, whole)
        for alias in aliases:
            self.aliases[alias] = name

    # -- looking up

    def canonical(self, name) -> str | None:
        """The registered name ``name`` is or is an alias of (built-ins imported, entry points loaded as
        needed); None if no implementation has it."""
        if not isinstance(name, str):
            return None
        found = self._known(name)
        if found is None and self._import_builtin(self.aliases.get(name, name)):
            found = self._known(name)
        if found is None:
            self._load_entry_points()
            found = self._known(name)
        return found

    def _known(self, name: str) -> str | None:
        name = self.aliases.get(name, name)
        return name if name in self._entries else None

    def _import_builtin(self, name: str) -> bool:
        module = self.builtins.get(name)
        if module is None or find_spec(module) is None:
            return False
        import_module(module)
        return True

    def _load_entry_points(self) -> None:
        for ep in entry_points(group=self.group):
            if ep.name not in self._entries:
                obj = ep.load()  # a module registering it on import, or the implementation itself
                if ep.name not in self._entries:
                    self.add(ep.name, obj)

    def __contains__(self, name) -> bool:
        return self.canonical(name) is not None

    def names(self) -> list[str]:
        """Every name: the built-ins (in their order), then the others as registered, then entry points'."""
        listed = [n for n, m in self.builtins.items() if n not in self.aliases and find_spec(m) is not None]
        listed += self._entries
        listed += [ep.name for ep in entry_points(group=self.group)]
        return list(dict.fromkeys(listed))

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self.names())

    def entry(self, name, key: str | None = None) -> Entry:
        """The :class:`Entry` of ``name``; an InputError naming ``key`` (default: the registry's) if unknown."""
        found = self.canonical(name)
        if found is None:
            raise self.unknown(name, key)
        return self._entries[found]

    def get(self, name, key: str | None = None):
        """The implementation registered as ``name`` (or an alias of it)."""
        return self.entry(name, key).obj

    def __getitem__(self, name):
        return self.get(name)

    def config(self, name) -> type[BaseModel] | None:
        """The options model of ``name`` (None if it takes no options)."""
        return self.entry(name).config

    def takes(self, name) -> tuple[str, ...]:
        """The role's inputs ``name`` takes (keywords of :meth:`create` passed on to it)."""
        return self.entry(name).takes

    def unknown_message(self, name) -> str:
        """"unknown WHAT 'name' (available: ...)": the names, then the aliases with what they stand for."""
        aliases = [f"{a} (= {n})" for a, n in self.aliases.items()]
        return f"unknown {self.what} {short_repr(name)} (available: {', '.join([*self.names(), *aliases])})"

    def unknown(self, name, key: str | None = None) -> InputError:
        """The error of a name no implementation has, listing the available ones."""
        return InputError(key or self.key, self.unknown_message(name))

    # -- options and instances

    def check_options(self, name, options=None) -> BaseModel | None:
        """``options`` (a mapping, or the model itself) as the options model of ``name``: pydantic's
        ValidationError if they do not fit; None for an implementation that takes none (and got none)."""
        model = self.entry(name).config
        if model is not None and isinstance(options, model):
            return options
        if model is None and not options:
            return None
        return (model or _NoOptions).model_validate(dict(options or {}))

    def resolve_options(self, name, options=None, key: str | None = None) -> BaseModel | None:
        """The options model of ``name`` filled from ``options`` (its defaults for what they do not give);
        an InputError naming the full dotted key (``key``: where the options are, default ``options_key``)."""
        key = key or self.options_key
        try:
            return self.check_options(name, options)
        except ValidationError as err:
            raise validation_error(err, key, model=self.entry(name).config or _NoOptions) from None

    def options_in(self, name, section) -> dict[str, Any]:
        """The values of ``section`` (a model or mapping) that are options of ``name``: for roles whose
        implementations' parameters are keys of a shared config section."""
        model = self.entry(name).config
        values = section.model_dump() if isinstance(section, BaseModel) else dict(section)
        return {k: v for k, v in values.items() if model is not None and k in model.model_fields}

    def create(self, name, options=None, *args, **inputs):
        """Build (or, for a function, call) the implementation ``name`` with ``args``, its checked options
        and the ``inputs`` it takes (others are dropped). An InputError names a bad name or option."""
        entry = self.entry(name)
        config = self.resolve_options(name, options)
        given = {k: v for k, v in inputs.items() if k in entry.takes}
        if config is None:
            return entry.obj(*args, **given)
        if entry.whole:
            return entry.obj(*args, config, **given)
        return entry.obj(*args, **{f: getattr(config, f) for f in type(config).model_fields}, **given)

    # -- listing

    def describe(self, name) -> str:
        """The first paragraph of the implementation's docstring on one line ("" without one)."""
        doc = inspect.getdoc(self.get(name)) or ""
        return " ".join(doc.split("\n\n")[0].split())

    def catalog(self) -> dict[str, str]:
        """Name -> one-line description of every implementation (a module that cannot be imported says so)."""
        out = {}
        for name in self.names():
            try:
                out[name] = self.describe(name)
            except ImportError as err:
                out[name] = f"(cannot be imported: {err})"
        return out


def lazy_exports(package: str, exports: Mapping[str, str]):
    """A package's module ``__getattr__`` giving each public name of ``exports`` (name -> submodule) from
    its submodule, imported on first use, so that importing the package stays light."""

    def attribute(name: str):
        if name in exports:
            return getattr(import_module(f"{package}.{exports[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return attribute


def role(name: str) -> Registry:
    """The registry of the role ``name`` (its module imported if it is a built-in role not loaded yet)."""
    if name not in _REGISTRIES and name in ROLES:
        import_module(ROLES[name])
    if name not in _REGISTRIES:
        raise InputError("role", f"unknown role {short_repr(name)} (available: {', '.join(roles())})")
    return _REGISTRIES[name]


def roles() -> list[str]:
    """The names of all roles: the built-in ones, then those other packages defined."""
    return list(dict.fromkeys([*ROLES, *_REGISTRIES]))


def catalog() -> dict[str, dict[str, str]]:
    """Role -> (name -> one-line description) of every implementation of every role."""
    return {r: role(r).catalog() for r in roles()}


def options_model(*functions, skip: Iterable[str] = (), name: str | None = None) -> type[BaseModel]:
    """A pydantic model (unknown keys refused) of the parameters with defaults of ``functions`` (the first
    one's win), but ``skip``: their options. Types come from the annotations where they resolve."""
    fields: dict[str, tuple[Any, Any]] = {}
    skip = set(skip)
    for fn in functions:
        try:
            hints = get_type_hints(fn)
        except Exception:  # noqa: BLE001 - an annotation that does not resolve: no type check then
            hints = {}
        for p in inspect.signature(fn).parameters.values():
            if p.default is p.empty or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) or p.name in skip:
                continue
            fields.setdefault(p.name, (hints.get(p.name, Any), p.default))
    config = ConfigDict(extra="forbid", arbitrary_types_allowed=True)
    return create_model(name or f"{functions[0].__name__}_options", __config__=config, **fields)


class Choice:
    """Annotation of a config field naming an implementation: ``Annotated[str, Choice("frontends")]``.

    The name is checked against the role's registry when the config is validated and made canonical (an
    alias replaced) unless ``canonical`` is False; ``also``: further names that choose no implementation
    ("none"). ``options``: the sibling field holding the implementation's options, checked with the name
    (see :func:`check_choices`) and completed by :func:`resolve_config`. ``lazy``: both are checked only
    by :func:`resolve_config`, when a name may come from a plugin given after the config was read.
    """

    def __init__(self, role: str, options: str | None = None, also: Iterable[str] = (), canonical: bool = True,
                 lazy: bool = False):  # fmt: skip
        self.role, self.options, self.also, self.canonical, self.lazy = role, options, tuple(also), canonical, lazy

    def __get_pydantic_core_schema__(self, source, handler):
        return core_schema.no_info_after_validator_function(self._check, handler(source))

    def _check(self, name: str) -> str:
        if self.lazy or name in self.also:
            return name
        registry = role(self.role)
        found = registry.canonical(name)
        if found is None:
            raise PydanticCustomError(UNKNOWN_NAME, "{message}", {"message": registry.unknown_message(name)})
        return found if self.canonical else name


def _choices(model: type[BaseModel]) -> Iterator[tuple[str, Choice]]:
    """The fields of ``model`` that name an implementation, with their :class:`Choice`."""
    for field, info in model.model_fields.items():
        for meta in info.metadata:
            if isinstance(meta, Choice):
                yield field, meta


def check_choices(section: BaseModel) -> None:
    """For a model validator: the options of every implementation ``section`` names (not lazily) fit it;
    a pydantic error located at the offending key otherwise. Empty options are not checked (the defaults)."""
    for field, choice in _choices(type(section)):
        name, options = getattr(section, field), getattr(section, choice.options) if choice.options else None
        if choice.lazy or not options or name in choice.also:
            continue
        registry = role(choice.role)
        try:
            registry.check_options(name, options)
        except ValidationError as err:
            e = err.errors()[0]
            raise PydanticCustomError(BAD_OPTIONS, "{msg}", {
                "msg": e["msg"], "type": e["type"], "loc": (choice.options, *e["loc"]), "input": e.get("input"),
                "valid": _valid_keys(registry.config(name) or _NoOptions, e["loc"])}) from None


def resolve_config(cfg: BaseModel, key: str = "") -> BaseModel:
    """``cfg`` with the options of every implementation it names completed by their defaults (names and
    options checked, an InputError naming the key); the same object if nothing changes."""
    update = {}
    for field in type(cfg).model_fields:
        value = getattr(cfg, field)
        if isinstance(value, BaseModel):
            done = resolve_config(value, f"{key}{field}.")
            if done is not value:
                update[field] = done
    for field, choice in _choices(type(cfg)):
        name = getattr(cfg, field)
        if name in choice.also:
            continue
        registry = role(choice.role)
        registry.entry(name, f"{key}{field}")
        if choice.options:
            params = registry.resolve_options(name, getattr(cfg, choice.options), f"{key}{choice.options}")
            if params is not None:
                update[choice.options] = params.model_dump()
    return cfg.model_copy(update=update) if update else cfg


def _valid_keys(model: type[BaseModel] | None, loc) -> list[str] | None:
    """The keys a model accepts at the location of an unknown key ``loc`` (the nested model's), if known."""
    for part in tuple(loc)[:-1]:
        if model is None:
            return None
        info = model.model_fields.get(part) if isinstance(part, str) else None
        nested = info.annotation if info is not None else None
        model = nested if inspect.isclass(nested) and issubclass(nested, BaseModel) else None
    return list(model.model_fields) if model is not None else None


def validation_error(err: ValidationError, key: str = "", source: str | None = None,
                     model: type[BaseModel] | None = None) -> InputError:  # fmt: skip
    """The first error of ``err`` as one InputError. Its dotted key is ``key`` (where the validated values sit
    in a config) followed by the error's location. ``where`` is ``source`` (a file, "config") with the key in
    the message, or without a source the key itself. An unknown key lists the valid ones (``model``'s)."""
    e = err.errors()[0]
    loc, kind, msg, given, valid = tuple(e["loc"]), e["type"], e["msg"], e.get("input"), None
    if kind == BAD_OPTIONS:  # options an implementation refused: its own error, one level down
        ctx = e["ctx"]
        loc, kind, msg, given, valid = (*loc, *ctx["loc"]), ctx["type"], ctx["msg"], ctx["input"], ctx["valid"]
    dotted = ".".join(p for p in [key, *map(str, loc)] if p) or "<root>"
    if kind == "extra_forbidden":
        valid = valid if valid is not None else _valid_keys(model, loc)
        listing = "" if valid is None else f" (valid: {', '.join(valid)})" if valid else " (it takes no options)"
        if source:
            return InputError(source, f"unknown key '{dotted}'{listing}")
        return InputError(dotted, f"unknown key{listing}")
    what = msg if kind == UNKNOWN_NAME else f"{msg} (got {short_repr(given)})"
    return InputError(source, f"key '{dotted}': {what}") if source else InputError(dotted, what)
