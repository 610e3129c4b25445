"""TOML files and the error of a bad setting.

Lab setups (:mod:`rig.config.setup`) and test plans (:mod:`rig.config.plans`) are TOML files
read into the classes declared with :mod:`rig.config.settings`. Every error is a
:class:`ConfigError` whose message starts with the source (file or built-in name) and the full
key path, e.g. ``plan 'paper' (rig/plans/paper.toml): excitation.levels_n[2]: must be > 0, got
-4.0``, and which keeps that key path as a tuple (:attr:`ConfigError.path`).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

__all__ = ["ConfigError", "KeyPath", "dotted", "read_toml"]

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


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file, turning syntax errors into :class:`ConfigError`."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} ({path})", (), f"not valid TOML: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"{what}: cannot read {path}: {exc.strerror or exc}") from exc
