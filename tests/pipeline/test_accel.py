"""The accelerometers of a stream (aux channels accel_<name>_g) through the pipeline
(fogmon.pipeline.accel): the gyros' results unchanged, each accelerometer's windows and
fits those of the gyro engine on its samples in micro-g, platform motion kept out as its
gyro axis's gate found it; the console's and the Rerun sink's accelerometer parts."""
import numpy as np
import pytest
from helpers.doubles import Collect, ListSource

from fogmon.block import Block
from fogmon.pipeline import PipelineConfig, run_pipeline
from fogmon.sinks.console import format_summary

AXES = ("x", "y", "z")
FS = 100.0
N = 30_000
SIZES = [700, 1, 299, 9000, 1000, 15000, 4000]


class AccelCollect(Collect):
    def __init__(self):
        super().__init__()
        self.accel = {}

    def accel_frames(self, d, fit, t_end, accel):
        self.accel.setdefault(accel, []).append((d, fit, t_end))


def data():
    """Three gyros (y turns for 5 s) and three accelerometers in g: white noise of 100, 80,
    60 ug/sqrt(Hz) on 0, 0, 1 g, a random walk on x, lost samples of z."""
    rng = np.random.default_rng(5)
    t = np.arange(N) / FS
    rate = 60 * 0.05 * np.sqrt(FS) * rng.standard_normal((N, 3))
    rate[20_000:20_500, 1] += 3e4 * np.sin(np.linspace(0, np.pi, 500))
    acc = np.array([0.0, 0.0, 1.0]) + np.array([100e-6, 80e-6, 60e-6]) * np.sqrt(FS) * rng.standard_normal((N, 3))
    acc[:, 0] += np.cumsum(20e-6 / np.sqrt(FS) * rng.standard_normal(N))
    acc[7000:7040, 2] = np.nan
    aux = {f"accel_{a}_g": acc[:, j] for j, a in enumerate(AXES)} | {"temp_c": 25 + t / 1000}
    return t, rate, aux


def run(cfg, aux_keep=None):
    t, rate, aux = data()
    if aux_keep is not None:
        aux = {k: v for k, v in aux.items() if k in aux_keep}
    col = AccelCollect()
    return col, run_pipeline(ListSource(t, rate, SIZES, FS, aux=aux, axes=AXES), cfg, [col])


@pytest.fixture(scope="module")
def gated():
    return run(PipelineConfig(window_s=40.96, hop_s=20.48))


def test_the_gyros_results_are_those_of_a_run_without_accelerometers(gated):
    col, s = gated
    ref, s0 = run(PipelineConfig(window_s=40.96, hop_s=20.48), aux_keep={"temp_c"})
    assert set(col.accel) == set(AXES) and not ref.accel and s0.accels == {}
    for a in AXES:
        assert len(col.by_axis[a]) == len(ref.by_axis[a]) > 0
        for (d, f, t1), (d0, f0, t0) in zip(col.by_axis[a], ref.by_axis[a], strict=True):
            np.testing.assert_array_equal(d.adev_dph, d0.adev_dph)
            np.testing.assert_array_equal(t1, t0)
            for name, c in f.coefficients().items():
                np.testing.assert_array_equal(c.value, getattr(f0, name).value)
        np.testing.assert_array_equal(s.axes[a].overall.adev_dph, s0.axes[a].overall.adev_dph)
        assert s.axes[a].overall_fit.N_dpsh.value == s0.axes[a].overall_fit.N_dpsh.value
    assert col.info.accels == AXES


