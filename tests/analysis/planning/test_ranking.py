"""All configurations at once: block sums, batched determinants, invariance to scaling."""

from __future__ import annotations

import itertools

import numpy as np

from analysis.planning import PlanSettings, plan_tests
from analysis.planning.ranking import combinations, configuration_fims, log10_determinants

from .conftest import REDUCED


def test_configuration_fims_equal_explicit_loops_over_blocks():
    rng = np.random.default_rng(7)
    A = rng.standard_normal((2, 4, 3, 5, 6, 3))
    blocks = np.einsum("alrski,alrskj->alrsij", A, A)  # PSD blocks (act, lev, rng, sens)
    lev_combos, lev_ind = combinations(4, 2)
    sen_combos, sen_ind = combinations(5, 3)
    fims = configuration_fims(blocks, lev_ind, sen_ind)
    assert fims.shape == (2, 3, 6, 10, 3, 3)
    for a, r in itertools.product(range(2), range(3)):
        for x, lv in enumerate(lev_combos):
            for y, ss in enumerate(sen_combos):
                direct = sum(blocks[a, i, r, s] for i in lv for s in ss)
                np.testing.assert_allclose(fims[a, r, x, y], direct, rtol=1e-12)
    logdet = log10_determinants(fims)
    np.testing.assert_allclose(10**logdet, np.linalg.det(fims), rtol=1e-9)
    assert log10_determinants(np.zeros((2, 3, 3))).tolist() == [-np.inf, -np.inf]


def test_ranking_is_invariant_to_parameter_scaling(rig, reduced_plan):
    """Scaling theta = P / s multiplies every det by the same prod(s)^-2: same order, and the
    determinants reported in physical units agree (1e-6 in log10)."""
    base = reduced_plan
    ok = np.isfinite(base.ranking.log10_det)
    assert ok.sum() >= 20
    for scales in ({"k_c": 1.0, "gap": 1.0, "v_c": 1.0}, {"k_c": 3e7, "gap": 2e-5, "v_c": 0.3}):
        other = plan_tests(
            rig,
            REDUCED,
            executor=None,
            settings=PlanSettings(parameter_scales=scales, refine_band_hz=None),
        )
        assert np.array_equal(np.isfinite(other.ranking.log10_det), ok)
        phys_base = base.ranking.log10_det[ok] + base.log10_det_offset
        phys_other = other.ranking.log10_det[ok] + other.log10_det_offset
        np.testing.assert_allclose(phys_other, phys_base, rtol=0, atol=1e-6)
        n = int(ok.sum())
        assert np.array_equal(other.ranking.order[:n], base.ranking.order[:n])
        assert [t.configuration for t in other.top] == [t.configuration for t in base.top]
        np.testing.assert_allclose(other.fim, base.fim, rtol=1e-8)
