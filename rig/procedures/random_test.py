"""The random-excitation procedure of the linear test: H1 and coherence of every channel.

:func:`random_procedure` turns a :class:`~rig.config.plans.RandomPlan` into commands:

1. noise floor: one record at 0 V;
2. calibration: a short record at ``calibration_drive_rms_v`` measures the force per volt (the
   test is linear, so the drive that gives ``force_rms_n`` follows by scaling) and checks that
   every channel responds (:func:`rig.procedures.pretest.check_random_response`);
3. the test: the band-limited random record at the scaled level, regenerated; ``settle_records``
   discarded, ``average_records`` acquired; every block checked against the limits (the tip's
   displacement against the gap);
4. H1 and coherence by Welch averaging (:func:`rig.estimation.h1_frf`), written as a
   ``kind = "random"`` file (``WriteRandom``). Channels with a low coherence get a warning.
"""

from __future__ import annotations

import logging
from collections.abc import Generator

import numpy as np

from analysis.measurement_file import RandomFRF
from rig.config.plans import RandomPlan
from rig.estimation.frf import h1_frf, periodic_frf, welch_average_count
from rig.procedures.pretest import band_rms, check_random_response
from rig.run.commands import AcquireRecords, Notify, RunContext, SetWaveform, Warn, WriteRandom
from rig.run.events import PretestFinished
from rig.run.faults import RunFault
from rig.signals.random import band_limited_random

__all__ = ["LOW_COHERENCE", "random_procedure"]

logger = logging.getLogger(__name__)

LOW_COHERENCE = 0.8  # a channel whose median in-band coherence is below this gets a warning


def random_procedure(plan: RandomPlan):
    """The procedure (``callable(RunContext) -> generator``) that runs a random plan."""

    def procedure(ctx: RunContext) -> Generator:
        return _run(plan, ctx)

    return procedure


def _run(plan: RandomPlan, ctx: RunContext):
    ex, acq = plan.excitation, plan.acquisition
    fs = ctx.sample_rate_hz
    n = int(round(ex.record_s * fs))
    band = (ex.f_lo_hz, ex.f_hi_hz)
    fi = ctx.drive_force_index
    shape = band_limited_random(n, fs, ex.f_lo_hz, ex.f_hi_hz, 1.0, seed=ex.seed, kind=ex.signal)
    noise = None
    if plan.pretest.enabled:
        n_noise = max(1, int(round(plan.pretest.noise_s * fs)))
        yield SetWaveform(np.zeros(n_noise), acq.ramp_s, band, "zero")
        noise = yield AcquireRecords(records=1, purpose="noise")
    v0 = ex.calibration_drive_rms_v
    yield SetWaveform(v0 * shape, acq.ramp_s, band, "calibration")
    cal = yield AcquireRecords(records=2, settle_records=1, purpose="calibration")
    if noise is not None:
        report = check_random_response(
            ctx, noise.samples, cal.samples, n, band, plan.pretest.min_snr
        )
        yield Notify(PretestFinished(report))
        if not report.ok:
            raise RunFault("pretest", report.problem_message(), report.problems[0].name)
        for check in report.doubtful:
            yield Warn("weak-channel", check.message, check.name)
    force_rms = float(band_rms(cal.samples[:, [fi]], fs, band)[0])
    if not force_rms > 0:
        raise RunFault(
            "no-force",
            f"no force at the drive point in the calibration record ({v0:g} V rms drive): the "
            "amplifier is off, muted or tripped, or the shaker is not connected",
        )
    drive_rms = v0 * ex.force_rms_n / force_rms
    peak = drive_rms * float(np.max(np.abs(shape)))
    if peak > min(plan.limits.drive_peak_v, ctx.drive_limit_v):
        raise RunFault(
            "drive-limit",
            f"{ex.force_rms_n:g} N rms needs a drive peak of {peak:.3g} V, above the drive limit "
            f"{plan.limits.drive_peak_v:g} V (calibration: {force_rms:.3g} N rms at {v0:g} V rms)",
        )
    logger.info("random drive %.4g V rms for %.3g N rms", drive_rms, ex.force_rms_n)
    yield SetWaveform(drive_rms * shape, acq.ramp_s, band, "random")
    rec = yield AcquireRecords(
        records=acq.average_records, settle_records=acq.settle_records, purpose="average"
    )
    nperseg = n // acq.segments_per_record
    # a periodic excitation read in whole periods: the ratio of the averaged spectra, which
    # noise on the force does not bias (H1 is biased low where the force drops at resonances)
    periodic = (
        ex.signal == "periodic"
        and acq.segments_per_record == 1
        and acq.window == "boxcar"
        and acq.overlap == 0
    )
    if periodic:
        est = periodic_frf(rec.samples[:, fi], rec.samples, fs, n, band_hz=band)
    else:
        est = h1_frf(
            rec.samples[:, fi],
            rec.samples,
            fs,
            nperseg,
            window=acq.window,
            overlap=acq.overlap,
            band_hz=band,
        )
    ok = np.isfinite(est.force_psd) & (est.force_psd > 0) & np.all(np.isfinite(est.h1), axis=1)
    coherence = np.nan_to_num(est.coherence[ok], nan=0.0)
    h1 = est.h1[ok].copy()
    h1[:, fi] = 1.0
    coherence[:, fi] = 1.0
    frf = RandomFRF(
        frequency_hz=est.frequency_hz[ok],
        h1=h1,
        coherence=coherence,
        force_psd=est.force_psd[ok],
        n_averages=welch_average_count(rec.samples.shape[0], nperseg, acq.overlap),
        window=acq.window,
        overlap=acq.overlap,
        fs_hz=fs,
        rms_force_n=float(band_rms(rec.samples[:, [fi]], fs, band)[0]),
        estimator="periodic" if periodic else "H1",
    )
    low = [
        f"{ch.name} {np.median(coherence[:, c]):.2f}"
        for c, ch in enumerate(ctx.channels)
        if c != fi and np.median(coherence[:, c]) < LOW_COHERENCE
    ]
    if low:
        yield Warn(
            "low-coherence",
            f"median coherence over {band[0]:g}-{band[1]:g} Hz below {LOW_COHERENCE:g} on "
            f"{', '.join(low)}: noise (more records or a higher level help) or a nonlinear "
            "response",
        )
    yield WriteRandom(frf)
