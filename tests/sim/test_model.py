"""Sensor model file: round trip, catalogue, and one-line errors for bad files."""
from __future__ import annotations

import subprocess
import sys

import pytest
from helpers import REPO

from fogmon.cli import main
from fogmon.errors import FogmonError
from fogmon.sim.model import (
    EFFECT_KINDS,
    Effect,
    Noise,
    SensorModel,
    dumps_model,
    load_model,
    save_model,
    validate_effect,
    validate_model,
)

DATA = REPO / "fogmon" / "data"

EVERY_KIND = [
    Effect("thermal_drift", {"k0_poly_dph": [0.1, 0.01, -3.3e-5], "k1_pos": 41.0, "k1_neg": 20.5,
                             "k2_pos": 1e3, "k2_neg": -7.25, "smooth_s": 5.0, "diff_step_s": 0.5}),
    Effect("periodic", {"period_s": 5580.0, "amplitude_dph": 0.2, "phase_rad": -1.2345678901234567}),
    Effect("glitches", {"times_s": [10.0, 20.5], "amplitudes_dph": [5.0, -3.0], "width_s": 0.0}),
    Effect("bias_step", {"t_s": 100.0, "step_dph": -0.3}),
    Effect("vibration_noise", {"n_gain_dpsh_per_g": 0.004}),
    Effect("rate_ramp", {"slope_dphh": -0.1, "t0_s": 50.0}),
    Effect("scale_factor", {"ppm": 30.0, "asym_ppm": 5.0}),
    Effect("markov", {"tau_c_s": 30.0, "sigma_dph": 0.1}),
    Effect("temperature_noise", {"n_gain_dpsh_per_c": 0.0002, "t_ref_c": 25.0}),
    Effect("warm_up", {"amplitude_dph": 1.0, "tau_s": 300.0, "t0_s": 0.0}),
    Effect("bandwidth", {"cutoff_hz": 20.0, "order": 2, "taps": []}),
    Effect("bandwidth", {"cutoff_hz": 0.0, "order": 0, "taps": [0.25, 0.5, 0.25]}),
    Effect("outliers", {"rate_per_h": 36.5, "amplitude_quantiles_dph": [1.0, 2.0, 7.5], "quantile_probs": [0, 0.5, 1],
                        "positive_fraction": 0.25, "count": 73, "times_file": "run.outliers.csv"}),
    Effect("vibration_lines", {"freq_hz": [2.2, 5.5], "sigma_dph": [0.3, 0.1], "bandwidth_hz": [0.1, 0.05]}),
    Effect("lowpass_noise", {"sigma_dph": 110.5, "cutoff_hz": 31.7, "order": 2}),
]


def full_model() -> SensorModel:
    return SensorModel(100.0, 0.1 + 0.2, Noise(0.01, 0.05, 0.02, 0.003, 1e-4), list(EVERY_KIND),
                       {"fitted_by": "fogmon explain"})


def test_catalogue_covers_contract_kinds_and_names_aux_and_nature():
    contract = {"thermal_drift", "periodic", "glitches", "bias_step", "vibration_noise", "rate_ramp",
                "scale_factor", "markov", "temperature_noise", "warm_up", "bandwidth", "vibration_lines", "noise"}
    assert set(EFFECT_KINDS) == contract | {"outliers", "lowpass_noise"}  # additions (docs/explain.md)
    assert EFFECT_KINDS["lowpass_noise"].nature == "noise"
    assert EFFECT_KINDS["vibration_lines"].nature == "noise"
    assert EFFECT_KINDS["noise"].nature == "coefficients"
    assert EFFECT_KINDS["thermal_drift"].aux == "temp_c"
    assert EFFECT_KINDS["vibration_noise"].aux == "vib_g"
    assert EFFECT_KINDS["scale_factor"].aux == "rot_dps"
    assert EFFECT_KINDS["periodic"].aux is None
    assert EFFECT_KINDS["markov"].nature == "noise"
    assert EFFECT_KINDS["vibration_noise"].nature == "white_level"
    assert EFFECT_KINDS["bandwidth"].nature == "filter"
    assert EFFECT_KINDS["thermal_drift"].nature == "mean"
    assert EFFECT_KINDS["periodic"].required == ("period_s", "amplitude_dph", "phase_rad")
    assert EFFECT_KINDS["thermal_drift"].params["k1_pos"].unit == "deg/h per degC/s"


