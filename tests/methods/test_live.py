"""The live methods in the pipeline: --thermal-cal corrects the analysed rate exactly as
the offline correction does, --reject-outliers makes spikes invalid and counts them,
--denoise kalman adds its channel, --model reports leaving the model band."""
from __future__ import annotations

import numpy as np
import pytest
from helpers import REPO
from helpers.doubles import Collect, ListSource

from fogmon.errors import FogmonError
from fogmon.formats.replay_log import read_replay_log
from fogmon.methods.live import CORRECTED, DRIFT, KALMAN, LiveMethods
from fogmon.methods.live_thermal import thermal_effect
from fogmon.methods.thermal import calibrate_thermal, correct_thermal
from fogmon.pipeline import Pipeline, PipelineConfig
from fogmon.sim.model import load_model

ROOT = REPO


@pytest.fixture(scope="module")
def chamber():
    rec = read_replay_log(str(ROOT / "replay_logs" / "sim_thermal_chamber_1hz.csv"))
    prior = thermal_effect(load_model(ROOT / "replay_logs" / "sim_thermal_chamber.toml"), "model").params
    cal = calibrate_thermal(rec.t_s, rec.rate_dph, rec.aux["temp_c"], 2, prior["smooth_s"], prior["diff_step_s"])
    return rec, cal.effect


def _run(rec, config, sizes=(777,)):
    n = len(rec.t_s)
    src = ListSource(rec.t_s, rec.rate_dph, list(sizes) * (n // sizes[0]) + [n % sizes[0]], rec.sample_rate_hz,
                     aux={k: v for k, v in rec.aux.items() if k == "temp_c"})
    sink = Collect()
    Pipeline(src, config).run([sink])
    return sink


def test_thermal_cal_analyses_the_offline_correction(chamber):
    rec, effect = chamber
    sink = _run(rec, PipelineConfig(window_s=2048, keep_motion=True, methods=LiveMethods(thermal=effect)))
    corrected = np.concatenate([b.aux[CORRECTED] for b in sink.blocks])
    offline = correct_thermal(rec.t_s, rec.rate_dph, rec.aux["temp_c"], effect)
    assert np.max(np.abs(corrected - offline)) < 1e-9
    assert set(sink.info.aux_names) >= {CORRECTED, DRIFT}
    assert sink.summary.analysed == "rate_dph - thermal drift"
    # DAVAR saw the corrected rate: its long-tau ADEV is far below the raw run's
    raw = _run(rec, PipelineConfig(window_s=2048, keep_motion=True))
    assert sink.frames_[-1][0].adev_dph[-1, -1] < 0.5 * raw.frames_[-1][0].adev_dph[-1, -1]


def test_thermal_cal_needs_a_temperature(chamber):
    rec, effect = chamber
    n = len(rec.t_s)
    src = ListSource(rec.t_s, rec.rate_dph, [n], rec.sample_rate_hz)
    with pytest.raises(FogmonError, match="no temp_c channel"):
        Pipeline(src, PipelineConfig(window_s=2048, methods=LiveMethods(thermal=effect))).run([Collect()])


def test_outliers_rejected_counted_and_kalman_channel():
    rng = np.random.default_rng(5)
    n, sample_rate_hz = 60_000, 100.0
    t = np.arange(n) / sample_rate_hz
    y = 60 * 0.05 * np.sqrt(sample_rate_hz) * rng.standard_normal(n)
    spikes = np.sort(rng.choice(np.arange(10_000, n), 40, replace=False))
    y[spikes] += 1e4
    src = ListSource(t, y, [1000] * 60, sample_rate_hz)
    sink = Collect()
    Pipeline(src, PipelineConfig(window_s=163.84, keep_motion=True,
                                 methods=LiveMethods(outlier_k=7.0, kalman_n_k=(0.05, 0.01)))).run([sink])
    assert sink.summary.counters["outliers_rejected"] == 40
    assert sum(int(e.message.split()[0]) for e in sink.events_ if e.kind == "outlier") == 40
    kal = np.concatenate([b.aux[KALMAN] for b in sink.blocks])
    assert np.isfinite(kal).all() and np.std(kal[5000:]) < 0.2 * np.std(y[5000:])


def test_model_band_is_drawn_in_the_rrd_and_departures_reported(tmp_path):
    """--model: the band (lo, median, hi) is in the .rrd around the live curve, as log10
    deg/h at the engine's taus, with the model's median at tau 1 s from its N."""
    from rerun.chunk import RrdReader

    from fogmon.cli import main

    rrd = tmp_path / "mwd.rrd"
    assert main(["replay", str(ROOT / "replay_logs" / "sim_mwd_run_1hz.csv"), "--model",
                 str(ROOT / "replay_logs" / "sim_mwd_run.toml"), "--rrd", str(rrd), "--quiet"]) == 0
    band = "/adev_curve/log10/model_band"
    strips = [ch.to_record_batch() for ch in RrdReader(str(rrd)).stream().filter(content=band)]
    lines = [rb.column(n).to_pylist()[0] for rb in strips for n in rb.schema.names if n.endswith("strips")]
    lo, median, hi = (np.array(s) for s in lines[0])
    assert np.all(lo[:, 1] < median[:, 1]) and np.all(median[:, 1] < hi[:, 1])
    assert median[0, 0] == 0.0  # tau 1 s: the MWD model's N0 = 0.02 deg/sqrt(h) -> 1.2 deg/h
    assert abs(10 ** median[0, 1] - 60 * 0.02) < 0.05
