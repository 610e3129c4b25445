"""Latin hypercube starting points with the paper's distributions.

The paper draws 100 realisations: k_c uniform on [1e5, 1e7], the gap from a beta distribution
with the nominal as mean and 50 % of it as standard deviation, v uniform on [1, 100]. A beta
with mean ``mu`` and std ``s`` is placed on ``[0, 2 mu]`` (symmetric, so its mean is ``mu``) with
shape ``a = b = (mu^2 / (2 s^2) - 1/2)``; for ``s = mu/2`` that is ``a = b = 1.5``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.stats import qmc

__all__ = ["Distribution", "latin_hypercube", "paper_distributions"]


@dataclass(frozen=True)
class Distribution:
    """A marginal distribution of a start parameter.

    Parameters
    ----------
    kind : {"uniform", "loguniform", "beta"}
    a, b : float
        ``uniform``/``loguniform``: the interval. ``beta``: mean and standard deviation.
    """

    kind: str
    a: float
    b: float

    def __post_init__(self) -> None:
        if self.kind not in ("uniform", "loguniform", "beta"):
            raise ValueError(
                f"Distribution.kind: expected uniform, loguniform or beta, got {self.kind!r}"
            )
        if self.kind in ("uniform", "loguniform") and not self.a < self.b:
            raise ValueError(f"Distribution {self.kind}: need a < b, got {self.a}, {self.b}")
        if self.kind == "loguniform" and self.a <= 0:
            raise ValueError("Distribution loguniform: the interval must be positive")
        if self.kind == "beta":
            if not (self.a > 0 and self.b > 0):
                raise ValueError("Distribution beta: need mean > 0 and std > 0")
            if self.b >= self.a:
                raise ValueError(
                    "Distribution beta: std must be below the mean "
                    f"(got mean {self.a}, std {self.b})"
                )

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Quantiles at probabilities ``u`` in (0, 1)."""
        if self.kind == "uniform":
            return self.a + (self.b - self.a) * u
        if self.kind == "loguniform":
            return np.exp(np.log(self.a) + (np.log(self.b) - np.log(self.a)) * u)
        mu, s = self.a, self.b
        shape = mu**2 / (2 * s**2) - 0.5
        return 2 * mu * stats.beta.ppf(u, shape, shape)

    def to_json(self) -> dict:
        return {"kind": self.kind, "a": self.a, "b": self.b}


def paper_distributions(nominal_gap: float) -> dict[str, Distribution]:
    """The paper's start distributions for ``k_c``, ``gap`` and ``v_c``."""
    return {
        "k_c": Distribution("uniform", 1e5, 1e7),
        "gap": Distribution("beta", nominal_gap, 0.5 * nominal_gap),
        "v_c": Distribution("uniform", 1.0, 100.0),
    }


def latin_hypercube(
    distributions: Mapping[str, Distribution],
    n: int,
    seed: int | None = 0,
    names: Sequence[str] | None = None,
) -> np.ndarray:
    """``n`` Latin hypercube realisations, shape (n, n_params), columns in ``names`` order."""
    names = list(distributions) if names is None else list(names)
    missing = [p for p in names if p not in distributions]
    if missing:
        raise ValueError(f"no start distribution for {missing}")
    u = qmc.LatinHypercube(d=len(names), seed=seed).random(n)
    return np.column_stack([distributions[p].ppf(u[:, i]) for i, p in enumerate(names)])
