"""The pipeline on a stream of several axes: each axis's windows, fits, events and
summary equal a one-axis run of that axis (Block.axis) exactly; the console shows the
axes side by side; a one-axis run prints what it printed before axes existed."""
import io
import re
from dataclasses import replace

import numpy as np
import pytest
from helpers.doubles import Collect, ListSource

from fogmon.block import Block, Event
from fogmon.cli import command_flags
from fogmon.errors import FogmonError
from fogmon.methods.live import LiveMethods
from fogmon.pipeline import Pipeline, PipelineConfig, run_pipeline
from fogmon.pipeline.reader import _Dropped, _ThreadedBlocks
from fogmon.sim.model import Noise, SensorModel, validate_effect
from fogmon.sinks.console import ConsoleSink, format_summary

AXES = ("x", "y", "z")
FS = 100.0
N = 12_000
SIZES = [700, 1, 299, 4000, 1000, 5000, 1000]


def three_axis_data():
    """(t_s, rate (N, 3) deg/h, aux): white noise of a different level per axis, a
    platform turn on y only, a glitch on z, lost samples of x and of every axis."""
    rng = np.random.default_rng(7)
    t = np.arange(N) / FS
    rate = np.array([3.0, -1.0, 0.5]) + 60 * np.array([0.05, 0.08, 0.03]) * np.sqrt(FS) * rng.standard_normal((N, 3))
    rate[6000:6400, 1] += 2e4 * np.sin(np.linspace(0, np.pi, 400))   # y turns for 4 s
    rate[9000, 2] += 1e4                                             # one glitch on z
    rate[2000:2050, 0] = np.nan                                      # x lost 50 samples
    rate[4000:4010] = np.nan                                         # every axis lost 10
    aux = {"temp_c": 25 + t / 100, "temp_c_z": 30 + t / 50}
    return t, rate, aux


MODEL = SensorModel(FS, 0.0, Noise(0.0, 0.05, 0.0, 0.0, 0.0), [], {})


def config():
    return PipelineConfig(window_s=20.48, hop_s=10.24, model=MODEL, methods=LiveMethods(outlier_k=7.0))


def run_axes(cfg):
    t, rate, aux = three_axis_data()
    col = Collect()
    summary = run_pipeline(ListSource(t, rate, SIZES, FS, aux=aux, axes=AXES), cfg, [col])
    return col, summary


def run_one(cfg, axis):
    t, rate, aux = three_axis_data()
    view = Block.make(t, rate, aux=aux, axes=AXES).axis(axis)
    col = Collect()
    summary = run_pipeline(ListSource(t, view.rate_dph, SIZES, FS, aux=view.aux), cfg, [col])
    return col, summary


@pytest.fixture(scope="module")
def axes_run():
    return run_axes(config())


def test_each_axis_equals_a_one_axis_run_of_it(axes_run):
    cfg = config()
    col, s = axes_run
    assert col.info.axes == AXES and set(col.info.model_bands) == set(AXES)
    assert set(col.by_axis) == set(AXES)
    assert "rate_kalman_dph_x" not in col.info.aux_names      # no Kalman channel asked for
    for a in AXES:
        one, s1 = run_one(cfg, a)
        assert len(col.by_axis[a]) == len(one.by_axis[""]) > 0
        for (d, f, t_end), (d1, f1, t1) in zip(col.by_axis[a], one.by_axis[""], strict=True):
            np.testing.assert_array_equal(d.adev_dph, d1.adev_dph)
            np.testing.assert_array_equal(d.hi_dph, d1.hi_dph)
            np.testing.assert_array_equal(t_end, t1)
            np.testing.assert_array_equal(f.N_dpsh.value, f1.N_dpsh.value)
            np.testing.assert_array_equal(f.B_dph.hi, f1.B_dph.hi)
        ax = s.axes[a]
        np.testing.assert_array_equal(ax.overall.adev_dph, s1.overall.adev_dph)
        assert ax.overall_fit.N_dpsh.value == s1.overall_fit.N_dpsh.value
        assert (ax.n_invalid, ax.n_windows, ax.motion_spans, ax.motion_samples) == \
            (s1.n_invalid, s1.n_windows, s1.motion_spans, s1.motion_samples)
        assert ax.model_check == s1.model_check
        assert s.counters[f"outliers_rejected_{a}"] == s1.counters["outliers_rejected"]
        mine = [e for e in col.events_ if e.axis == a]
        assert mine == [replace(e, axis=a) for e in one.events_ if e.kind in
                        ("platform_motion", "coef_jump", "model_band", "outlier")]
    assert s.axes["y"].motion_spans and not s.axes["x"].motion_spans   # the turn is y's alone
    assert (s.axes["x"].n_invalid, s.axes["y"].n_invalid, s.n_invalid) == (60, 10, 60)
    assert s.n_windows == s.axes["x"].n_windows and s.overall is None


