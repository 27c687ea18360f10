"""Issue 28 items 4 and 5: outliers are always reported - removed as an effect that lowers
the score even when the model's N was read with them in it, or every spike listed under a
``spikes`` warning - and a datasheet N the record excludes is named as a ``noise`` effect
even when the sensor's own low-pass takes power off the top of the band."""
import numpy as np
import pytest
from helpers.explain import assert_invariants
from scipy import signal

from fogmon.explain import detectors
from fogmon.explain.baseline import baseline_model
from fogmon.explain.explainer import explain
from fogmon.explain.options import Options
from fogmon.explain.report import build_report, write_outliers
from fogmon.formats.recording import Recording
from fogmon.sim.model import Noise, SensorModel

FS = 100.0
N_CLEAN = 2.0
SIGMA = 60.0 * N_CLEAN * FS ** 0.5  # per-sample white-noise std (deg/h)


def contaminated(n: int, share: float, spread: float, seed: int) -> Recording:
    """White noise (N_CLEAN) with ``share`` of the samples replaced by ``spread`` x wider noise."""
    rng = np.random.default_rng(seed)
    y = rng.standard_normal(n) * SIGMA
    hit = rng.random(n) < share
    y[hit] = rng.standard_normal(int(hit.sum())) * SIGMA * spread
    return Recording(np.arange(n) / FS, y, {}, {"sample_rate_hz": "100"})


def test_outliers_are_removed_when_the_models_n_holds_their_variance():
    rec = contaminated(2 ** 16, 0.03, 8.0, seed=1)
    model = baseline_model(rec)                 # its N holds the outliers' variance
    assert model.noise.N_dpsh > 1.5 * N_CLEAN
    res = explain(rec, model, Options(n_boot=30, seed=2, workers=1), baseline=True)
    rep = build_report(res, "c.csv", None)
    assert_invariants(rep, 0.0, len(rec.t_s) / FS)
    assert [e["kind"] for e in rep["effects"]] == ["outliers"]
    assert "white level N refitted" in rep["effects"][0]["evidence"]
    assert res.fitted.noise.N_dpsh == pytest.approx(N_CLEAN, rel=0.1)
    assert rep["score_after"] < 1.5 < rep["score_before"]
    assert not any(w["kind"] == "spikes" for w in rep["warnings"])


def test_spikes_no_effect_removed_are_listed_with_a_warning(tmp_path):
    rec = contaminated(2 ** 15, 0.01, 10.0, seed=3)
    model = SensorModel(FS, 0.0, Noise(N_dpsh=N_CLEAN))
    res = explain(rec, model, Options(n_boot=20, seed=2, workers=1, max_effects=0))
    rep = build_report(res, "c.csv", None)
    assert_invariants(rep, 0.0, len(rec.t_s) / FS)
    assert not rep["effects"] and rep["score_components_before"]["spikes"] > 2.0
    warn = [w for w in rep["warnings"] if w["kind"] == "spikes"]
    assert len(warn) == 1 and "no outlier effect was accepted" in warn[0]["text"]
    n = write_outliers(res, str(tmp_path / "c.outliers.csv"))
    listed = np.loadtxt(tmp_path / "c.outliers.csv", delimiter=",", comments="#", skiprows=3)
    assert n == len(listed) == len(res.spikes["times_s"]) > 100
    assert f"finds {n} sample(s)" in warn[0]["text"] and np.all(listed[:, 2] > 5.0)


def test_a_wrong_datasheet_n_is_named_through_the_sensors_low_pass():
    rng = np.random.default_rng(5)
    n, n_true = 2 ** 17, 2.4
    # the sensor's digital low-pass: a short FIR (DC gain 1) that takes half the power at Nyquist
    y = signal.lfilter([0.85, 0.15], [1.0], rng.standard_normal(n) * 60.0 * n_true * FS ** 0.5)
    rec = Recording(np.arange(n) / FS, y, {}, {"sample_rate_hz": "100"})
    res = explain(rec, SensorModel(FS, 0.0, Noise(N_dpsh=N_CLEAN)), Options(n_boot=20, seed=2, workers=1))
    rep = build_report(res, "d.csv", None)
    assert_invariants(rep, 0.0, len(rec.t_s) / FS)
    noise = [e for e in rep["effects"] if e["kind"] == "noise"]
    assert noise, rep["refused"]
    p = noise[0]["params"]
    # the filter pulls the Allan fit's N a little low (2.33 [2.26, 2.39] here): named, not exact
    assert p["N_dpsh_lo"] > N_CLEAN and p["N_dpsh"] == pytest.approx(n_true, rel=0.05)
    assert "your N is" in noise[0]["evidence"] and "sensor's own low-pass" in noise[0]["evidence"]


def test_pure_noise_against_its_own_model_names_nothing_and_lists_nothing():
    model = SensorModel(FS, 0.0, Noise(N_dpsh=N_CLEAN))
    rng = np.random.default_rng(7)
    rec = Recording(np.arange(2 ** 15) / FS, rng.standard_normal(2 ** 15) * SIGMA, {}, {"sample_rate_hz": "100"})
    res = explain(rec, model, Options(n_boot=20, seed=2, workers=1))
    assert not res.accepted and res.spikes is None
    assert not any(w["kind"] == "spikes" for w in res.warnings)


