"""The service's access token: made once, stored user-only, checked on every request.

Every request to the service carries ``Authorization: Bearer <token>``. The token is 32 random
bytes (:func:`secrets.token_urlsafe`) made on the service's first start and kept in the service
directory's ``token`` file with mode 0600; anyone who can read that file can drive the rig, so
it is never written anywhere else. A token file that group or others can read is replaced by a
new one on start. Comparison is constant-time (:func:`hmac.compare_digest`).

Only the standard library is used here: clients import this module too.
"""

from __future__ import annotations

import hmac
import logging
import os
import secrets
import stat
from pathlib import Path

__all__ = ["bearer_token", "ensure_token", "new_token", "read_token", "token_matches"]

logger = logging.getLogger(__name__)

_MIN_LENGTH = 16


def new_token() -> str:
    """A fresh random token (43 URL-safe characters)."""
    return secrets.token_urlsafe(32)


def _create(path: Path) -> str:
    token = new_token()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as fh:
        fh.write(token + "\n")
    return token


def ensure_token(path: str | os.PathLike[str]) -> tuple[str, bool]:
    """The token in ``path``, made (mode 0600) if there is none yet.

    Returns
    -------
    token : str
    created : bool
        Whether a new token was written.
    """
    path = Path(path)
    try:
        return _create(path), True
    except FileExistsError:
        pass
    mode = path.stat().st_mode
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        logger.warning("%s could be read by others: replaced by a new token", path)
        path.unlink()
        return _create(path), True
    token = read_token(path)
    if token is None:
        logger.warning("%s held no valid token: replaced by a new one", path)
        path.unlink()
        return _create(path), True
    return token, False


def read_token(path: str | os.PathLike[str]) -> str | None:
    """The token stored in ``path``, or None if there is no (valid) one."""
    try:
        text = Path(path).read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return text if len(text) >= _MIN_LENGTH and text.isprintable() and " " not in text else None


def bearer_token(header: str | None) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header value, or None."""
    if not header:
        return None
    scheme, _, value = header.strip().partition(" ")
    if scheme.lower() != "bearer":
        return None
    value = value.strip()
    return value or None


def token_matches(given: str | None, expected: str) -> bool:
    """Constant-time comparison of a presented token with the service's."""
    if given is None or not given.isascii():  # a token is ASCII; undecodable bytes are not
        return False
    return hmac.compare_digest(given.encode("ascii"), expected.encode("utf-8"))