def test_counters_reach_the_sinks_once_per_block_with_windows(axes_run):
    col, s = axes_run
    times = [t for t, _ in col.counters]
    assert times == sorted(set(times))                # once per set of windows, not once per axis
    assert "outliers_rejected_z" in col.counters[-1][1]


def test_console_shows_the_axes_side_by_side(axes_run):
    s = replace(axes_run[1], wall_s=2.0)
    text = format_summary(s)
    lines = text.splitlines()
    assert "12000 samples at 100 Hz = 120.00 s of recording (60 invalid/lost on some axis)" in text
    assert "DADEV windows per axis of 20.48 s" in text
    assert "  invalid/lost samples per axis: x 60, y 10, z 10" in lines
    assert any(ln.startswith("  axis y: platform motion: 1 span(s)") for ln in lines)
    assert sum(ln.startswith("  axis ") and "model band" in ln for ln in lines) == 3
    head = lines.index("IEEE-952 noise coefficients per axis (whole run, 68.3 % intervals; n/i: not identifiable "
                       "from this record, < its 95 % upper limit):")
    assert lines[head + 1].split() == ["coefficient", "unit", "x", "y", "z"]
    row = next(ln for ln in lines[head:] if ln.startswith("  N_dpsh"))
    for a in AXES:
        c = s.axes[a].overall_fit.N_dpsh
        assert f"{float(c.value):.4g} [{float(c.lo):.4g}, {float(c.hi):.4g}]" in row
    assert "deg/sqrt(h)" in row
    adev_head = next(i for i, ln in enumerate(lines) if ln.startswith("Overall Allan deviation per axis"))
    assert lines[adev_head + 1].split() == ["tau_s", "x", "y", "z"]
    first = lines[adev_head + 2].split()
    assert float(first[0]) == pytest.approx(s.axes["x"].overall.tau_s[0], rel=1e-3)
    assert float(first[1]) == pytest.approx(s.axes["x"].overall.adev_dph[0], rel=1e-4)


def test_console_events_name_their_axis():
    err = io.StringIO()
    sink = ConsoleSink(err=err)
    sink.events([Event(1.0, "coef_jump", "N jumped", "y"), Event(2.0, "gap", "lost")])
    assert err.getvalue() == "[      1.00 s] coef_jump (axis y): N jumped\n[      2.00 s] gap: lost\n"


def test_a_one_axis_thermal_calibration_on_several_axes_is_a_one_line_error():
    t, rate, aux = three_axis_data()
    cal = validate_effect("thermal_drift", {"k0_poly_dph": [0.0], "k1_pos": 0.0, "k1_neg": 0.0, "k2_pos": 0.0,
                                            "k2_neg": 0.0}, "test")
    src = ListSource(t, rate, SIZES, FS, aux=aux, axes=AXES)
    with pytest.raises(FogmonError, match=r"^thermal: the calibration is for one axis and test source has "
                                          r"axes x, y, z: select one with axis NAME$"):
        Pipeline(src, PipelineConfig(window_s=20.48, methods=LiveMethods(thermal=cal))).run([Collect()])


def test_a_model_without_the_stream_s_axis_is_a_one_line_error():
    t, rate, aux = three_axis_data()
    model = replace(MODEL, axis_noise={"x": MODEL.noise, "y": MODEL.noise})
    src = ListSource(t, rate, SIZES, FS, aux=aux, axes=AXES)
    with pytest.raises(FogmonError, match=r"^model: the model has no \[noise.z\] table"):
        Pipeline(src, PipelineConfig(window_s=20.48, model=model)).run([Collect()])


