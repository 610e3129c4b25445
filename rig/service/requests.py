"""The bodies of the service's requests, declared like the settings (:mod:`rig.config.settings`).

A body is read with :func:`read_request`: an unknown field, a field of the wrong type or a
missing one is refused with the key path the error carries (``plan.excitation.levels_n[1]``).
"""

from __future__ import annotations

from typing import Any

from pydantic import Field

from rig.config.settings import Flag, Text, build, settings
from rig.config.tomlconfig import ConfigError

__all__ = ["AbortRequest", "RequestError", "SubmitRequest", "read_request"]


@settings()
class SubmitRequest:
    """``POST /api/v1/runs``: a run to queue."""

    plan: Any = Field(description="A built-in plan's name or a plan table (a plan file's data).")
    out: Text | None = Field(
        None, description="File name in the results folder (default: made up)."
    )
    label: Text = Field("", description="Free text shown with the run (first 200 characters).")
    pause_on_fault: Flag = Field(False, description="Pause instead of ending at a fault.")


@settings()
class AbortRequest:
    """``POST /api/v1/runs/{id}/abort``: why the run is aborted."""

    reason: Text = Field("", description="Why (first 300 characters; default: by the operator).")


class RequestError(ValueError):
    """A refused request: the short code of the answer and the error with its key path."""

    def __init__(self, code: str, error: ConfigError) -> None:
        super().__init__(str(error))
        self.code, self.error = code, error


# the answer's code names the field at fault where a client may act on it
_CODES = {"plan": "bad-plan", "out": "bad-out"}


def read_request(cls: type[Any], body: dict[str, Any]) -> Any:
    """The request ``cls`` read from a JSON body.

    Raises
    ------
    RequestError
        With the code ``bad-plan``, ``bad-out`` or ``bad-field`` and the error.
    """
    try:
        return build(cls, body, "request")
    except ConfigError as exc:
        field = str(exc.path[0]) if exc.path else ""
        raise RequestError(_CODES.get(field, "bad-field"), exc) from None