def test_round_trip_every_kind_loads_back_identically(tmp_path):
    m = full_model()
    p = tmp_path / "m.toml"
    save_model(m, p)
    back = load_model(p)
    assert back == validate_model(m)
    assert back.bias_dph == 0.1 + 0.2  # exact float repr
    assert back.effects[1].params["phase_rad"] == -1.2345678901234567
    save_model(back, tmp_path / "m2.toml")
    assert (tmp_path / "m2.toml").read_text() == p.read_text()


def test_defaults_filled_and_ints_become_floats():
    e = validate_effect("thermal_drift", {"k0_poly_dph": [0, 1], "k1_pos": 1, "k1_neg": 2, "k2_pos": 0, "k2_neg": 0})
    assert e.params["smooth_s"] == 10.0 and e.params["diff_step_s"] == 1.0
    assert e.params["k0_poly_dph"] == [0.0, 1.0] and isinstance(e.params["k1_pos"], float)


@pytest.mark.parametrize("path", sorted(DATA.glob("*.toml")) + sorted((DATA.parents[1] / "replay_logs").glob("*.toml")),
                         ids=lambda p: p.name)
def test_bundled_models_load(path):
    m = load_model(path)
    assert m.sample_rate_hz > 0 and m.noise.N_dpsh > 0


