"""The live thermal correction equals the offline one, block size by block size."""
from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO

from fogmon.errors import FogmonError
from fogmon.formats.replay_log import read_replay_log
from fogmon.methods.live_thermal import LiveThermalCorrection, thermal_effect
from fogmon.methods.thermal import calibrate_thermal, correct_thermal, drift_peak_to_peak
from fogmon.sim.model import load_model

ROOT = REPO
CHAMBER = ROOT / "replay_logs" / "sim_thermal_chamber_1hz.csv"
CHAMBER_MODEL = ROOT / "replay_logs" / "sim_thermal_chamber.toml"


@pytest.fixture(scope="module")
def chamber():
    rec = read_replay_log(str(CHAMBER))
    prior = thermal_effect(load_model(CHAMBER_MODEL), CHAMBER_MODEL.name).params
    cal = calibrate_thermal(rec.t_s, rec.rate_dph, rec.aux["temp_c"], 2, prior["smooth_s"], prior["diff_step_s"])
    return rec, cal.effect


def _live(rec, effect, sizes):
    live = LiveThermalCorrection(effect)
    out, i, k = [], 0, 0
    while i < len(rec.t_s):
        sl = slice(i, i + sizes[k % len(sizes)])
        out.append(live.push(rec.t_s[sl], rec.rate_dph[sl], rec.aux["temp_c"][sl]))
        i, k = sl.stop, k + 1
    return live, out


@pytest.mark.parametrize("sizes", [[1], [7, 1, 300], [4096]])
def test_live_equals_offline(chamber, sizes):
    rec, effect = chamber
    offline = correct_thermal(rec.t_s, rec.rate_dph, rec.aux["temp_c"], effect)
    live, out = _live(rec, effect, sizes)
    corrected = np.concatenate([c.rate_dph for c in out])
    assert np.max(np.abs(corrected - offline)) < 1e-9
    # bounded memory: the buffer holds the filter span plus the latest block, at most twice over
    span_n = live.history_s * rec.sample_rate_hz + 2
    assert live._buf.shape[1] <= max(1024, 2 * (span_n + 2 * max(sizes)))


def test_live_correction_removes_the_drift(chamber):
    """The chamber run's drift (300 s averages: the 100 s figure is limited by the white
    and bias-instability noise, not by the correction) shrinks by more than 5x."""
    rec, effect = chamber
    _, out = _live(rec, effect, [1000])
    corrected = np.concatenate([c.rate_dph for c in out])
    raw = drift_peak_to_peak(rec.t_s, rec.rate_dph, 300.0)
    assert raw / drift_peak_to_peak(rec.t_s, corrected, 300.0) > 5.0


def test_unknown_temperature_is_flagged_and_recovers(chamber):
    rec, effect = chamber
    live = LiveThermalCorrection(effect)
    temp = rec.aux["temp_c"][:400].copy()
    temp[100:200] = np.nan  # 100 s without a thermometer, longer than the 30 s smoothing
    c = live.push(rec.t_s[:400], rec.rate_dph[:400], temp)
    assert c.unknown[140:200].all() and not c.unknown[:100].any() and not c.unknown[260:].any()
    assert np.isnan(c.rate_dph[c.unknown]).all() and np.isfinite(c.rate_dph[~c.unknown]).all()


def test_a_model_without_thermal_drift_is_refused(tmp_path):
    path = tmp_path / "plain.toml"
    path.write_text("[sensor]\nsample_rate_hz = 1.0\n[noise]\nQ_arcsec = 0.0\nN_dpsh = 0.01\nB_dph = 0.0\n"
                    "K_dphsh = 0.0\nR_dphh = 0.0\n")
    with pytest.raises(FogmonError, match="plain.toml: a thermal calibration needs exactly one"):
        thermal_effect(load_model(path), path.name)
