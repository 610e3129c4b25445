"""All configurations at once: FIMs as sums of blocks, batched determinants, the ranking.

The blocks ``B[a, l, r, s]`` (actuator, level, range, sensor; each ``p x p``) are combined by
indicator matrices of the level and sensor combinations, so every configuration's FIM is one
``einsum`` and every determinant one batched ``slogdet``::

    FIM[a, r, x, y] = sum_l sum_s L[x, l] S[y, s] B[a, l, r, s]
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from analysis.planning.candidates import Candidates, Configuration

__all__ = [
    "Ranking",
    "combinations",
    "configuration_at",
    "configuration_fims",
    "configuration_index",
    "log10_determinants",
    "rank",
]


def combinations(n: int, k: int) -> tuple[list[tuple[int, ...]], np.ndarray]:
    """All k-subsets of ``range(n)`` in lexicographic order and their indicator matrix.

    Returns
    -------
    combos : list of tuple of int, length C(n, k)
    indicator : ndarray, shape (C(n, k), n)
        ``indicator[x, i] = 1`` when item ``i`` is in combination ``x``.
    """
    combos = list(itertools.combinations(range(n), k))
    ind = np.zeros((len(combos), n))
    for x, c in enumerate(combos):
        ind[x, list(c)] = 1.0
    return combos, ind


def configuration_fims(
    blocks: np.ndarray, level_indicator: np.ndarray, sensor_indicator: np.ndarray
) -> np.ndarray:
    """FIM of every configuration as a sum of its blocks.

    Parameters
    ----------
    blocks : ndarray, shape (n_act, n_lev, n_rng, n_sens, p, p)
        Information of each (actuator, level, range, sensor).
    level_indicator : ndarray, shape (n_level_combos, n_lev)
    sensor_indicator : ndarray, shape (n_sensor_combos, n_sens)

    Returns
    -------
    ndarray, shape (n_act, n_rng, n_level_combos, n_sensor_combos, p, p)
    """
    per_levels = np.einsum("xl,alrsij->arxsij", level_indicator, blocks, optimize=True)
    return np.einsum("ys,arxsij->arxyij", sensor_indicator, per_levels, optimize=True)


def log10_determinants(fims: np.ndarray) -> np.ndarray:
    """``log10 det`` of a stack of FIMs; ``-inf`` where not positive definite.

    Parameters
    ----------
    fims : ndarray, shape (..., p, p)

    Returns
    -------
    ndarray, shape (...)
    """
    sign, logdet = np.linalg.slogdet(fims)
    return np.where(sign > 0, logdet / math.log(10.0), -np.inf)


@dataclass(frozen=True)
class Ranking:
    """Every configuration's ``log10 det FIM`` and the order from best to worst.

    Attributes
    ----------
    shape : tuple of int
        ``(n_act, n_rng, n_level_combos, n_sensor_combos)``: a configuration's flat index is
        ``np.ravel_multi_index((a, r, x, y), shape)``.
    log10_det : ndarray, shape (n_configurations,)
        In scaled parameters, by flat index.
    order : ndarray of int, shape (n_configurations,)
        Flat indices, largest determinant first (ties keep index order; singular last).
    """

    shape: tuple[int, ...]
    log10_det: np.ndarray
    order: np.ndarray

    def __post_init__(self) -> None:
        for name in ("log10_det", "order"):
            a = np.array(getattr(self, name))
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def index(self, flat: int) -> tuple[int, ...]:
        """``(a, r, x, y)`` of a flat index."""
        return tuple(int(i) for i in np.unravel_index(flat, self.shape))


def rank(
    blocks: np.ndarray, level_indicator: np.ndarray, sensor_indicator: np.ndarray
) -> tuple[Ranking, np.ndarray]:
    """Rank all configurations by ``det(FIM)`` (scaled parameters).

    Returns
    -------
    Ranking
    fims : ndarray, shape (n_act, n_rng, n_level_combos, n_sensor_combos, p, p)
    """
    fims = configuration_fims(blocks, level_indicator, sensor_indicator)
    logdet = log10_determinants(fims).ravel()
    order = np.argsort(-logdet, kind="stable")
    return Ranking(fims.shape[:4], logdet, order), fims


def _shape(cand: Candidates) -> tuple[int, int, int, int]:
    return (
        len(cand.actuators),
        len(cand.ranges),
        math.comb(len(cand.levels_n), cand.n_levels),
        math.comb(len(cand.sensors), cand.n_sensors),
    )


def configuration_at(cand: Candidates, flat: int) -> Configuration:
    """The configuration at a flat index of the ranking of ``cand``."""
    a, r, x, y = (int(i) for i in np.unravel_index(flat, _shape(cand)))
    lv = combinations(len(cand.levels_n), cand.n_levels)[0][x]
    ss = combinations(len(cand.sensors), cand.n_sensors)[0][y]
    return Configuration(
        actuator=cand.actuators[a],
        sensors=tuple(cand.sensors[i] for i in ss),
        levels_n=tuple(cand.levels_n[i] for i in lv),
        frequency_range=cand.ranges[r],
    )


def configuration_index(cand: Candidates, config: Configuration) -> int | None:
    """Flat index of a configuration in the ranking of ``cand``; None if not a candidate."""
    try:
        a = cand.actuators.index(config.actuator)
        r = cand.ranges.index(config.frequency_range)
        lv = tuple(sorted(cand.levels_n.index(v) for v in config.levels_n))
        ss = tuple(sorted(cand.sensors.index(s) for s in config.sensors))
    except ValueError:
        return None
    if len(lv) != cand.n_levels or len(ss) != cand.n_sensors:
        return None
    x = combinations(len(cand.levels_n), cand.n_levels)[0].index(lv)
    y = combinations(len(cand.sensors), cand.n_sensors)[0].index(ss)
    return int(np.ravel_multi_index((a, r, x, y), _shape(cand)))
