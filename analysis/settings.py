"""Settings declared once: each field with its type, unit (in the name), default, bounds and doc.

The settings classes are pydantic dataclasses made by :func:`settings` (``@settings()``): still
frozen standard dataclasses (``dataclasses.replace``, ``fields`` and ``asdict`` work), validated
on construction by pydantic from the declarations (``Annotated`` types with
``Field(gt=..., description=...)``); a bad value given in Python raises :class:`ConfigError`
reading ``ControlSettings.max_drive_v: must be > 0, got 0``. Everything else is derived from the
declarations:

- :func:`build` reads plain data (parsed TOML, a ``to_dict()``, a service request) into a
  settings class; a problem raises :class:`ConfigError` whose :attr:`ConfigError.path` is the
  key path as a tuple (``("excitation", "levels_n", 1)``) and whose message reads
  ``plan my.toml: excitation.levels_n[1]: must be > 0, got -4.0``;
- :func:`dump` writes the plain data back (what ``to_dict()`` returns and TOML files hold);
- :func:`declared_fields` lists the fields with their kind, choices and one-line doc (the GUI's
  forms and tooltips).

Checks that involve several fields stay in ``__post_init__``; a :class:`SettingError` raised
there names the field it concerns, relative to the class, so its location is structured too.

This module is the generic layer and lives in ``analysis`` (the bottom package) so that the
model file, the simulator's truth files and the lab application's plans and setups
(:mod:`rig.config.settings`, which adds the harmonic-order type) all read through it. Why
pydantic rather than attrs + cattrs is said in ``docs/architecture.md`` (practice 3).
"""

from __future__ import annotations

import functools
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Annotated, Any, Literal, TypeVar

import pydantic.dataclasses
from pydantic import ConfigDict, Field, Strict, TypeAdapter
from pydantic import ValidationError as _ValidationError

__all__ = [
    "SETTINGS",
    "ConfigError",
    "KeyPath",
    "dotted",
    "DeclaredField",
    "Flag",
    "Integer",
    "NonNegative",
    "Number",
    "Positive",
    "SettingError",
    "Text",
    "build",
    "declare",
    "declared_fields",
    "dump",
    "settings",
]

T = TypeVar("T")

#: A key path: table keys and array indices, ``("excitation", "levels_n", 1)``.
KeyPath = tuple[str | int, ...]


def dotted(path: KeyPath) -> str:
    """``("frequencies", "ranges", 0, "stop_hz")`` -> ``"frequencies.ranges[0].stop_hz"``."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


class ConfigError(ValueError):
    """A settings document (a model file, a truth, a setup, a plan) is invalid.

    ``ConfigError(source, path, problem)`` reads ``"source: key.path[1]: problem"``
    (``"Class.key.path[1]: problem"`` with ``joined``, for a class built in Python); its
    :attr:`path` (a :data:`KeyPath`, empty for the whole document) and :attr:`problem` are kept
    for whoever shows the error at its field. ``ConfigError(message)`` is a problem of no key.
    """

    path: KeyPath

    def __init__(
        self, source: str, path: KeyPath | None = None, problem: str = "", joined: bool = False
    ) -> None:
        if path is None:
            self.source, self.path, self.problem = "", (), source
            super().__init__(source)
            return
        self.source, self.path, self.problem = source, tuple(path), problem
        where = dotted(self.path)
        if joined:
            super().__init__(f"{source}.{where}: {problem}" if where else f"{source}: {problem}")
        else:
            where = where or "(root)"
            super().__init__(f"{source}: {where}: {problem}" if source else f"{where}: {problem}")

    @property
    def key(self) -> str:
        """The key path as text (``"excitation.levels_n[1]"``; empty for the document)."""
        return dotted(self.path)


#: The configuration of every settings class: unknown keys are errors (a misspelt key is not a
#: silently ignored setting), numbers must be finite. A field may be declared with a shorter
#: file key (``validation_alias`` and ``serialization_alias``, ``b`` for ``b_m``): Python code
#: passes the field's name, :func:`build` reads only the file key and :func:`dump` writes it.
SETTINGS = ConfigDict(
    extra="forbid",
    allow_inf_nan=False,
    validate_default=True,
    validate_by_name=True,
    validate_by_alias=True,
)

# Scalars are strict (TOML's "2" is not the number 2, true is not 1; an integer is a number);
# arrays are lax so that Python callers may pass lists.
Number = Annotated[float, Strict()]
Integer = Annotated[int, Strict()]
Flag = Annotated[bool, Strict()]
Text = Annotated[str, Strict()]
Positive = Annotated[Number, Field(gt=0)]
NonNegative = Annotated[Number, Field(ge=0)]


def declare(doc: str, default: Any = ..., key: str | None = None, **bounds: Any) -> Any:
    """A declared setting's default (``...``: required), one-line doc, file key (``None``: the
    field's name) and bounds (``gt``, ``ge``, ``lt``, ``le``, ``min_length``)."""
    if key is not None:
        bounds |= {"validation_alias": key, "serialization_alias": key}
    return Field(default, description=doc, **bounds)