def test_adjacent_spikes_in_white_noise_are_each_listed():
    # white noise: the matched filter's half-width is 1 sample, so two adjacent outliers are
    # two spikes; the local-maximum rule once suppressed the neighbour too (|lag| <= half-width),
    # listing 3 of 6 such samples as glitches and leaving the others in the residual unreported
    assert list(detectors.find_spikes(np.array([0.0, 9.0, 8.0, 0.0, 7.0]), 5.0, min_sep=1)) == [1, 2, 4]
    assert list(detectors.find_spikes(np.array([0.0, 9.0, 8.0, 0.0, 7.0]), 5.0, min_sep=2)) == [1, 4]
    rng = np.random.default_rng(11)
    n = 2 ** 15
    y = rng.standard_normal(n) * SIGMA
    starts = np.array([7718, 18034, 27818])
    hit = np.r_[starts, starts + 1]
    y[hit] += SIGMA * np.array([12.3, -13.8, 14.5, 12.9, -13.1, 15.2])
    rec = Recording(np.arange(n) / FS, y, {}, {"sample_rate_hz": "100"})
    res = explain(rec, SensorModel(FS, 0.0, Noise(N_dpsh=N_CLEAN)), Options(n_boot=20, seed=2, workers=1))
    rep = build_report(res, "p.csv", None)
    assert_invariants(rep, 0.0, n / FS)
    glitch = [e for e in rep["effects"] if e["kind"] == "glitches"]
    assert len(glitch) == 1, rep["effects"]
    assert sorted(np.round(np.array(glitch[0]["params"]["times_s"]) * FS).astype(int)) == sorted(hit.tolist())
    assert rep["score_after"] < 1.5 and not any(w["kind"] in ("spikes", "nonstationary") for w in rep["warnings"])


def test_spikes_left_after_an_accepted_outlier_effect_are_warned_of_and_listed(tmp_path):
    """The spike test runs on the final residual whatever was accepted: spikes it still
    finds after a glitches or outliers effect get a `spikes` warning that says so, and
    are listed (after the outliers, when an outliers effect holds the file)."""
    from types import SimpleNamespace

    from fogmon.explain.analysis import whittle_context
    from fogmon.explain.caveats import spike_warnings

    rng = np.random.default_rng(5)
    n = 2 ** 14
    y = rng.standard_normal(n) * SIGMA
    y[[1000, 5000, 9000]] += 30 * SIGMA
    t = np.arange(n) / FS
    model = SensorModel(FS, 0.0, Noise(N_dpsh=N_CLEAN))
    ctx = whittle_context(model, {}, t, np.ones(n, bool), y)
    (w,), listing = spike_warnings(ctx, [], ["outliers"])
    assert w["kind"] == "spikes" and w["text"].startswith("after the accepted outliers effect, the spike test of the "
                                                         "final residual still finds 3 sample(s) beyond |z| = ")
    assert w["text"].endswith("listed in the outliers file after the outliers")
    np.testing.assert_allclose(listing["times_s"], t[[1000, 5000, 9000]])
    held = {"times_s": np.array([1.0, 2.0]), "amplitudes_dph": np.array([5.0, 6.0]), "abs_z": np.array([9.0, 8.0])}
    outliers = SimpleNamespace(cand=SimpleNamespace(kind="outliers", listing=held))
    res = SimpleNamespace(accepted=[outliers], spikes=listing, recording=SimpleNamespace(name="r.csv"))
    path = tmp_path / "r.outliers.csv"
    assert write_outliers(res, str(path)) == 5
    lines = path.read_text().splitlines()
    assert lines[0] == ("# fogmon explain outliers of r.csv: all 2 outlier samples, then the 3 spike(s) the final "
                        "residual still holds beyond a Gaussian noise's 1 % family-wise spike threshold (not removed; "
                        "the spikes warning) "
                        "(none left out)")
    assert [float(ln.split(",")[0]) for ln in lines[3:]] == [1.0, 2.0, *t[[1000, 5000, 9000]]]


def test_a_broad_shouldered_noise_names_no_glitch_and_lists_its_extremes(tmp_path):
    """A noise heavier-shouldered than Gaussian (4 % of samples 1.8x wider, the model's N
    its whole variance) has samples beyond N(0, 1)'s 1 % family-wise threshold by its
    own law: no glitch is named, a `spikes` warning says why and lists them; far spikes
    on top of that noise are still glitches."""
    n = 2 ** 15
    rng = np.random.default_rng(1001)
    y = rng.standard_normal(n) * SIGMA
    hit = rng.random(n) < 0.04
    y[hit] *= 1.8
    model = SensorModel(FS, 0.0, Noise(N_dpsh=N_CLEAN * (0.96 + 0.04 * 1.8 ** 2) ** 0.5))
    t = np.arange(n) / FS
    res = explain(Recording(t, y, {}, {"sample_rate_hz": "100"}), model, Options(n_boot=20, seed=2, workers=1))
    rep = build_report(res, "s.csv", None)
    assert_invariants(rep, 0.0, n / FS)
    assert not any(e["kind"] in ("glitches", "outliers") for e in rep["effects"]), rep["effects"]
    warn = [w for w in rep["warnings"] if w["kind"] == "spikes"]
    assert len(warn) == 1 and warn[0]["text"].startswith("the noise is heavier-tailed than the model's Gaussian")
    n_listed = write_outliers(res, str(tmp_path / "s.outliers.csv"))
    assert n_listed == len(res.spikes["times_s"]) > 0
    y[[3000, 20000]] += 14 * SIGMA
    res = explain(Recording(t, y, {}, {"sample_rate_hz": "100"}), model, Options(n_boot=20, seed=2, workers=1))
    glitch = [e for e in build_report(res, "s.csv", None)["effects"] if e["kind"] == "glitches"]
    assert len(glitch) == 1 and sorted(np.round(np.array(glitch[0]["params"]["times_s"]) * FS)) == [3000, 20000]
    assert "under the noise's own broad-shouldered law" in glitch[0]["evidence"]
