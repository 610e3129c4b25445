"""TOML files and the error of a bad setting.

Lab setups (:mod:`rig.config.setup`) and test plans (:mod:`rig.config.plans`) are TOML files
read into the classes declared with :mod:`rig.config.settings`. Every error is a
:class:`ConfigError` whose message starts with the source (file or built-in name) and the full
key path, e.g. ``plan 'paper' (rig/plans/paper.toml): excitation.levels_n[2]: must be > 0, got
-4.0``, and which keeps that key path as a tuple (:attr:`ConfigError.path`). The error type is
:class:`analysis.settings.ConfigError`, shared with the model file and the truth files.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from analysis.settings import ConfigError, KeyPath, dotted

__all__ = ["ConfigError", "KeyPath", "builtin_files", "dotted", "read_named", "read_toml"]


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file, turning syntax errors into :class:`ConfigError`."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} ({path})", (), f"not valid TOML: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"{what}: cannot read {path}: {exc.strerror or exc}") from exc


def builtin_files(folder: str) -> dict[str, Path]:
    """Name -> file of the TOML files shipped in ``rig/<folder>`` (``plans``, ``setups``)."""
    root = resources.files("rig") / folder
    return {Path(str(p)).stem: Path(str(p)) for p in root.iterdir() if p.name.endswith(".toml")}


def read_named(
    kind: str, name_or_path: str | Path, builtins: dict[str, Path]
) -> tuple[dict[str, Any], str]:
    """The document of a built-in file by name, or of a file by path, and the label its errors
    start with (``plan 'paper' (rig/plans/paper.toml)``, ``setup file my.toml``).

    Raises
    ------
    ConfigError
        If the name is neither a built-in one nor an existing file (the message lists the
        built-in ones), or the file cannot be read or parsed.
    """
    text = str(name_or_path)
    if text in builtins:
        path, label = builtins[text], f"{kind} {text!r} ({builtins[text]})"
    else:
        path = Path(text)
        if not path.exists():
            raise ConfigError(
                f"{kind} {text!r}: no such file and not a built-in {kind} "
                f"(built-in: {', '.join(sorted(builtins))})"
            )
        label = f"{kind} file {path}"
    return read_toml(path, label), label