class SettingError(ValueError):
    """A problem found by a check of several fields, at ``path`` relative to the class."""

    def __init__(self, path: KeyPath, problem: str) -> None:
        self.path = tuple(path)
        self.problem = problem
        super().__init__(f"{dotted(self.path)}: {problem}" if self.path else problem)


# ------------------------------------------------------------------------ reading


_ADAPTERS: dict[type, TypeAdapter[Any]] = {}


def _adapter(cls: type) -> TypeAdapter[Any]:
    if cls not in _ADAPTERS:
        _ADAPTERS[cls] = TypeAdapter(cls)
    return _ADAPTERS[cls]


def _value_error(err: Mapping[str, Any]) -> tuple[KeyPath, str, BaseException | None]:
    exc = err.get("ctx", {}).get("error")
    if isinstance(exc, SettingError):
        return exc.path, exc.problem, exc
    if isinstance(exc, BaseException):
        return (), str(exc), exc
    return (), str(err["msg"]), None


_PROBLEMS = {
    "missing": "missing (required)",
    "greater_than": "must be > {gt:g}, got {input!r}",
    "greater_than_equal": "must be >= {ge:g}, got {input!r}",
    "less_than": "must be < {lt:g}, got {input!r}",
    "less_than_equal": "must be <= {le:g}, got {input!r}",
    "float_type": "expected a number, got {input!r}",
    "finite_number": "must be finite, got {input!r}",
    "int_type": "expected an integer, got {input!r}",
    "bool_type": "expected true or false, got {input!r}",
    "string_type": "expected a string, got {input!r}",
    "literal_error": "expected {expected}, got {input!r}",
    "tuple_type": "expected an array, got {input!r}",
    "too_short": "expected at least {min_length} entries, got {input!r}",
    "dataclass_type": "expected a table, got {input!r}",
    "dict_type": "expected a table, got {input!r}",
    "dataclass_exact_type": "expected a table, got {input!r}",
}


def _problem(err: Mapping[str, Any]) -> str:
    template = _PROBLEMS.get(err["type"])
    if template is None:
        return str(err["msg"])
    return template.format(input=err.get("input"), **err.get("ctx", {}))


def _first_error(cls: type, exc: _ValidationError, file: bool = False) -> ConfigError:
    """The first problem of ``exc``; ``file``: located by file keys rather than field names."""
    errors = exc.errors()
    unknown = [e for e in errors if e["type"] in ("unexpected_keyword_argument", "extra_forbidden")]
    if unknown:
        # every misspelt key of the first table that has one, and what that table knows
        table = _file_path(cls, tuple(unknown[0]["loc"][:-1]))
        keys = [str(e["loc"][-1]) for e in unknown if tuple(e["loc"][:-1]) == table]
        known = ", ".join(_known_keys(cls, table)) or "none"
        problem = f"unknown key(s) {', '.join(map(repr, keys))} (known here: {known})"
        return ConfigError("", table, problem)
    err = errors[0]
    # a table's key is located as (..., key, "[key]"): the key is the location
    loc: KeyPath = tuple(p for p in err["loc"] if p != "[key]")
    path = _file_path(cls, loc)
    cause: BaseException | None = None
    if err["type"] in ("value_error", "assertion_error"):
        where, problem, cause = _value_error(err)
        path = _file_path(cls, loc + where) if file else path + where
    else:
        problem = _problem(err)
    error = ConfigError("", path, problem)
    error.__cause__ = cause
    return error


@typing.dataclass_transform(frozen_default=True, field_specifiers=(Field,))
def settings(*, kw_only: bool = False) -> Callable[[type[T]], type[T]]:
    """Make a class of declared settings: a frozen pydantic dataclass configured with
    :data:`SETTINGS` whose construction in Python reports a bad value as a
    :class:`ConfigError` naming the class and the field."""

    def make(cls: type[T]) -> type[T]:
        made: Any = pydantic.dataclasses.dataclass(frozen=True, config=SETTINGS, kw_only=kw_only)(
            cls
        )
        init = made.__init__

        @functools.wraps(init)
        def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
            try:
                init(self, *args, **kwargs)
            except _ValidationError as exc:
                first = _first_error(made, exc)
                raise ConfigError(made.__name__, first.path, first.problem, joined=True) from (
                    first.__cause__
                )

        made.__init__ = __init__
        return typing.cast(type[T], made)

    return make


