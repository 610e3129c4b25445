"""The entries of a settings form, without Qt: fields generated from the settings classes and
values to and from text.

A form edits a *settings document*: the nested plain data that a plan's or a setup's
``to_dict()`` gives and ``plan_from_dict`` / ``setup_from_dict`` read back. Its fields are
generated from the classes themselves (:func:`dataclass_fields`): one field per setting, its
label from the name (the unit suffix becomes a unit in brackets: ``ramp_s`` -> ``ramp [s]``).
For the classes declared in :mod:`rig.config.settings` (plans, setups) the kind, the choices and
the tooltip are the declaration's; for plain dataclasses the kind follows the default's type
and the tooltip comes from the class docstring's Parameters section. Text that is not a number
is passed on as typed, so the loader's own message says what is wrong with it
(:func:`parse_value`); that error carries its key path (:class:`rig.config.tomlconfig.ConfigError`).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from rig.config.settings import declared_fields

__all__ = [
    "KINDS",
    "Field",
    "dataclass_fields",
    "format_value",
    "get_key",
    "label_of",
    "parameter_docs",
    "parse_value",
    "put_key",
]


# unit suffixes of the settings' field names, longest first
_UNITS = (
    ("_m_s2", "m/s²"),
    ("_v_per_v", "V/V"),
    ("_hz", "Hz"),
    ("_deg", "deg"),
    ("_kg", "kg"),
    ("_s", "s"),
    ("_v", "V"),
    ("_n", "N"),
    ("_m", "m"),
)

KINDS = ("number", "integer", "flag", "text", "choice", "numbers", "integers", "words")


@dataclass(frozen=True)
class Field:
    """One entry of a settings document.

    Attributes
    ----------
    key : str
        Dotted key path in the document (``"acquisition.settle_periods"``).
    label : str
    kind : str
        ``number``, ``integer``, ``flag``, ``text``, ``choice`` (one of ``choices``),
        ``numbers``, ``integers`` or ``words`` (comma-separated lists).
    choices : tuple of str
    tooltip : str
    optional : bool
        An empty entry is left out of the document (the setting's default applies).
    """

    key: str
    label: str
    kind: str
    choices: tuple[str, ...] = ()
    tooltip: str = ""
    optional: bool = True

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"Field {self.key!r}: kind must be one of {KINDS}, got {self.kind!r}")

    @property
    def name(self) -> str:
        """Last part of the key."""
        return self.key.rsplit(".", 1)[-1]


def label_of(name: str) -> str:
    """A field name as a label: words, and the unit suffix as a unit (``ramp_s`` ->
    ``ramp [s]``)."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return f"{name[: -len(suffix)].replace('_', ' ')} [{unit}]"
    return name.replace("_", " ")


def parameter_docs(cls: type) -> dict[str, str]:
    """Descriptions of the Parameters section of a numpydoc class docstring, by name."""
    doc = inspect.getdoc(cls) or ""
    match = re.search(r"^Parameters\n-+\n(.*?)(?:^\S[^\n]*\n-+\n|\Z)", doc, re.S | re.M)
    if not match:
        return {}
    out: dict[str, str] = {}
    names: list[str] = []
    for line in match.group(1).splitlines():
        if line and not line.startswith(" "):
            names = [n.strip() for n in line.split(":", 1)[0].split(",")]
            for n in names:
                out.setdefault(n, "")
        elif line.strip() and names:
            for n in names:
                out[n] = (out[n] + " " + line.strip()).strip()
    return out


def dataclass_fields(
    cls: type,
    prefix: str = "",
    *,
    skip: Iterable[str] = (),
    choices: Mapping[str, tuple[str, ...]] | None = None,
    kinds: Mapping[str, str] | None = None,
    labels: Mapping[str, str] | None = None,
) -> list[Field]:
    """The fields of a settings class, as its reader reads them.

    A class declared in :mod:`rig.config.settings` gives its declarations (sub-tables and
    arrays of tables left to the caller, flattened tables spread in). For a plain dataclass the
    kind follows the default's type (bool: flag, int: integer, float or None: number, tuple:
    numbers, str: text); ``choices`` and ``kinds`` override it.
    """
    if hasattr(cls, "__pydantic_fields__"):
        return _declared(cls, prefix, set(skip), dict(labels or {}))
    choices, kinds, labels = dict(choices or {}), dict(kinds or {}), dict(labels or {})
    docs = parameter_docs(cls)
    skipped = set(skip)
    out = []
    for f in dataclasses.fields(cls):
        if f.name in skipped or f.name.startswith("_"):
            continue
        default: Any = None
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        if f.name in choices:
            kind = "choice"
        elif f.name in kinds:
            kind = kinds[f.name]
        elif isinstance(default, bool):
            kind = "flag"
        elif isinstance(default, int):
            kind = "integer"
        elif isinstance(default, float) or default is None:
            kind = "number"
        elif isinstance(default, tuple):
            kind = "numbers"
        else:
            kind = "text"
        out.append(
            Field(
                f"{prefix}.{f.name}" if prefix else f.name,
                labels.get(f.name, label_of(f.name)),
                kind,
                tuple(choices.get(f.name, ())),
                docs.get(f.name, ""),
            )
        )
    return out


def _declared(cls: type, prefix: str, skip: set[str], labels: Mapping[str, str]) -> list[Field]:
    flattened = getattr(cls, "__flattened__", {})
    elsewhere = set(getattr(cls, "__set_elsewhere__", {}))
    out = []
    for d in declared_fields(cls):
        if d.name in skip:
            continue
        if d.name in flattened:
            out += _declared(flattened[d.name], prefix, skip | elsewhere, labels)
        elif d.kind not in ("table", "rows"):
            key = f"{prefix}.{d.name}" if prefix else d.name
            out.append(Field(key, labels.get(d.name, label_of(d.name)), d.kind, d.choices, d.doc))
    return out


# ------------------------------------------------------------------------ values and text


def format_value(value: Any) -> str:
    """A document value as the text of an entry."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isfinite(value) and value.is_integer() and abs(value) < 1e12:
            return str(int(value))
        return repr(value)
    if isinstance(value, list | tuple):
        return ", ".join(format_value(v) for v in value)
    return str(value)


def _number(token: str) -> Any:
    try:
        return int(token)
    except ValueError:
        pass
    try:
        return float(token)
    except ValueError:
        return token  # the loader says what is wrong with it


def parse_value(kind: str, text: str) -> Any:
    """The document value of an entry's text (None: left out).

    Text that is not a number stays text, so the settings' loader reports it with its key
    (``expected a number, got 'abc'``).
    """
    text = text.strip()
    if kind in ("text", "choice"):
        return text
    if not text:
        return None
    if kind == "flag":
        flags = {"true": True, "yes": True, "1": True, "false": False, "no": False, "0": False}
        return flags.get(text.lower(), text)
    if kind == "number":
        value = _number(text)
        return float(value) if isinstance(value, int) else value
    if kind == "integer":
        return _number(text)
    tokens = [t for t in re.split(r"[,\s;]+", text) if t]
    if kind == "words":
        return tokens
    if kind == "numbers":
        return [float(v) if isinstance(v, int) else v for v in map(_number, tokens)]
    return [_number(t) for t in tokens]  # integers


def get_key(doc: Mapping[str, Any], key: str) -> Any:
    node: Any = doc
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return None
        node = node[part]
    return node


def put_key(doc: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    node = doc
    for part in parts[:-1]:
        node = node.setdefault(part, {})
    node[parts[-1]] = value
