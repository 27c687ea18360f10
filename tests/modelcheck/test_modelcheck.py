"""The live model check (fogmon.modelcheck): the model band and the ModelWatch events,
on simulated gyros with known truth, streamed through the live DADEV engine."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest
from scipy.stats import poisson

from fogmon.davar.batch import oadev
from fogmon.davar.streaming import StreamingDadev
from fogmon.davar.taus import tau_grid
from fogmon.errors import FogmonError
from fogmon.modelcheck import AuxWindows, ModelBand, ModelWatch, cache
from fogmon.modelcheck.band import band_effects, window_log_avar
from fogmon.modelcheck.watch import stated_rate
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

FS = 10.0
W = 1024       # 102.4 s window
HOP = 256      # 25.6 s hop
NOISE = Noise(N_dpsh=0.05, B_dph=0.05, K_dphsh=0.02)


def base_model(N=0.05, effects=()) -> SensorModel:
    return SensorModel(FS, 1.0, Noise(N_dpsh=N, B_dph=NOISE.B_dph, K_dphsh=NOISE.K_dphsh), list(effects))


def engine() -> StreamingDadev:
    return StreamingDadev(FS, W / FS, hop_s=HOP / FS, alpha=0)  # fixed noise type: bounds unused


def stream(rate, aux: dict, band: ModelBand, aux_names=("vib_g", "temp_c", "rot_dps")):
    """Feed a rate record (deg/h) through StreamingDadev + ModelWatch in blocks of 3001
    samples (not a multiple of the hop); returns (events, watch)."""
    sd = engine()
    watch = ModelWatch(band, aux_names)
    held = AuxWindows(aux_names, W)
    events = []
    for k in range(0, len(rate), 3001):
        r = sd.push(rate[k:k + 3001])
        held.push({name: a[k:k + 3001] for name, a in aux.items()}, len(rate[k:k + 3001]))
        for i in range(len(r)):
            e = int(r.end_index[i])
            window = held.window(e)
            for name in aux_names:  # the whole window, exactly
                np.testing.assert_array_equal(window[name], aux[name][e - W + 1:e + 1] if name in aux
                                              else np.full(W, np.nan))
            events += watch.frame((e + 1) / FS, r.adev_dph[i], window)
    return events, watch


@pytest.fixture(scope="module")
def band_dir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("bandcache"))


def make_band(model, band_dir, alpha=0.001, **kw) -> ModelBand:
    return ModelBand.for_model(model, FS, W, tau_grid(FS, W), alpha=alpha, cache_dir=band_dir, **kw)


def test_window_estimator_is_the_engine_oadev():
    rng = np.random.default_rng(3)
    y = 500.0 + rng.normal(size=4096) + 0.01 * np.cumsum(rng.normal(size=4096))
    m = tau_grid(FS, len(y))
    a = oadev(y, FS, taus=m / FS, alpha=0)
    np.testing.assert_allclose(np.sqrt(np.exp(window_log_avar(y, m))), a.adev_dph, rtol=1e-9)


def test_band_level_matches_exact_theory_and_brackets_median(band_dir):
    model = SensorModel(FS, 0.0, Noise(Q_arcsec=0.3, N_dpsh=0.05, B_dph=0.05, K_dphsh=0.02, R_dphh=0.5),
                        [Effect("markov", {"tau_c_s": 5.0, "sigma_dph": 0.2}),
                         Effect("lowpass_noise", {"sigma_dph": 8.0, "cutoff_hz": 0.1 * FS, "order": 2})])
    band = make_band(model, band_dir, replicates=200)
    assert band.theory_dph is not None
    # relative sd of one window's avar is ~3 sd(u); the mean of B has 1/sqrt(B) of it
    tol = 5.0 * 3.0 * band.null.sd / math.sqrt(200)
    rel = band.mean_avar / band.theory_dph ** 2 - 1.0
    assert np.all(np.abs(rel) < tol), (rel, tol)
    assert np.all(band.lo_dph < band.median_dph) and np.all(band.median_dph < band.hi_dph)
    assert np.all(band.median_dph <= band.theory_dph * 1.01)  # a chi-square's median is below its mean
    np.testing.assert_allclose(band.tau_s, tau_grid(FS, W) / FS)
    z = band.z(band.median_dph)
    assert np.all(np.abs(z) < 0.5)
    zmap = band.z(np.stack([band.median_dph, band.hi_dph, np.full(len(band.m), np.nan)]))  # a z-map
    assert zmap.shape == (3, len(band.m))
    np.testing.assert_array_equal(zmap[0], z)
    assert np.all(np.isnan(zmap[2]))
    assert np.all(np.abs(band.z(band.hi_dph) - band.threshold) < 1e-9)


def test_band_holds_only_stationary_effects_without_aux(band_dir):
    effects = [Effect("markov", {"tau_c_s": 5.0, "sigma_dph": 0.2}),
               Effect("bandwidth", {"cutoff_hz": 2.0, "order": 2}),
               Effect("vibration_noise", {"n_gain_dpsh_per_g": 0.1}),
               Effect("periodic", {"period_s": 60.0, "amplitude_dph": 1.0, "phase_rad": 0.0}),
               Effect("thermal_drift", {"k0_poly_dph": [0.0, 0.1], "k1_pos": 1.0, "k1_neg": 1.0,
                                        "k2_pos": 0.0, "k2_neg": 0.0})]
    kept, left = band_effects(base_model(effects=effects))
    assert [e.kind for e in kept] == ["markov", "bandwidth"]
    assert left == ["vibration_noise", "periodic", "thermal_drift"]
    band = make_band(base_model(effects=effects), band_dir, replicates=16)
    assert band.theory_dph is None  # no closed form with the bandwidth filter
    assert band.left_out == ("vibration_noise", "periodic", "thermal_drift")


def test_bad_band_arguments_are_one_line_errors(band_dir):
    with pytest.raises(FogmonError, match="alpha"):
        make_band(base_model(), band_dir, alpha=0.7)
    with pytest.raises(FogmonError, match="at least 8"):
        make_band(base_model(), band_dir, replicates=4)
    with pytest.raises(FogmonError, match="averaging factors"):
        ModelBand.for_model(base_model(), FS, W, np.array([1, 600]), cache_dir=band_dir)


def test_cache_hit_corrupt_and_unwritable(tmp_path):
    d = str(tmp_path / "c")
    a = make_band(base_model(), d, replicates=16)
    assert a.cache_status.startswith("built and cached")
    (f,) = os.listdir(d)
    b = make_band(base_model(), d, replicates=16, alpha=0.01)  # alpha is applied after the cache
    assert b.cache_status.startswith("read from the cache")
    np.testing.assert_array_equal(a.median_dph, b.median_dph)
    assert b.threshold < a.threshold
    with open(os.path.join(d, f), "wb") as fh:
        fh.write(b"\x93NUMPY garbage")
    c = make_band(base_model(), d, replicates=16)
    assert c.cache_status.startswith("built and cached")
    np.testing.assert_array_equal(a.median_dph, c.median_dph)
    assert make_band(base_model(), d, replicates=16).cache_status.startswith("read")
    assert make_band(base_model(N=0.06), d, replicates=16).cache_status.startswith("built")  # new key
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    e = make_band(base_model(), str(blocker), replicates=16)
    assert e.cache_status.startswith("built, not cached")
    np.testing.assert_array_equal(a.median_dph, e.median_dph)
    assert cache.default_dir().endswith("fogmon")


def test_null_raises_no_event(band_dir):
    model = base_model()
    rec = simulate(model, duration_s=3 * 3600.0, seed=11)
    events, watch = stream(rec.rate_dph, {}, make_band(model, band_dir))
    assert events == []
    s = watch.summary()
    assert s["n_departures"] == 0 and s["time_outside_s"] == 0.0
    assert s["time_inside_s"] == pytest.approx(len(rec.rate_dph) // HOP * HOP / FS, abs=HOP / FS)


def test_false_alarm_rate_short_null(band_dir):
    """At alpha = 0.05 per window (many alarms, so the count means something) a 12 h
    null's windows out and departures stay within the stated rates."""
    model = base_model()
    band = make_band(model, band_dir, alpha=0.05)
    rec = simulate(model, duration_s=12 * 3600.0, seed=5)
    _, watch = stream(rec.rate_dph, {}, band)
    s = watch.summary()
    st = stated_rate(band, HOP / FS)
    hours = (s["time_inside_s"] + s["time_outside_s"]) / 3600.0
    expected_out = 0.05 * s["windows"]
    # overlapping windows come out together: a Poisson test on groups of window/hop
    assert poisson.sf(math.ceil(s["windows_out"] / 4) - 1, expected_out / 4) > 1e-4
    assert poisson.cdf(s["windows_out"] // 4, expected_out / 4) > 1e-4
    assert s["n_departures"] <= poisson.isf(1e-4, st["per_hour_max"] * hours)
    assert s["n_departures"] > 0


def vibration_record(t_on: float, t_off: float, duration: float, seed: int = 2):
    n = int(duration * FS)
    t = np.arange(n) / FS
    rng = np.random.default_rng(seed)
    vib = np.where((t >= t_on) & (t < t_off), 0.5, 0.0) + 0.01 * np.abs(rng.normal(size=n))
    aux = {"vib_g": vib, "temp_c": 25.0 + 0.05 * rng.normal(size=n), "rot_dps": np.zeros(n)}
    model = base_model(effects=[Effect("vibration_noise", {"n_gain_dpsh_per_g": 0.1})])
    return simulate(model, aux=aux, aux_t_s=t, seed=seed)


def test_concealed_vibration_rise_is_found_within_one_window_and_named(band_dir):
    t_on, t_off = 3600.0 + 37.3, 3600.0 + 1800.0
    rec = vibration_record(t_on, t_off, 7200.0)
    band = make_band(base_model(), band_dir)  # the same gyro without its vibration_noise effect
    events, watch = stream(rec.rate_dph, rec.aux, band)
    assert len(events) == 2, events
    leave, back = events
    assert leave.kind == back.kind == "model_band"
    assert t_on <= leave.t_s <= t_on + W / FS
    assert "left the model band" in leave.message and "likely cause: vibration (vib_g" in leave.message
    assert "white-level rise" in leave.message
    assert t_off + W / FS <= back.t_s <= t_off + 2 * W / FS + HOP / FS
    assert "back in the model band" in back.message
    (d,) = watch.summary()["departures"]
    assert d["cause"].startswith("vibration (vib_g") and not d["open"]
    assert d["start_s"] <= t_on + HOP / FS and t_off <= d["last_out_s"] <= t_off + W / FS
    assert 1.5 < d["peak_ratio"] < 2.5  # N doubles: ADEV ratio 2 at the shortest taus
    assert d["tau_min_s"] == pytest.approx(1 / FS)
    s = watch.summary()
    assert s["time_outside_s"] == pytest.approx(d["windows_out"] * HOP / FS)


def test_wrong_white_level_departs_from_the_start(band_dir):
    rec = simulate(base_model(N=0.05), duration_s=1800.0, seed=4)
    band = make_band(base_model(N=0.05 * 0.7), band_dir)  # model N 30 % low
    events, watch = stream(rec.rate_dph, {"temp_c": np.full(len(rec.rate_dph), 21.0)}, band)
    assert len(events) == 1
    assert events[0].t_s == pytest.approx(W / FS)
    assert "white-level rise" in events[0].message
    assert "no aux channel co-varies" in events[0].message
    (d,) = watch.summary()["departures"]
    assert d["open"] and d["end_s"] is None
    assert d["peak_ratio"] == pytest.approx(1 / 0.7, rel=0.1)
    assert watch.summary()["time_inside_s"] == 0.0


def test_quieter_gyro_is_below_the_band(band_dir):
    rec = simulate(base_model(N=0.025), duration_s=900.0, seed=9)
    events, _ = stream(rec.rate_dph, {}, make_band(base_model(), band_dir))
    assert len(events) == 1 and "below the band (quieter than the model)" in events[0].message


def test_window_without_valid_terms_is_not_judged(band_dir):
    band = make_band(base_model(), band_dir)
    watch = ModelWatch(band, ["vib_g"])
    assert watch.frame(102.4, np.full(len(band.m), np.nan), {"vib_g": np.zeros(W)}) == []
    assert watch.frame(128.0, band.median_dph, {"vib_g": np.zeros(W)}) == []
    s = watch.summary()
    assert s["windows_unjudged"] == 1 and s["time_unjudged_s"] == pytest.approx(W / FS)
    assert s["time_inside_s"] == pytest.approx(25.6)
    ev = watch.frame(153.6, np.full(len(band.m), np.inf), {"vib_g": np.zeros(W)})  # a huge sample
    assert len(ev) == 1 and ev[0].kind == "model_band"


@pytest.mark.parametrize("scale, shape", [
    ({0: 3.0}, "white-level rise"), ({4: 3.0}, "hump"), ({7: 4.0, 8: 6.0}, "drift"),
    ({0: 0.5}, "below the band"), ({0: 3.0, 8: 6.0}, "white-level rise")])
def test_tau_shapes(band_dir, scale, shape):
    band = make_band(base_model(), band_dir)
    assert len(band.m) == 9
    adev = band.median_dph.copy()
    for k, f in scale.items():
        adev[k] *= f
    (ev,) = ModelWatch(band, []).frame(W / FS, adev, {})
    assert f"; {shape}" in ev.message


def test_bandwidth_above_the_live_nyquist_is_a_one_line_error(band_dir):
    model = base_model(effects=[Effect("periodic", {"period_s": 60.0, "amplitude_dph": 1.0, "phase_rad": 0.0}),
                                Effect("bandwidth", {"cutoff_hz": 4.0, "order": 2})])
    with pytest.raises(FogmonError, match=r"live 5 Hz: \[\[effect\]\] #2 \(bandwidth\): cutoff_hz must be below"):
        ModelBand.for_model(model, 5.0, W, tau_grid(5.0, W), cache_dir=band_dir)
