"""The library's compiled laws behind one function, chosen by a code.

A compiled caller that loops over the elements of a problem (the balance's Newton iteration,
:mod:`analysis.mhb.kernels`) cannot take the laws as function arguments and stay cached:
numba compiles a function that takes another function anew in every process (some seconds a
combination of laws). It takes each element's law as a number instead, and
:func:`evaluate_law` calls the law of that number. A law outside this list (a user's own
``compiled_law``) has no code; the balance then evaluates it element by element as before.

numba keys a cached function on its own file only: a cached function that calls a law
from another file would keep the old law's machine code after that file changes. The
functions here are therefore built by :func:`stamped` in a closure over a digest of the
sources they call into, which numba keys the cache on (it hashes a function's closure), so a
changed law is compiled again.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from numba import njit

from .contact import _hertz_law
from .friction import _coulomb_law
from .gaps import _bilinear_law, _stops_law
from .polynomial import _power_series_law

__all__ = ["LAWS", "LAW_MODULES", "evaluate_law", "law_code", "source_stamp", "stamped"]

#: The library's compiled laws; a law's code is its position here.
LAWS = (_hertz_law, _power_series_law, _coulomb_law, _stops_law, _bilinear_law)

#: The modules that define them.
LAW_MODULES = tuple(sorted({law.py_func.__module__ for law in LAWS}))


def law_code(law: object) -> int | None:
    """The code of a compiled law of :data:`LAWS`, or None (a law outside the library)."""
    for i, known in enumerate(LAWS):
        if law is known:
            return i
    return None


def source_stamp(modules: Iterable[str]) -> int:
    """A 56-bit digest of the source files of the (imported) ``modules``."""
    h = hashlib.sha256()
    for name in sorted(modules):
        h.update(Path(sys.modules[name].__file__ or "").read_bytes())
    return int.from_bytes(h.digest()[:7], "big")


def stamped(modules: Iterable[str]) -> Callable[[Callable[[int], Any]], Any]:
    """A decorator for a builder ``build(stamp)`` of a compiled function, which it replaces
    by the function built in a closure over the digest of the ``modules`` it calls into
    (the function must name ``stamp`` in its body)."""
    stamp = source_stamp(modules)

    def decorate(build: Callable[[int], Any]) -> Any:
        return build(stamp)

    return decorate


@stamped(LAW_MODULES)
def evaluate_law(stamp: int):
    @njit(cache=True)
    def evaluate_law(code, u, v, p):
        """``f, df_du, df_dv`` of the law of ``code`` (:data:`LAWS`) at ``u``, ``v``."""
        stamp  # noqa: B018 - the laws' sources in numba's cache key
        if code == 0:
            return _hertz_law(u, v, p)
        if code == 1:
            return _power_series_law(u, v, p)
        if code == 2:
            return _coulomb_law(u, v, p)
        if code == 3:
            return _stops_law(u, v, p)
        return _bilinear_law(u, v, p)

    return evaluate_law
