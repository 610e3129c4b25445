"""The simulated DAQ against the physics it stands for: steady states, transients, noise."""

from __future__ import annotations

import numpy as np
import pytest

from sim_backend.daq import SimulatedDaq
from sim_backend.rig_model import RigModel
from sim_backend.sensors import STANDARD_GRAVITY
from tests.sim_backend.rig_setup import FS, multisine, paper_config, settle_and_estimate

N_PERIOD = 80  # 25.6 Hz at 2048 Hz, on the first beam resonance


def expected_phasors(daq: SimulatedDaq, wave: np.ndarray) -> np.ndarray:
    """The truth's MHB steady state for a drive period, from a fresh rig model.

    Returns phasors of orders 1-3 for the force and the three accelerometers, shape (4, 3).
    """
    rig = RigModel(daq.truth, daq.rig.sensors, drive_point=3)
    n = wave.size
    k = np.arange(1, 4)
    dft = np.fft.rfft(wave)[k] * 2 / n
    u = daq.amplifier.state().gain_v_per_v * np.sinc(k / n) ** 2 * dft
    st = rig.steady_state(2 * np.pi * FS / n, u)
    assert st.converged
    x = st.outputs[1:4]
    w = k * 2 * np.pi * FS / n
    force = x[:, rig.output_dofs.index(rig.coupled.force)]
    acc = -(w[:, None] ** 2) * x[:, : len(rig.structural_outputs)]
    return np.vstack([force, acc.T])


@pytest.mark.parametrize(("amplitude_v", "contact"), [(0.02, False), (0.1, True)])
def test_settled_harmonics_equal_the_truths_balance(amplitude_v: float, contact: bool) -> None:
    daq = SimulatedDaq(noise=False, quantisation=False)
    daq.configure(paper_config())
    wave = multisine(N_PERIOD, amplitude_v)
    index = daq.write_periodic(wave, 0.2)
    daq.start()
    est, _, _ = settle_and_estimate(daq, index, N_PERIOD, settle_s=30.0, periods=10)
    expected = expected_phasors(daq, wave)
    got = est.phasors[:4]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6 * np.abs(expected[:, 0]).max())
    tip_mm = abs(expected[3, 0]) / (2 * np.pi * FS / N_PERIOD) ** 2 * 1e3
    assert (tip_mm > 0.6) == contact  # the gap is 0.60 mm
    loopback = est.phasors[4]
    dft = np.fft.rfft(wave)[1:4] * 2 / N_PERIOD
    np.testing.assert_allclose(loopback, dft, atol=1e-12)
    daq.close()


def test_level_change_settles_with_the_coupled_rigs_own_decay() -> None:
    daq = SimulatedDaq(noise=False, quantisation=False)
    daq.configure(paper_config())
    n = 64  # 32 Hz, above the beam mode: the transient beats against the drive
    daq.write_periodic(multisine(n, 0.02), 0.0)
    daq.start()
    daq.read(int(40 * FS), 5.0)
    index = daq.write_periodic(multisine(n, 0.03), 0.0)
    est, _, _ = settle_and_estimate(daq, index, n, settle_s=0.0, periods=400)
    x = est.block_phasors[:, 3, 0]  # tip acceleration, fundamental, per period
    gap = np.abs(x - x[-1])
    assert gap[0] > 0.1 * abs(x[-1])  # a real transient, not an instant step
    t = np.arange(gap.size) * n / FS
    rate = -np.polyfit(t[60:200], np.log(gap[60:200]), 1)[0]
    # the slowest poles of the coupled rig (frame on its mounts, 11-15 Hz) outlast the beam
    # mode, which the shaker's back-EMF damps to about 8 %
    decay = np.sort(-daq.rig.space.lam.real)
    assert decay[0] * 0.9 < rate < decay[4]
    daq.close()


@pytest.mark.slow
def test_transient_after_a_level_change_matches_time_integration() -> None:
    """Contact open: the modal transient of the mhb engine is the linear rig's exact one."""
    runs = []
    for mode in ("mhb", "time"):
        daq = SimulatedDaq(mode=mode, noise=False, quantisation=False, time_substeps=1)
        daq.configure(paper_config())
        daq.write_periodic(multisine(N_PERIOD, 0.015), 0.1)
        daq.start()
        daq.read(int(2 * FS), 5.0)
        daq.write_periodic(multisine(70, 0.02), 0.05)  # new level and frequency
        runs.append(daq.read(int(2 * FS), 5.0)[0][:, :4])
        daq.close()
    scale = np.abs(runs[1]).max(axis=0)
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-3 * scale.max())
    assert np.all(np.abs(runs[0] - runs[1]).max(axis=0) < 2e-3 * scale)


def test_noise_scatter_matches_the_configured_floors() -> None:
    daq = SimulatedDaq(seed=7, quantisation=False)
    daq.configure(paper_config())
    index = daq.write_periodic(multisine(N_PERIOD, 0.02), 0.1)
    daq.start()
    est, _, _ = settle_and_estimate(daq, index, N_PERIOD, settle_s=30.0, periods=200)
    noise = daq.truth.noise
    asd = np.array([noise.force_n_per_rthz] + [noise.acceleration_ms2_per_rthz] * 3)
    sigma = asd * np.sqrt(FS / 2)
    # per-sample scatter about the periodic waveform: 16000 samples, 1 % precision
    np.testing.assert_allclose(est.nonperiodic_rms[:4], sigma, rtol=0.03)
    # phasor standard error of the mean: asd * sqrt(2 / T); 200 blocks, 5 % precision
    duration = 200 * N_PERIOD / FS
    expected = np.broadcast_to((asd * np.sqrt(2 / duration))[:, None], (4, 3))
    np.testing.assert_allclose(est.std[:4], expected, rtol=0.2)
    daq.close()


