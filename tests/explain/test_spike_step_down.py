"""Issue 28 item 4: every spike beyond chance is listed. The spike statistic's robust
scale is that of the noise without its spikes (detectors.find_spikes_step_down): many
spikes inflate a MAD taken with them in and hide the spikes just beyond the threshold.
Checked against the truth of simulated records (spikes of known times and sizes in
white noise of known sigma); pure noise lists nothing and is left unchanged."""
import numpy as np
import pytest

from fogmon.explain import analysis, detectors
from fogmon.explain.candidates.spikes import spike_evidence
from fogmon.explain.fitting import Whittle, noise_psd, rfft_omega
from fogmon.sim.model import Noise, SensorModel

N = 200_000
FS = 10.0
SIGMA = 60.0 * 0.01 * FS ** 0.5  # per-sample std (deg/h) of white noise N = 0.01 deg/sqrt(h) at 10 Hz


def spiky_record(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y deg/h, far spike indices, marginal spike indices): white noise of std SIGMA;
    8 % of the samples (3 or more apart) replaced by far spikes (8..40 sigma, random sign:
    they inflate a MAD taken with them by about 10 %) and 300 by spikes of exactly 6.0 sigma, beyond the
    1 % family-wise threshold (5.45 over 2e5 samples) by 0.55 sigma."""
    rng = np.random.default_rng(seed)
    y = SIGMA * rng.standard_normal(N)
    # at least 3 samples apart: adjacent samples beyond the threshold are one spike to the
    # local-maximum rule (find_spikes' min_sep)
    pos = 3 * rng.choice(np.arange(34, N // 3 - 34), size=int(0.08 * N) + 300, replace=False)
    far, marginal = pos[:-300], pos[-300:]
    sign = rng.choice([-1.0, 1.0], size=len(pos))
    y[far] = sign[:-300] * SIGMA * rng.uniform(8.0, 40.0, len(far))
    y[marginal] = sign[-300:] * SIGMA * 6.0
    return y, np.sort(far), np.sort(marginal)


def white_scan(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    wh = Whittle(noise_psd(rfft_omega(len(y)), FS, N_dpsh=0.01), len(y))
    return detectors.spike_scan(wh, wh.fft(y))


def test_step_down_lists_every_spike_beyond_the_threshold_against_the_true_sigma():
    y, far, marginal = spiky_record(1)
    _, z = white_scan(y)
    thr = detectors.bonferroni_z(N)
    single = detectors.find_spikes(z, thr)
    assert np.isin(marginal, single).mean() < 0.5   # the inflated MAD hides most of them
    z2, got = detectors.find_spikes_step_down(z, thr)
    injected = np.union1d(far, marginal)
    assert np.isin(injected, got).all()            # every spike beyond chance, by the truth
    extra = np.setdiff1d(got, injected)             # noise samples listed: beyond the threshold by the truth
    assert np.all(np.abs(y[extra]) / SIGMA > thr - 0.3)
    assert len(extra) <= 2
    # the rescaled statistic is the true standard score (the mean is fitted out: tiny)
    noise = np.setdiff1d(np.arange(1000, N - 1000), injected)
    assert np.median(np.abs(z2[noise])) == pytest.approx(0.6745, rel=0.02)
    assert np.median(np.abs(z2[marginal])) == pytest.approx(6.0, rel=0.03)


@pytest.mark.parametrize("seed", range(4))
def test_step_down_changes_nothing_on_pure_noise(seed):
    y = SIGMA * np.random.default_rng(100 + seed).standard_normal(N)
    _, z = white_scan(y)
    thr = detectors.bonferroni_z(N)
    z2, got = detectors.find_spikes_step_down(z, thr)
    assert len(got) == 0 and z2 is z


def test_spike_evidence_lists_the_marginal_spikes_as_glitches():
    y, far, marginal = spiky_record(2)
    model = SensorModel(FS, 0.5, Noise(N_dpsh=0.01), [])
    t = np.arange(N) / FS
    ctx = analysis.whittle_context(model, {}, t, np.ones(N, dtype=bool), y)
    ev = spike_evidence(ctx)
    assert np.isin(np.union1d(far, marginal), ev.glitch_idx).all()
    assert len(ev.glitch_idx) <= len(far) + len(marginal) + 2