def test_dropped_blocks_of_several_axes_become_placeholders_of_several_axes():
    class Empty:
        name, sample_rate_hz, n_samples, counters = "empty", FS, None, {}
        axes = ()        # a source that learns its axes only with its first block
        live, opened_s = True, None

        def blocks(self):
            yield Block.make(np.arange(2) / FS, np.ones((2, 3)), aux={"temp_c": np.ones(2)}, axes=AXES)

        def close(self):
            pass

        def limit(self, n_samples):
            pass

    reader = _ThreadedBlocks(Empty())
    assert len(list(reader)) == 1                            # read: its axes and channels are known
    got = list(reader._placeholders(_Dropped(0.02, 5, 1, [])))
    assert len(got) == 1 and got[0].axes == AXES and got[0].rate_dph.shape == (5, 3)
    assert not got[0].valid.any() and list(got[0].aux) == ["temp_c"] and got[0].events[0].kind == "dropped"


#: What the one-axis run of ``one_axis_run`` printed before axes existed (fogmon 9d437a7).
ONE_AXIS_SUMMARY = "\n".join([
    'fogmon: done: test source',
    '  12000 samples at 100 Hz = 120.00 s of recording (10 invalid/lost), in 2.00 s wall = x60 real'
     ' time',
    '  10 DADEV windows of 20.48 s every 10.24 s',
    '  platform motion: 1 span(s), 415 samples (3.5 %) kept out of DAVAR and the fits'
     ' (--keep-motion analyses them; docs/motion.md):',
    '    59.84..64.31 s (peak 1.99e+04 deg/h)',
    '  model band (--model, family-wise 0.01 per window): inside 0.0 s, outside 112.6 s, not judged'
     ' 0.0 s; 1 departure(s)',
    '    -0.00 s .. the end (still out): peak 1.65x the model at tau 0.01 s; white-level rise'
     ' (excess at the shortest taus); likely cause: no aux channel co-varies (no in-band window yet'
     ' to compare the aux channels with)',
    '',
    'Overall Allan deviation (0.00..119.99 s, 68.3 % confidence bounds):',
    '       tau_s     adev_dph       lo_dph       hi_dph        edf   n_terms',
    '        0.01       47.806       47.425       48.197       7693     11537',
    '        0.02       33.755       33.464       34.053       6589     11529',
    '        0.04       23.917       23.654       24.189       4005     11513',
    '        0.08       17.049       16.793       17.318       2112     11481',
    '        0.16       12.455       12.194       12.734       1065     11417',
    '        0.32       8.6615       8.4069       8.9409      528.7     11289',
    '        0.64       5.9629        5.717       6.2436      258.6     11033',
    '        1.28       4.1979       3.9542        4.493      123.4     10521',
    '        2.56       2.8871       2.6484       3.2047      55.75      9497',
    '        5.12       2.5216       2.2135       3.0089      21.91      7449',
    '       10.24       1.6454       1.3057       2.5548      5.077      3426',
    '       20.48   no valid Allan term (the record is too short, or every term '
    'spans a gap or platform motion)',
    '',
    'IEEE-952 noise coefficients (whole run, 68.3 % intervals):',
    '  Q_arcsec    not identifiable from this record (< 0.04843 arcsec, 95 % upper limit)',
    '  N_dpsh    = 0.07983 deg/sqrt(h)  [0.07932, 0.08069]',
    '  B_dph       not identifiable from this record (< 2.953 deg/h, 95 % upper limit)',
    '  K_dphsh     not identifiable from this record (< 116.1 deg/h/sqrt(h), 95 % upper limit)',
    '  R_dphh      not identifiable from this record (< 978.1 deg/h^2, 95 % upper limit)',
    '  model check: the fitted model agrees with the measured ADEV within chance at every tau (chi-square with'
     " each tau's EDF, family-wise 1 % over 11 taus; largest factor 1.10 at tau 5.12 s)",
    '',
    'IEEE-952 noise coefficients without and with platform motion (415 samples, 3.5 %, kept out'
     ' above; --keep-motion analyses them; 68.3 % intervals; n/i: not identifiable from this record,'
     ' < its 95 % upper limit):',
    '  coefficient unit                       motion kept out             motion analysed',
    '  Q_arcsec    arcsec                     n/i (< 0.04843)      0.2202 [0.175, 0.2772]',
    '  N_dpsh      deg/sqrt(h)     0.07983 [0.07932, 0.08069]  0.03936 [0.03935, 0.06171]',
    '  B_dph       deg/h                        n/i (< 2.953)               n/i (< 37.55)',
    '  K_dphsh     deg/h/sqrt(h)                n/i (< 116.1)               n/i (< 217.8)',
    '  R_dphh      deg/h^2                      n/i (< 978.1)                n/i (< 4715)',
    '',
    'Counters:',
    '  frames_ok                12000',
    '  outliers_rejected        34',
    '  events.model_band        1',
    '  events.outlier           1',
    '  events.platform_motion   2',
    'Wrote out.rrd (open it with: rerun out.rrd)',
])


