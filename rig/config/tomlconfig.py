"""Reading validated settings from TOML tables: typed getters whose errors name the key.

Lab setups (:mod:`rig.config.setup`) and test plans (:mod:`rig.config.plans`) are TOML files turned
into frozen
dataclasses. :class:`Table` wraps one TOML table with the path of keys that leads to it, hands
out typed values, and refuses keys nobody asked for (a misspelt key is an error, not a silently
ignored setting). Every error is a :class:`ConfigError` whose message starts with the source
(file or built-in name) and the full key path, e.g.
``plan 'paper' (rig/plans/paper.toml): excitation.levels_n[2]: must be > 0, got -4``.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["REQUIRED", "ConfigError", "KeyPath", "Table", "dotted", "read_toml"]

#: A key path: table keys and array indices, ``("excitation", "levels_n", 1)``.
KeyPath = tuple[str | int, ...]


def dotted(path: KeyPath) -> str:
    """``("frequencies", "ranges", 0, "stop_hz")`` -> ``"frequencies.ranges[0].stop_hz"``."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


class ConfigError(ValueError):
    """A setup or plan is invalid.

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


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()
"""Marker default: the key must be present."""


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file, turning syntax errors into :class:`ConfigError`."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} ({path})", (), f"not valid TOML: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"{what}: cannot read {path}: {exc.strerror or exc}") from exc


class Table:
    """One TOML table being read.

    Parameters
    ----------
    data : mapping
        The table's contents.
    source : str
        Where it comes from, e.g. ``"setup 'reference' (rig/setups/reference.toml)"``.
    path : KeyPath
        Key path of this table inside the document (empty for the root).
    """

    def __init__(self, data: Mapping[str, Any], source: str, path: KeyPath = ()) -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(source, path, f"expected a table, got {data!r}")
        self._data = dict(data)
        self.source = source
        self.path = path
        self._used: set[str] = set()

    # -- errors ---------------------------------------------------------------------------------
    def key_path(self, key: str | int) -> KeyPath:
        """Full key path of ``key``."""
        return (*self.path, key)

    def error(self, key: str | None, problem: str, index: int | None = None) -> ConfigError:
        """A :class:`ConfigError` for ``key`` (entry ``index`` of it) of this table, or the
        table itself."""
        where = self.path if key is None else self.key_path(key)
        return ConfigError(self.source, where if index is None else (*where, index), problem)

    @contextmanager
    def checking(self, key: str | None = None) -> Iterator[None]:
        """Re-raise a ``ValueError``, ``TypeError`` or ``ArithmeticError`` (an overflow from an
        infinite or huge number) from a constructor with this key path."""
        try:
            yield
        except ConfigError:
            raise
        except (ValueError, TypeError, ArithmeticError) as exc:
            raise self.error(key, str(exc)) from exc

    # -- access ---------------------------------------------------------------------------------
    def __contains__(self, key: str) -> bool:
        return key in self._data

    def raw(self, key: str, default: Any = REQUIRED) -> Any:
        """The value of ``key`` as parsed (marks it as used)."""
        self._used.add(key)
        if key not in self._data:
            if default is REQUIRED:
                raise self.error(key, "missing (required)")
            return default
        return self._data[key]

    def text(self, key: str, default: Any = REQUIRED, choices: tuple[str, ...] | None = None):
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.error(key, f"expected one of {', '.join(map(repr, choices))}, got {value!r}")
        return value

    def flag(self, key: str, default: Any = REQUIRED):
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {value!r}")
        return value

    def integer(self, key: str, default: Any = REQUIRED, minimum: int | None = None):
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {value!r}")
        if minimum is not None and value < minimum:
            raise self.error(key, f"must be >= {minimum}, got {value}")
        return value

    def number(
        self,
        key: str,
        default: Any = REQUIRED,
        positive: bool = False,
        minimum: float | None = None,
    ):
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        return self._number(key, value, positive, minimum)

    def _number(
        self, key: str, value: Any, positive: bool, minimum: float | None, index: int | None = None
    ) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"expected a number, got {value!r}", index)
        x = float(value)
        if not math.isfinite(x):
            raise self.error(key, f"must be finite, got {value!r}", index)
        if positive and x <= 0:
            raise self.error(key, f"must be > 0, got {value!r}", index)
        if minimum is not None and x < minimum:
            raise self.error(key, f"must be >= {minimum:g}, got {value!r}", index)
        return x

    def numbers(self, key: str, default: Any = REQUIRED, positive: bool = False):
        """A non-empty array of numbers."""
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        if not isinstance(value, list) or not value:
            raise self.error(key, f"expected a non-empty array of numbers, got {value!r}")
        return tuple(self._number(key, v, positive, None, i) for i, v in enumerate(value))

    def integers(self, key: str, default: Any = REQUIRED, minimum: int | None = None):
        """A non-empty array of integers."""
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        if not isinstance(value, list) or not value:
            raise self.error(key, f"expected a non-empty array of integers, got {value!r}")
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, int):
                raise self.error(key, f"expected an integer, got {v!r}", i)
            if minimum is not None and v < minimum:
                raise self.error(key, f"must be >= {minimum}, got {v}", i)
            out.append(v)
        return tuple(out)

    def array(self, key: str, default: Any = REQUIRED):
        """A non-empty array of anything."""
        value = self.raw(key, default)
        if value is default and key not in self._data:
            return value
        if not isinstance(value, list) or not value:
            raise self.error(key, f"expected a non-empty array, got {value!r}")
        return list(value)

    def table(self, key: str, required: bool = False) -> Table:
        """A sub-table (an empty one when absent and not required)."""
        value = self.raw(key, REQUIRED if required else {})
        if not isinstance(value, Mapping):
            raise self.error(key, f"expected a table, got {value!r}")
        return Table(value, self.source, self.key_path(key))

    def tables(self, key: str, required: bool = False) -> list[Table]:
        """An array of tables (``[[key]]``); empty when absent and not required."""
        value = self.raw(key, REQUIRED if required else [])
        if not isinstance(value, list) or not all(isinstance(v, Mapping) for v in value):
            raise self.error(key, f"expected an array of tables ([[{key}]]), got {value!r}")
        if required and not value:
            raise self.error(key, "at least one entry is needed")
        return [Table(v, self.source, (*self.key_path(key), i)) for i, v in enumerate(value)]

    def finish(self) -> None:
        """Raise on keys that were never read (misspelt or unknown settings)."""
        unknown = sorted(set(self._data) - self._used)
        if unknown:
            known = ", ".join(sorted(self._used)) or "none"
            raise self.error(
                None, f"unknown key(s) {', '.join(map(repr, unknown))} (known here: {known})"
            )

    def build(self, factory: Callable[..., Any], key: str | None = None, **kwargs: Any) -> Any:
        """Call ``factory(**kwargs)`` and report its validation errors at this table."""
        with self.checking(key):
            return factory(**kwargs)