#: a complete [noise] table, for the cases that are about something else
NOISE = "[noise]\nQ_arcsec = 0.0\nN_dpsh = 0.01\nB_dph = 0.0\nK_dphsh = 0.0\nR_dphh = 0.0\n"
S100 = "[sensor]\nsample_rate_hz = 100\n"
BAD = {
    "unknown kind": (S100 + NOISE + '[[effect]]\nkind = "thermal_drfit"\n',
                     ["bad.toml", "[[effect]] #1", "unknown effect kind 'thermal_drfit'", "thermal_drift"]),
    "missing parameter": (S100 + NOISE + '[[effect]]\nkind = "periodic"\namplitude_dph = 1.0\nphase_rad = 0.0\n',
                          ["bad.toml", "periodic", "missing parameter 'period_s'"]),
    "negative parameter": (S100 + NOISE + '[[effect]]\nkind = "markov"\ntau_c_s = -3.0\nsigma_dph = 0.1\n',
                           ["bad.toml", "markov", "'tau_c_s'", "> 0"]),
    "negative noise": (S100 + NOISE.replace("B_dph = 0.0", "B_dph = -0.1"), ["bad.toml", "[noise] B_dph", ">= 0"]),
    "wrong units name": (S100 + NOISE.replace("N_dpsh", "N_dph"),
                         ["bad.toml", "[noise]", "unknown key 'N_dph'", "did you mean 'N_dpsh'"]),
    "missing noise key": (S100 + NOISE.replace("N_dpsh = 0.01\n", ""),
                          ["bad.toml: [noise] missing N_dpsh [deg/sqrt(h) (angle random walk)]: every IEEE-952 term "
                           "is required (0.0 for a term the gyro does not have)"]),
    "missing noise keys": (S100 + "[noise]\nN_dpsh = 0.01\n", ["bad.toml: [noise] missing Q_arcsec [", "B_dph [",
                                                               "K_dphsh [", "R_dphh ["]),
    "no noise table": (S100, ["bad.toml: no [noise] table: give Q_arcsec, N_dpsh, B_dph, K_dphsh, R_dphh"]),
    "wrong units in effect": (S100 + NOISE + '[[effect]]\nkind = "periodic"\nperiod_min = 10.0\n'
                              'amplitude_dph = 1.0\nphase_rad = 0.0\n', ["bad.toml", "unknown parameter 'period_min'",
                                                                          "did you mean 'period_s'"]),
    "missing rate": ("[sensor]\nbias_dph = 1\n" + NOISE, ["bad.toml", "[sensor]", "sample_rate_hz"]),
    "unknown table": (S100 + NOISE + "[noize]\nN_dpsh = 1\n", ["bad.toml", "'noize'", "[noise]"]),
    "not toml": ('[sensor\nsample_rate_hz = 100\n', ["bad.toml", "not valid TOML", "line 1"]),
    "string number": ('[sensor]\nsample_rate_hz = "100"\n' + NOISE,
                      ["bad.toml", "sample_rate_hz", "expected a number"]),
    "glitch lengths": (S100 + NOISE + '[[effect]]\nkind = "glitches"\ntimes_s = [1.0, 2.0]\namplitudes_dph = [1.0]\n',
                       ["bad.toml", "glitches", "same length"]),
    "bandwidth both": (S100 + NOISE + '[[effect]]\nkind = "bandwidth"\ncutoff_hz = 10.0\norder = 2\n'
                       'taps = [0.5, 0.5]\n', ["bad.toml", "bandwidth", "not both"]),
    "bandwidth nyquist": (S100 + NOISE + '[[effect]]\nkind = "bandwidth"\ncutoff_hz = 60.0\norder = 2\n',
                          ["bad.toml", "Nyquist"]),
    "scale factor of 100 %": (S100 + NOISE + '[[effect]]\nkind = "scale_factor"\nppm = -1e6\nasym_ppm = 0.0\n',
                              ["bad.toml: [[effect]] #1 (scale_factor): |ppm| + |asym_ppm|/2 = 1e+06 ppm",
                               "wrong unit"]),
    "effect without kind": (S100 + NOISE + '[[effect]]\nperiod_s = 1.0\n', ["bad.toml", "'kind'"]),
    "nan": ('[sensor]\nsample_rate_hz = 100\nbias_dph = nan\n' + NOISE, ["bad.toml", "bias_dph", "finite"]),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_model_files_fail_with_one_clear_line(tmp_path, case):
    text, needles = BAD[case]
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(FogmonError) as ei:
        load_model(p)
    msg = str(ei.value)
    assert "\n" not in msg
    for n in needles:
        assert n in msg, (n, msg)


def test_missing_file(tmp_path):
    with pytest.raises(FogmonError, match="no such model file"):
        load_model(tmp_path / "nope.toml")


def test_cli_bad_model_exit_2_one_line_no_traceback(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(BAD["wrong units name"][0])
    r = subprocess.run([sys.executable, "-m", "fogmon", "sim", "--model", str(p), "--out", str(tmp_path / "o.csv"),
                        "--duration-s", "1"], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
    assert "N_dph" in r.stderr and "bad.toml" in r.stderr


def test_cli_model_missing_a_noise_key_exit_2_naming_file_and_key(tmp_path):
    p = tmp_path / "gyro.toml"
    p.write_text(BAD["missing noise key"][0])
    out = tmp_path / "o.csv"
    r = subprocess.run([sys.executable, "-m", "fogmon", "sim", "--model", str(p), "--out", str(out),
                        "--duration-s", "1"], capture_output=True, text=True)
    assert r.returncode == 2 and not out.exists()
    assert r.stderr == ("fogmon sim: error: gyro.toml: [noise] missing N_dpsh [deg/sqrt(h) (angle random walk)]: "
                        "every IEEE-952 term is required (0.0 for a term the gyro does not have)\n")


EXAMPLE = str(DATA / "example_model.toml")


@pytest.mark.parametrize("argv, message", [
    (["--duration-s", "-1"], "argument --duration-s: must be a finite number > 0, got '-1'"),
    (["--duration-s", "inf"], "argument --duration-s: must be a finite number > 0, got 'inf'"),
    (["--duration-s", "nan"], "argument --duration-s: must be a finite number > 0, got 'nan'"),
    (["--duration-s", "1", "--seed", "-3"], "argument --seed: must be an integer >= 0, got '-3'"),
    (["--duration-s", "1", "--seed", "1.5"], "argument --seed: must be an integer >= 0, got '1.5'"),
])
def test_cli_sim_bad_values_are_usage_errors(tmp_path, capsys, argv, message):
    out = tmp_path / "o.csv"
    with pytest.raises(SystemExit) as e:
        main(["sim", "--model", EXAMPLE, "--out", str(out), *argv])
    assert e.value.code == 2 and not out.exists()
    assert capsys.readouterr().err.strip().splitlines()[-1] == f"fogmon: error: {message}"


@pytest.mark.parametrize("out, extra, message", [
    ("{tmp}/nodir/o.csv", [], "--out {tmp}/nodir/o.csv: folder {tmp}/nodir does not exist"),
    ("{tmp}", [], "--out {tmp}: is a folder, give a file name"),
    ("/proc/o.csv", [], "--out /proc/o.csv: cannot write: No such file or directory"),
    ("{tmp}/like.csv", ["--like", "{tmp}/like.csv"], "--out {tmp}/like.csv: is the input {tmp}/like.csv; write to "
                                                    "another file"),
    ("{tmp}/o.csv", ["--duration-s", "1e15"], "--out {tmp}/o.csv: 1e+17 more rows of "),
    ("{tmp}/o.csv", ["--scenario", "orbit", "--duration-s", "0.5"], "scenario orbit: duration_s 0.5 s holds fewer "
                                                                    "than 2 samples at sample_rate_hz 1 Hz"),
    ("{tmp}/o.csv", ["--scenario", "chamber", "--set", "plateaus_c=20,nan"], "scenario chamber: parameter plateaus_c: "
                                                                             "bad value '20,nan'"),
])
def test_cli_sim_bad_outputs_fail_at_once_and_create_nothing(tmp_path, capsys, out, extra, message):
    from fogmon.formats.replay_log import write_replay_log
    like = tmp_path / "like.csv"
    write_replay_log(like, [0.0, 0.01, 0.02], [1.0, 2.0, 3.0], meta={"sample_rate_hz": 100})
    before = sorted(tmp_path.iterdir())
    fmt = {"tmp": tmp_path}
    argv = ["sim", "--model", EXAMPLE, "--out", out.format(**fmt), *[a.format(**fmt) for a in extra]]
    if not extra:
        argv += ["--duration-s", "1"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon sim: error: {message.format(**fmt)}") and err.count("\n") == 1
    assert sorted(tmp_path.iterdir()) == before and like.read_text().endswith("0.02,3\n")


def test_dumps_names_units():
    text = dumps_model(SensorModel(10.0))
    assert "N_dpsh deg/sqrt(h)" in text and "sample_rate_hz = 10.0" in text


def _effect_strategy():
    from hypothesis import strategies as st

    def params_for(kind):
        spec = EFFECT_KINDS[kind]
        fields_ = {}
        for name, p in spec.params.items():
            lo = {"any": None, ">=0": 0.0, ">0": 1e-6}[p.check]
            hi = 4e5 if kind == "scale_factor" else 1e9   # |ppm| + |asym_ppm|/2 < 1e6
            lo = -hi if kind == "scale_factor" else lo
            num = st.floats(min_value=lo, max_value=hi, allow_nan=False, allow_infinity=False)
            if p.type == "list":
                fields_[name] = st.lists(num, max_size=4)
            elif p.type == "int":
                fields_[name] = st.integers(min_value=1, max_value=8)
            else:
                fields_[name] = num
        return st.fixed_dictionaries(fields_)

    def build(kind):
        if kind == "bandwidth":
            return st.one_of(
                st.builds(lambda c, o: Effect(kind, {"cutoff_hz": c, "order": o, "taps": []}),
                          st.floats(1e-3, 49.0), st.integers(1, 8)),
                st.builds(lambda t: Effect(kind, {"cutoff_hz": 0.0, "order": 0, "taps": t}),
                          st.lists(st.floats(-1, 1), min_size=1, max_size=5)))
        if kind == "glitches":
            return st.integers(0, 4).flatmap(lambda n: st.builds(
                lambda ts, am: Effect(kind, {"times_s": ts, "amplitudes_dph": am, "width_s": 0.0}),
                st.lists(st.floats(0, 1e6), min_size=n, max_size=n),
                st.lists(st.floats(-1e3, 1e3), min_size=n, max_size=n)))
        if kind == "outliers":
            return st.builds(
                lambda r, q, f, c, name: Effect(kind, {"rate_per_h": r, "amplitude_quantiles_dph": sorted(q),
                                                       "positive_fraction": f, "count": c, "times_file": name}),
                st.floats(0, 1e5), st.lists(st.floats(0, 1e6), min_size=8, max_size=8), st.floats(0, 1),
                st.integers(0, 10**6), st.text(max_size=12))
        if kind == "lowpass_noise":  # a cutoff below the Nyquist frequency of the 100 Hz model
            return st.builds(lambda s, c, o: Effect(kind, {"sigma_dph": s, "cutoff_hz": c, "order": o}),
                             st.floats(0.0, 1e6), st.floats(1e-3, 49.0), st.integers(1, 8))
        if kind == "vibration_lines":  # lines inside (0, Nyquist) of the 100 Hz model
            return st.lists(st.tuples(st.floats(1.0, 40.0), st.floats(0.0, 1e3), st.floats(1e-3, 1.0)),
                            max_size=4).map(lambda ls: Effect(kind, {
                                "freq_hz": [x[0] for x in ls], "sigma_dph": [x[1] for x in ls],
                                "bandwidth_hz": [x[2] for x in ls]}))
        return params_for(kind).map(lambda p: Effect(kind, p))

    return st.sampled_from(sorted(k for k, v in EFFECT_KINDS.items() if v.nature != "coefficients")).flatmap(build)


def test_round_trip_property(tmp_path_factory):
    """Any valid model (random effects of every kind, arbitrary finite floats) saved by
    fogmon loads back identically."""
    from hypothesis import given, settings, strategies as st

    pos = st.floats(min_value=0.0, max_value=1e6, allow_nan=False)

    @settings(max_examples=60, deadline=None)
    @given(st.floats(min_value=100.0, max_value=1e5), st.floats(-1e6, 1e6), st.tuples(pos, pos, pos, pos, pos),
           st.lists(_effect_strategy(), max_size=4))
    def check(sample_rate_hz, bias, nz, effects):
        m = validate_model(SensorModel(sample_rate_hz, bias, Noise(*nz), effects))
        p = tmp_path_factory.mktemp("rt") / "m.toml"
        save_model(m, p)
        assert load_model(p) == m

    check()


def test_noise_kind_is_refused_in_a_model_file_and_lines_are_checked(tmp_path):
    p = tmp_path / "m.toml"
    head = ("[sensor]\nsample_rate_hz = 20.0\n"
            "[noise]\nQ_arcsec = 0.0\nN_dpsh = 0.01\nB_dph = 0.0\nK_dphsh = 0.0\nR_dphh = 0.0\n")
    p.write_text(head + '[[effect]]\nkind = "noise"\nN_dpsh = 0.04\n')
    with pytest.raises(FogmonError, match=r"m.toml.*noise.*\[noise\] table"):
        load_model(p)
    lines = '[[effect]]\nkind = "vibration_lines"\n'
    p.write_text(head + lines + 'freq_hz = [9.99]\nsigma_dph = [1.0]\nbandwidth_hz = [0.1]\n')
    with pytest.raises(FogmonError, match=r"line 1 at 9.99 Hz.*Nyquist frequency 10 Hz"):
        load_model(p)
    p.write_text(head + lines + 'freq_hz = [2.0, 3.0]\nsigma_dph = [1.0]\nbandwidth_hz = [0.1, 0.1]\n')
    with pytest.raises(FogmonError, match="one entry per line"):
        load_model(p)


@pytest.mark.parametrize("term", ["N_dpsh", "B_dph"])
def test_cli_sim_refuses_non_finite_output(tmp_path, capsys, term):
    """Issue 32.8: numbers too large for float64 give inf: refused, nothing written."""
    model = tmp_path / "m.toml"
    noise = {"Q_arcsec": 0.0, "N_dpsh": 0.0, "B_dph": 0.0, "K_dphsh": 0.0, "R_dphh": 0.0, term: 1e308}
    model.write_text("[sensor]\nsample_rate_hz = 10.0\nbias_dph = 0.0\n[noise]\n"
                     + "".join(f"{k} = {v!r}\n" for k, v in noise.items()))
    out = tmp_path / "o.csv"
    assert main(["sim", "--model", str(model), "--out", str(out), "--duration-s", "10", "--seed", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fogmon sim: error: --model {model}: the simulated rate is not finite at ") and \
        err.endswith("nothing written\n") and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


def test_cli_sim_writes_what_its_suffix_says(tmp_path, capsys):
    """Issue 32.8: --out x.parquet is a Parquet replay log (the same samples as x.csv);
    another suffix is refused before any work."""
    from fogmon.formats.parquet_log import read_parquet_log
    from fogmon.formats.replay_log import read_replay_log

    csv, parquet = tmp_path / "s.csv", tmp_path / "s.parquet"
    for out in (csv, parquet):
        assert main(["sim", "--model", EXAMPLE, "--out", str(out), "--duration-s", "20", "--seed", "4"]) == 0
    a, b = read_replay_log(csv), read_parquet_log(str(parquet))
    assert parquet.read_bytes()[:4] == b"PAR1" and len(a) == len(b) == 2000
    assert abs(a.rate_dph - b.rate_dph).max() < 1e-9 * abs(a.rate_dph).max()   # the CSV's 12 digits
    capsys.readouterr()
    assert main(["sim", "--model", EXAMPLE, "--out", str(tmp_path / "s.txt"), "--duration-s", "20"]) == 2
    assert capsys.readouterr().err == (f"fogmon sim: error: --out {tmp_path / 's.txt'}: name it .csv (replay log) "
                                       f"or .parquet (Parquet replay log); fogmon writes no other format\n")
    assert not (tmp_path / "s.txt").exists()