def test_quantisation_and_clipping_follow_the_adc() -> None:
    cfg = paper_config()
    daq = SimulatedDaq(noise=False)
    daq.configure(cfg)
    daq.write_periodic(multisine(N_PERIOD, 0.02), 0.1)
    daq.start()
    data, _ = daq.read(4096, 5.0)
    volts = data[:, 2] * 100.0 / 1000.0 / STANDARD_GRAVITY  # acc6, 100 mV/g
    lsb = 2 * cfg.ai[2].range_v / 2**16
    np.testing.assert_allclose(volts / lsb, np.round(volts / lsb), atol=1e-6)
    daq.close()
    from rig.backends.protocol import AcquisitionConfig, AIChannelConfig

    small = AIChannelConfig(
        "acc7", "Dev1/ai3", "acceleration", 100.0, "mV/g", range_v=0.05, point=7
    )
    cfg2 = AcquisitionConfig(FS, cfg.ao, (*cfg.ai[:3], small, cfg.ai[4]))
    daq = SimulatedDaq(noise=False)
    daq.configure(cfg2)
    daq.write_periodic(multisine(N_PERIOD, 0.02), 0.1)
    daq.start()
    data, _ = daq.read(int(10 * FS), 5.0)
    full_scale = 0.05 / (100.0 / 1000.0 / STANDARD_GRAVITY)
    assert np.abs(data[:, 3]).max() == pytest.approx(full_scale, rel=1e-3)
    assert np.mean(np.abs(data[-4096:, 3]) > 0.999 * full_scale) > 0.2  # flat tops
    daq.close()


def test_same_seed_same_samples_whatever_the_read_sizes() -> None:
    runs = []
    for seed, blocks in ((3, (5000,)), (3, (1, 999, 4000)), (4, (5000,))):
        daq = SimulatedDaq(seed=seed)
        daq.configure(paper_config())
        daq.write_periodic(multisine(N_PERIOD, 0.05), 0.1)
        daq.start()
        runs.append(np.concatenate([daq.read(b, 5.0)[0] for b in blocks]))
        daq.close()
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.allclose(runs[0], runs[2])


def test_write_index_is_a_whole_period_after_a_rounded_fade() -> None:
    daq = SimulatedDaq(noise=False)
    daq.configure(paper_config())
    daq.write_periodic(multisine(64, 0.02), 0.0)
    daq.start()
    daq.read(1000, 5.0)
    index = daq.write_periodic(multisine(N_PERIOD, 0.02), 0.1)
    fade = int(np.ceil(0.1 * FS / N_PERIOD)) * N_PERIOD
    start = index - fade
    assert start >= 1000 and start % 64 == 0 and start - 1000 < 64
    data, first = daq.read(index + 2 * N_PERIOD - 1000, 5.0)
    drive = data[:, 4]
    np.testing.assert_allclose(
        drive[index - first : index - first + N_PERIOD], multisine(N_PERIOD, 0.02), atol=1e-3
    )
    daq.close()


@pytest.mark.slow
def test_random_drive_gives_an_h1_with_the_truths_first_beam_mode() -> None:
    from rig.estimation.frf import h1_frf
    from rig.signals.random import band_limited_random

    fs = 1024.0
    daq = SimulatedDaq()
    daq.configure(paper_config(fs))
    n = int(32 * fs)
    daq.write_periodic(band_limited_random(n, fs, 5.0, 200.0, 0.02, seed=1), 0.0)
    daq.start()
    daq.read(int(8 * fs), 5.0)  # transient
    data, _ = daq.read(n, 5.0)
    assert daq.simulation.engine == "time"
    f, h1, coh, _ = h1_frf(data[:, 0], data[:, 1:4], fs, 8192)
    band = (f > 18) & (f < 35)
    peak = f[band][np.argmax(np.abs(h1[band, 2]))]
    mode = daq.rig.model.assemble().normal_modes(5)[0][3]
    assert abs(peak - mode) < 0.3
    quiet = (f > 40) & (f < 120)
    assert np.median(coh[quiet, 2]) > 0.9
    daq.close()


def test_the_simulated_rig_computes_with_one_blas_thread(monkeypatch) -> None:
    """Its matrices are small; two simulated tests at once must not each take every core."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from sim_backend.simulation import RigSimulation

    seen = []

    def spy(method):
        def wrapped(self, *args):
            seen.append({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})
            return method(self, *args)

        return wrapped

    # the samples and a new drive's steady state
    monkeypatch.setattr(RigSimulation, "_generate", spy(RigSimulation._generate))
    monkeypatch.setattr(RigSimulation, "_transition", spy(RigSimulation._transition))
    with threadpool_limits(limits=2):
        daq = SimulatedDaq(noise=False, quantisation=False)
        daq.configure(paper_config())
        daq.write_periodic(multisine(N_PERIOD, 0.02), 0.0)
        daq.start()
        daq.read(4 * N_PERIOD, 5.0)
        daq.close()
        after = {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
    assert seen and all(s == {1} for s in seen)
    assert after == {2}
