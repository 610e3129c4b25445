"""The generic settings layer: what :func:`dump` writes and :func:`build` reads back."""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import Field, Strict

from analysis.settings import Number, Text, build, declare, dump, settings

Unbounded = Annotated[float, Strict(), Field(allow_inf_nan=True)]


@settings()
class _Inner:
    label: Text = declare("A label.", "none")
    gain: Number = declare("A gain [1].", 1.0)


@settings()
class _Record:
    name: Text = declare("Name.")
    length_m: Number = declare("Length [m].", 0.5, key="L")
    upper: Unbounded = declare("Upper bound (inf: none).", math.inf)
    note: Text | None = declare("A note.", None)
    inner: _Inner = Field(default_factory=_Inner, description="A nested table.")
    extra: dict[str, float] = Field(default_factory=dict, description="Named numbers.")


def test_dump_writes_file_keys_and_leaves_out_unset_optionals():
    record = _Record("a")
    assert dump(record) == {
        "name": "a", "L": 0.5, "upper": math.inf, "inner": {"label": "none", "gain": 1.0},
        "extra": {},
    }  # fmt: skip
    # an infinite number stays a float (TOML writes it as inf), never None or a string
    assert isinstance(dump(record)["upper"], float)
    assert build(_Record, dump(record), "dump") == record


def test_dump_without_defaults_holds_what_differs_and_reads_back():
    assert dump(_Record("a"), exclude_defaults=True) == {"name": "a"}
    changed = _Record("b", 2.0, 3.0, "n", _Inner(gain=2.0), {"k": 1.0})
    written = dump(changed, exclude_defaults=True)
    # nested tables lose their defaults too
    assert written == {
        "name": "b", "L": 2.0, "upper": 3.0, "note": "n", "inner": {"gain": 2.0},
        "extra": {"k": 1.0},
    }  # fmt: skip
    assert build(_Record, written, "dump") == changed
    assert build(_Record, dump(_Record("a"), exclude_defaults=True), "dump") == _Record("a")


def test_dump_leaves_out_fields_by_name_not_file_key():
    assert dump(_Record("a", 2.0), exclude_defaults=True, exclude={"length_m"}) == {"name": "a"}
    assert "L" in dump(_Record("a", 2.0), exclude={"L"})