def one_axis_run():
    """The y axis of ``three_axis_data`` alone (lost samples, a platform turn, a glitch)
    with the live model check and outlier rejection."""
    rng = np.random.default_rng(7)
    t = np.arange(N) / FS
    rate = 3.0 + 60 * 0.08 * np.sqrt(FS) * rng.standard_normal(N)
    rate[6000:6400] += 2e4 * np.sin(np.linspace(0, np.pi, 400))
    rate[9000] += 1e4
    rate[4000:4010] = np.nan
    col = Collect()
    s = run_pipeline(ListSource(t, rate, SIZES, FS, aux={"temp_c": 25 + t / 100}), config(), [col])
    return col, replace(s, wall_s=2.0, outputs=["out.rrd"])


def test_a_one_axis_run_prints_what_it_printed_before_axes():
    col, s = one_axis_run()
    assert format_summary(s, command_flags("replay")) == ONE_AXIS_SUMMARY   # what `fogmon replay` prints
    assert [(e.kind, round(e.t_s, 3), e.axis) for e in col.events_] == [
        ("model_band", 20.47, ""), ("outlier", 60.02, ""), ("platform_motion", 60.16, ""),
        ("platform_motion", 74.55, "")]
    assert set(col.by_axis) == {""} and col.info.axes == () and s.axes == {}


def test_replay_export_of_several_axes_holds_the_largest_and_each_axis(monkeypatch, tmp_path, capsys):
    import fogmon.cli.replay as replay_cli
    from fogmon.cli import main
    from fogmon.export import noise_density_rad

    t, rate, aux = three_axis_data()
    monkeypatch.setattr(replay_cli, "open_replay_source", lambda path, options: ListSource(t, rate, SIZES, FS,
                                                                                            aux=aux, axes=AXES))
    out = tmp_path / "imu.yaml"
    assert main(["replay", "three.csv", "--export", "kalibr", str(out), "--no-progress"]) == 0
    assert "Wrote" in capsys.readouterr().out
    yaml = out.read_text()
    line = next(ln for ln in yaml.splitlines() if ln.startswith("gyroscope_noise_density:"))
    n = {a: float(re.search(rf"#   axis {a}: N_dpsh ([0-9.e+-]+)", yaml).group(1)) for a in AXES}
    largest = max(n, key=n.__getitem__)
    assert f"(axis {largest}, the largest of x, y, z)" in line
    assert float(line.split()[1]) == pytest.approx(noise_density_rad(n[largest]), rel=1e-5)
    assert "accelerometer_noise_density" not in yaml.replace("#accelerometer_noise_density", "")   # none recorded


MODEL3 = """
[sensor]
sample_rate_hz = 100.0
[noise]
Q_arcsec = 0.0
N_dpsh = 0.05
B_dph = 0.0
K_dphsh = 0.0
R_dphh = 0.0
[noise.x]
[noise.y]
N_dpsh = 0.08
[noise.z]
N_dpsh = 0.03
"""


def _parsed(*argv):
    import argparse

    from fogmon.cli.pipeline_options import add_pipeline_arguments
    from fogmon.cli.source_options import add_source_arguments

    p = argparse.ArgumentParser()
    add_source_arguments(p)
    add_pipeline_arguments(p)
    return p.parse_args(list(argv))


def test_axis_picks_the_model_of_that_axis(tmp_path):
    from fogmon.cli.pipeline_options import pipeline_config

    m = tmp_path / "m.toml"
    m.write_text(MODEL3)
    assert pipeline_config(_parsed("--model", str(m), "--axis", "y")).model.noise.N_dpsh == 0.08
    assert pipeline_config(_parsed("--model", str(m))).model.axes == AXES
    m.write_text(MODEL3.replace("[noise.z]", "[noise.w]"))
    with pytest.raises(FogmonError, match=r"--model .*m.toml: the model has no \[noise.z\] table"):
        pipeline_config(_parsed("--model", str(m), "--axis", "z"))