def test_an_accelerometer_is_the_gyro_engine_on_its_samples_in_micro_g():
    cfg = PipelineConfig(window_s=40.96, hop_s=20.48, keep_motion=True)
    col, s = run(cfg)
    t, _, aux = data()
    for a in AXES:
        one = Collect()
        ug = aux[f"accel_{a}_g"] * 1e6
        s1 = run_pipeline(ListSource(t, ug, SIZES, FS), cfg, [one])
        assert len(col.accel[a]) == len(one.frames_) > 0
        for (d, f, t1), (d1, f1, t2) in zip(col.accel[a], one.frames_, strict=True):
            np.testing.assert_array_equal(d.adev_dph, d1.adev_dph)
            np.testing.assert_array_equal(t1, t2)
            np.testing.assert_array_equal(f.noise.avar_terms, f1.avar_terms)
            np.testing.assert_allclose(f.VRW_mpsph.value, f1.N_dpsh.value * 3600e-6 * 9.80665, rtol=1e-15)
        acc = s.accels[a]
        np.testing.assert_array_equal(acc.overall.adev_dph, s1.overall.adev_dph)
        assert acc.n_invalid == (40 if a == "z" else 0) and acc.n_windows == sum(len(x[0]) for x in one.frames_)
    vrw = {a: s.accels[a].overall_fit.VRW_mpsph.value for a in AXES}
    for a, density_g in zip(AXES, (100e-6, 80e-6, 60e-6), strict=True):   # VRW = density x g0 x 60
        assert vrw[a] == pytest.approx(density_g * 9.80665 * 60, rel=0.03)
    assert s.accels["x"].overall_fit.AccRW_mpshsh.identifiable


def test_platform_motion_of_a_gyro_axis_is_kept_out_of_its_accelerometer(gated):
    _, s = gated
    assert s.axes["y"].motion_samples > 0 and s.axes["x"].motion_samples == 0
    assert s.accels["y"].motion_samples == s.axes["y"].motion_samples       # the same samples, every one valid
    assert s.accels["x"].motion_samples == s.accels["z"].motion_samples == 0


def test_accels_chooses_the_accelerometers():
    _, s = run(PipelineConfig(window_s=40.96, hop_s=20.48, accels=("z",)))
    assert list(s.accels) == ["z"]
    _, s = run(PipelineConfig(window_s=40.96, hop_s=20.48, accels=()))
    assert s.accels == {}


def test_a_one_axis_stream_with_accelerometers_follows_its_one_gate():
    t, rate, aux = data()
    view = Block.make(t, rate, aux=aux, axes=AXES).axis("y")
    s = run_pipeline(ListSource(t, view.rate_dph, SIZES, FS, aux=view.aux), PipelineConfig(window_s=40.96,
                                                                                           hop_s=20.48), [])
    assert set(s.accels) == set(AXES) and s.motion_samples > 0
    assert all(x.motion_samples == s.motion_samples for a, x in s.accels.items() if a != "z")


def test_the_console_shows_the_accelerometers_side_by_side(gated):
    _, s = gated
    text = format_summary(s)
    head = text.index("Accelerometers x, y, z (aux channels accel_<name>_g, analysed in micro-g")
    assert "  invalid/lost samples: x 0, y 0, z 40; kept out as platform motion: x 0, y " in text[head:]
    assert "adev_ug [lo_ug, hi_ug]:" in text and "Accelerometer noise coefficients (IEEE Std 1293" in text
    for name, unit in (("VRW_mpsph", "m/s/sqrt(h)"), ("Bias_ug", "ug"), ("AccRW_mpshsh", "m/s/h/sqrt(h)")):
        assert f"  {name:<12} {unit:<14}" in text
    assert text.index("IEEE-952 noise coefficients per axis") < head    # the gyros first, as before


def test_constant_or_absent_accelerometers_give_no_fit_and_no_error():
    t, rate, _ = data()
    aux = {"accel_x_g": np.zeros(N), "accel_y_g": np.full(N, np.nan)}
    s = run_pipeline(ListSource(t, rate, SIZES, FS, aux=aux, axes=AXES), PipelineConfig(window_s=40.96,
                                                                                        hop_s=20.48), [])
    assert s.accels["y"].overall is None and s.accels["y"].n_invalid == N
    assert not any(bool(c.identifiable) for c in s.accels["x"].overall_fit.coefficients().values())
    assert "Accelerometers x, y" in format_summary(s)