def build(
    cls: type[T],
    data: Any,
    source: str,
    at: KeyPath = (),
    error: Callable[[str, KeyPath, str], ConfigError] = ConfigError,
) -> T:
    """Read plain data into the settings class ``cls``; ``at`` is where the data sit in the
    document (``("truth", "noise")``), put before the key path of an error, and ``error``
    makes the error (a reader's own :class:`ConfigError` subclass).

    Raises
    ------
    ConfigError
        Naming ``source`` and the key path of the first problem (:attr:`ConfigError.path`);
        its ``__cause__`` is the exception a cross-field check raised, if one did.
    """
    if not isinstance(data, Mapping):
        raise error(source, at, f"expected a table, got {data!r}")
    try:
        return _adapter(cls).validate_python(dict(data), by_name=False)
    except _ValidationError as exc:
        first = _first_error(cls, exc, file=True)
        raise error(source, (*at, *first.path), first.problem) from first.__cause__


def dump(
    value: Any, *, exclude_defaults: bool = False, exclude: set[str] | None = None
) -> dict[str, Any]:
    """The plain data of a settings object (lists, strings, numbers; unset optionals left
    out), as :func:`build` reads it back, under the file keys.

    ``exclude_defaults`` also leaves out every field (in nested tables too) whose value is its
    declared default, which :func:`build` supplies again: a file written for people then holds
    what differs from the defaults. ``exclude`` leaves out fields by name (a name the document
    holds elsewhere, as a table key, or a value derived from other fields). Floats stay floats:
    an infinite value is ``inf``, never ``None`` or a string.
    """
    return _adapter(type(value)).dump_python(
        value,
        mode="json",
        exclude_none=True,
        by_alias=True,
        exclude_defaults=exclude_defaults,
        exclude=exclude,
    )


# ------------------------------------------------------------------------ declarations


@dataclass(frozen=True)
class DeclaredField:
    """One declared setting: its name, kind, choices, default, one-line doc and file key.

    ``kind`` is ``number``, ``integer``, ``flag``, ``text``, ``choice``, ``numbers``,
    ``integers``, ``words`` (orders), ``table`` or ``rows`` (an array of tables); ``of`` is the
    class of a ``table`` or ``rows`` field.
    """

    name: str
    kind: str
    doc: str
    default: Any
    choices: tuple[str, ...] = ()
    of: type | None = None
    key: str = ""

    def __post_init__(self) -> None:
        if not self.key:
            object.__setattr__(self, "key", self.name)


def _strip(annotation: Any) -> Any:
    """The annotation without ``Annotated`` metadata and without ``| None``."""
    while typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return _strip(args[0])
    return annotation


def _kind(annotation: Any) -> tuple[str, tuple[str, ...], type | None]:
    bare = _strip(annotation)
    origin = typing.get_origin(bare)
    if origin is Literal:
        return "choice", tuple(typing.get_args(bare)), None
    if origin is tuple:
        item = _strip(typing.get_args(bare)[0])
        if hasattr(item, "__pydantic_fields__"):
            return "rows", (), item
        scalar = {int: "integers", float: "numbers", Fraction: "words"}
        return scalar.get(item, "words"), (), None
    if hasattr(bare, "__pydantic_fields__"):
        return "table", (), bare
    return {bool: "flag", int: "integer", float: "number"}.get(bare, "text"), (), None


def declared_fields(cls: type) -> list[DeclaredField]:
    """The declared settings of a settings class, in declaration order."""
    out = []
    for name, info in cls.__pydantic_fields__.items():  # type: ignore[attr-defined]
        kind, choices, of = _kind(info.rebuild_annotation())
        default = None if info.is_required() else info.get_default(call_default_factory=True)
        key = info.validation_alias if isinstance(info.validation_alias, str) else name
        out.append(DeclaredField(name, kind, info.description or "", default, choices, of, key))
    return out


def _field(cls: type, part: str) -> DeclaredField | None:
    """The field of ``cls`` named ``part`` or read from the file key ``part``."""
    return next((f for f in declared_fields(cls) if part in (f.name, f.key)), None)


def _file_path(cls: type, loc: KeyPath) -> KeyPath:
    """A location in the objects as a key path in the file (flattened tables left out, fields
    named by their file keys)."""
    out: list[str | int] = []
    for part in loc:
        if isinstance(part, int) or cls is None:
            out.append(part)
            continue
        found = _field(cls, str(part))
        if part not in getattr(cls, "__flattened__", {}):
            out.append(part if found is None else found.key)
        cls = None if found is None else found.of  # type: ignore[assignment]
    return tuple(out)


def _known_keys(cls: type, table: KeyPath) -> list[str]:
    """The keys the table at ``table`` (a path from ``cls``) accepts, as far as declared."""
    for part in table:
        if isinstance(part, int):
            continue
        found = {f.name: f.of for f in declared_fields(cls)}.get(str(part))
        if found is None:
            return []
        cls = found
    hidden = getattr(cls, "__flattened__", {})
    names = [f.key for f in declared_fields(cls) if f.name not in hidden]
    for inner in hidden.values():
        names += [f.key for f in declared_fields(inner) if f.name not in _set_elsewhere(cls)]
    return sorted(names)


def _set_elsewhere(cls: type) -> Mapping[str, str]:
    return getattr(cls, "__set_elsewhere__", {})