def test_a_model_of_several_axes_on_one_axis_says_which_noise_it_checks(tmp_path):
    from fogmon.errors import FogmonWarning
    from fogmon.sim.model import load_model

    m = tmp_path / "m.toml"
    m.write_text(MODEL3)
    t, rate, aux = three_axis_data()
    src = ListSource(t[:4096], rate[:4096, 0].copy(), [4096], FS)
    with pytest.warns(FogmonWarning, match=r"^model has \[noise.<axis>\] tables \(x, y, z\) and test source is one "
                                           r"axis: it is checked against the model's \[noise\] table"):
        Pipeline(src, PipelineConfig(window_s=10.24, model=load_model(m), keep_motion=True)).run([Collect()])


def test_each_axis_is_checked_against_its_own_model(tmp_path):
    from fogmon.sim.model import load_model

    m = tmp_path / "m.toml"
    m.write_text(MODEL3)
    col, s = run_axes(PipelineConfig(window_s=20.48, hop_s=20.48, model=load_model(m)))
    med = {a: col.info.model_bands[a][1] for a in AXES}
    assert med["y"][0] / med["x"][0] == pytest.approx(0.08 / 0.05, rel=1e-6)
    assert med["z"][0] / med["x"][0] == pytest.approx(0.03 / 0.05, rel=1e-6)
    assert s.axes["x"].model_check["n_departures"] == 0          # inside its own band all along
    assert s.axes["y"].model_check["n_departures"] == 0          # its turn is kept out by its motion gate
    deps = s.axes["z"].model_check["departures"]
    assert [d["start_s"] <= 90.0 <= d["alarm_s"] for d in deps] == [True]    # z leaves it only for its glitch


def test_a_live_source_of_several_axes_read_in_its_thread_equals_one_axis_runs():
    t, rate, aux = three_axis_data()
    cfg = PipelineConfig(window_s=20.48, hop_s=20.48, keep_motion=True)

    def live(r, axes=()):
        src = ListSource(t, r, SIZES, FS, aux=aux, axes=axes)
        src.n_samples = None                         # live: warm-up, reader thread, backlog at the end
        col = Collect()
        return col, run_pipeline(src, cfg, [col])

    col, s = live(rate, AXES)
    assert s.n_samples == N and set(col.by_axis) == set(AXES)
    for j, a in enumerate(AXES):
        one, s1 = live(rate[:, j].copy())
        np.testing.assert_array_equal(np.concatenate([d.adev_dph for d, _, _ in col.by_axis[a]]),
                                      np.concatenate([d.adev_dph for d, _, _ in one.by_axis[""]]))
        np.testing.assert_array_equal(s.axes[a].overall.adev_dph, s1.overall.adev_dph)


def test_the_kalman_channel_of_each_axis_uses_that_axis_s_noise(tmp_path):
    from fogmon.cli.pipeline_options import pipeline_config

    m = tmp_path / "m.toml"
    m.write_text(MODEL3.replace("K_dphsh = 0.0", "K_dphsh = 0.5"))
    cfg = pipeline_config(_parsed("--model", str(m), "--denoise", "kalman"))
    assert {a: x.kalman_n_k for a, x in cfg.axis_methods.items()} == {"x": (0.05, 0.5), "y": (0.08, 0.5),
                                                                      "z": (0.03, 0.5)}
    cfg = replace(cfg, model=None, keep_motion=True, window_s=20.48, hop_s=20.48)
    col, s = run_axes(cfg)
    assert {"rate_kalman_dph_x", "rate_kalman_dph_y", "rate_kalman_dph_z"} <= set(col.info.aux_names)
    kalman_y = np.concatenate([b.aux["rate_kalman_dph_y"] for b in col.blocks])
    one, _ = run_one(replace(cfg, methods=cfg.axis_methods["y"], axis_methods={}), "y")
    np.testing.assert_array_equal(kalman_y, np.concatenate([b.aux["rate_kalman_dph"] for b in one.blocks]))
