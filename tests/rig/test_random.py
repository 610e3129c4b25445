"""Band-limited random excitation and H1 FRF estimation against an analytic SDOF system."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from rig.estimation import h1_frf, periodic_frf, welch_average_count
from rig.signals import band_limited_random

FS = 1024.0
BAND = (5.0, 100.0)
MASS, FN, ZETA = 1.0, 25.0, 0.05  # SDOF: kg, Hz, damping ratio
STIFF = MASS * (2 * np.pi * FN) ** 2
DAMP = 2 * ZETA * np.sqrt(STIFF * MASS)


def _receptance(f_hz):
    """Analytic SDOF receptance x/F [m/N]."""
    w = 2 * np.pi * f_hz
    return 1.0 / (STIFF - MASS * w**2 + 1j * DAMP * w)


@pytest.mark.parametrize("kind", ["periodic", "gaussian"])
def test_random_record_is_band_limited_with_exact_rms(kind):
    n, rms = 8192, 0.37
    x = band_limited_random(n, FS, 20.0, 80.0, rms, seed=1, kind=kind)
    assert x.shape == (n,)
    assert np.sqrt(np.mean(x**2)) == pytest.approx(rms, rel=1e-12)
    spectrum = np.abs(np.fft.rfft(x))
    freq = np.fft.rfftfreq(n, 1 / FS)
    inside = (freq >= 20.0) & (freq <= 80.0)
    assert np.max(spectrum[~inside]) < 1e-10 * np.max(spectrum)
    if kind == "periodic":
        np.testing.assert_allclose(spectrum[inside], spectrum[inside][0], rtol=1e-9)
    else:  # flat on average: bin power is exponential, so a mean of m bins has rel. std 1/sqrt(m)
        power = spectrum[inside] ** 2
        quarters = np.array([q.mean() for q in np.array_split(power, 4)])
        m = power.size // 4
        assert np.all(np.abs(quarters / power.mean() - 1) < 4 / np.sqrt(m))
        # A Gaussian record: excess kurtosis near 0 (within 0.2 for 8192 samples).
        assert abs(np.mean(x**4) / np.mean(x**2) ** 2 - 3) < 0.2
    np.testing.assert_array_equal(x, band_limited_random(n, FS, 20.0, 80.0, rms, 1, kind))
    assert not np.array_equal(x, band_limited_random(n, FS, 20.0, 80.0, rms, 2, kind))


def test_random_record_input_errors():
    with pytest.raises(ValueError, match="no DFT bin"):
        band_limited_random(16, FS, 10.0, 20.0, 1.0)
    with pytest.raises(ValueError, match="f_lo_hz < f_hi_hz"):
        band_limited_random(1024, FS, 50.0, 20.0, 1.0)
    with pytest.raises(ValueError, match="kind"):
        band_limited_random(1024, FS, 10.0, 20.0, 1.0, kind="pink")
    with pytest.raises(ValueError, match="rms"):
        band_limited_random(1024, FS, 10.0, 20.0, 0.0)


@pytest.fixture(scope="module")
def sdof_record():
    """Gaussian band-limited force through the SDOF (lsim), first 2 s discarded."""
    n, skip = 2**16 + 2048, 2048
    force = band_limited_random(n, FS, *BAND, rms=1.0, seed=11, kind="gaussian")
    t = np.arange(n) / FS
    _, x, _ = signal.lsim(signal.lti([1.0], [MASS, DAMP, STIFF]), force, t)
    return force[skip:], x[skip:]


def test_h1_recovers_the_analytic_sdof_frf(sdof_record):
    """Tolerance 3 % in magnitude and 1.5 degrees in phase over 10-70 Hz, 1 % median.

    Error budget: lsim's first-order hold (its discrete FRF differs from the continuous one by
    1.5 % at 70 Hz), and near the resonance the segment-edge leakage of a lightly damped response
    (decay time 0.13 s vs 8 s segments; coherence 0.995 over 15 averages gives about 1.3 %
    random error). Hann resolution bias (df = 0.125 Hz vs a 2.5 Hz half-power band) is 0.2 %.
    """
    force, x = sdof_record
    nperseg = 8192
    freq, h1, coh, s_ff = h1_frf(force, np.column_stack([x, force]), FS, nperseg, band_hz=BAND)
    assert h1.shape == (freq.size, 2) and coh.shape == (freq.size, 2) and s_ff.shape == freq.shape
    sel = (freq >= 10) & (freq <= 70)
    ratio = h1[sel, 0] / _receptance(freq[sel])
    assert np.max(np.abs(np.abs(ratio) - 1)) < 0.03
    assert np.median(np.abs(np.abs(ratio) - 1)) < 0.01
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 1.5
    assert np.min(coh[sel, 0]) > 0.99
    np.testing.assert_allclose(h1[:, 1], 1.0, atol=1e-12)  # the force channel itself
    # One-sided force PSD of a flat band: rms^2 / bandwidth (within 20 % per 0.125 Hz bin avg).
    assert np.mean(s_ff[sel]) == pytest.approx(1.0 / (BAND[1] - BAND[0]), rel=0.05)


def test_coherence_drops_with_output_noise_as_predicted(sdof_record):
    """gamma^2 = S_yy,signal / (S_yy,signal + S_nn) with white noise S_nn = 2 sigma^2 / fs.

    With n_d averages the per-bin coherence scatters by about sqrt(2) (1 - g^2) / sqrt(n_d);
    tolerances: mean deviation over 10-70 Hz within 0.03, median absolute deviation below 0.06.
    H1 stays unbiased by output noise (H2 would be 1/g^2 too high, up to 5x here): the complex
    ratio H1 / H averages to 1 within 2 % over the bins (lsim's first-order hold alone accounts
    for up to 1.5 %), and each bin's magnitude error is of the size Bendat & Piersol predict,
    eps = sqrt((1 - g^2) / (2 n_d g^2)): median of |error| / eps below 1.2 (0.67 if Gaussian).
    """
    force, x = sdof_record
    rng = np.random.default_rng(5)
    sigma = 0.3 * np.std(x)
    y = x + sigma * rng.standard_normal(x.size)
    nperseg = 2048
    freq, h1, coh, s_ff = h1_frf(force, y, FS, nperseg, band_hz=BAND)
    s_signal = np.abs(_receptance(freq)) ** 2 * s_ff
    predicted = s_signal / (s_signal + 2 * sigma**2 / FS)
    sel = (freq >= 10) & (freq <= 70)
    assert predicted[sel].min() < 0.4 and predicted[sel].max() > 0.95  # a real range is tested
    deviation = coh[sel, 0] - predicted[sel]
    assert abs(np.mean(deviation)) < 0.03
    assert np.median(np.abs(deviation)) < 0.06
    n_avg = welch_average_count(force.size, nperseg, 0.5)
    ratio = h1[sel, 0] / _receptance(freq[sel])
    assert abs(np.mean(ratio) - 1) < 0.02
    eps = np.sqrt((1 - predicted[sel]) / (2 * n_avg * predicted[sel]))
    assert np.median(np.abs(np.abs(ratio) - 1) / eps) < 1.2
    assert n_avg == signal.spectrogram(force, FS, nperseg=nperseg, noverlap=1024)[1].size


def test_periodic_estimate_is_not_biased_by_noise_on_the_force():
    """Noise on the force biases H1 low by 1 / (1 + S_nn / S_ff); averaging the periods' spectra
    before dividing removes the bias (Pintelon & Schoukens 2012, ch. 2).

    A random-phase multisine of 1024 samples (1 Hz lines, flat over 5-100 Hz) through the SDOF,
    computed exactly per line, 64 periods; white noise on the measured force at S_nn / S_ff =
    0.25 and on the response. H1's magnitude comes out 0.8 (20 % low, its scatter about 1 %);
    the periodic estimate's mean ratio is within 1 % of 1 and its median line error is of the
    size the noise predicts (about sqrt(0.25 / 64) / sqrt(2) = 4 %: below 5 %).
    """
    n, periods = 1024, 64
    rng = np.random.default_rng(2)
    freq = np.fft.rfftfreq(n, 1 / FS)
    lines = (freq >= BAND[0]) & (freq <= BAND[1])
    spec = np.zeros(freq.size, complex)
    spec[lines] = np.exp(2j * np.pi * rng.random(lines.sum()))
    f_period = np.fft.irfft(spec, n)
    x_period = np.fft.irfft(spec * _receptance(freq), n)
    f_clean = np.tile(f_period, periods)
    s_ff = (2 / n) ** 2 / 2 / (FS / n)  # one-sided PSD of a line of amplitude 2 / n
    sigma_f = np.sqrt(0.25 * s_ff * FS / 2)  # white: S_nn = 2 sigma^2 / fs = S_ff / 4
    force = f_clean + sigma_f * rng.standard_normal(f_clean.size)
    x = np.tile(x_period, periods) + 1e-3 * np.std(x_period) * rng.standard_normal(f_clean.size)

    h1 = h1_frf(force, x, FS, n, window="boxcar", overlap=0.0, band_hz=BAND)
    est = periodic_frf(force, x, FS, n, band_hz=BAND)
    np.testing.assert_array_equal(est.frequency_hz, h1.frequency_hz)
    true = _receptance(est.frequency_hz)
    r_h1 = np.abs(h1.h1[:, 0] / true)
    r_per = est.h1[:, 0] / true
    assert np.median(r_h1) == pytest.approx(0.8, abs=0.02)
    assert abs(np.mean(r_per) - 1) < 0.01
    assert np.median(np.abs(r_per - 1)) < 0.05
    np.testing.assert_allclose(est.coherence, h1.coherence)
    with pytest.raises(ValueError, match="two periods"):
        periodic_frf(force[:n], x[:n], FS, n)


def test_h1_input_errors():
    with pytest.raises(ValueError, match="nperseg"):
        h1_frf(np.zeros(100), np.zeros(100), FS, 200)
    with pytest.raises(ValueError, match=r"responses \(n, C\)"):
        h1_frf(np.zeros(100), np.zeros(90), FS, 50)
    with pytest.raises(ValueError, match="overlap"):
        h1_frf(np.zeros(100), np.zeros(100), FS, 50, overlap=1.0)
