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
from pathlib import Path
from typing import Any

from analysis.settings import ConfigError, KeyPath, dotted

__all__ = ["ConfigError", "KeyPath", "dotted", "read_toml"]


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file, turning syntax errors into :class:`ConfigError`."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} ({path})", (), f"not valid TOML: {exc}") from exc
    except OSError as exc:
        raise ConfigError(f"{what}: cannot read {path}: {exc.strerror or exc}") from exc
