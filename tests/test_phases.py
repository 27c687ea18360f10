"""Operating phases from pumps/rotation and the coefficient ranges per phase."""
import numpy as np

from fogmon.phases import STEADY, TRANSITION, PhaseLog, window_state


def aux(pumps, rot_dps, n=100):
    return {"pumps": np.full(n, float(pumps)), "rot_dps": np.full(n, float(rot_dps))}


def test_window_state_names_pumps_and_rotation_and_needs_a_clear_majority():
    assert window_state(aux(1, 720)) == "pumps on, rotating"
    assert window_state(aux(0, 0.004)) == "pumps off, not rotating"      # Earth rate is not rotating
    assert window_state({"temp_c": np.zeros(5)}) == STEADY
    mixed = {"pumps": np.r_[np.ones(85), np.zeros(15)]}
    assert window_state(mixed) == TRANSITION
    mostly = {"pumps": np.r_[np.ones(95), np.zeros(5)], "vib_g": np.zeros(100)}
    assert window_state(mostly) == "pumps on"
    assert window_state({"pumps": np.full(10, np.nan)}) == TRANSITION


def test_states_are_named_from_the_channels_a_recording_has():
    """Without a drilling channel (pumps) a rotation is only said against its threshold:
    a gyro in orbit turns at 0.0645 deg/s and is not "not rotating"."""
    orbit = {"rot_dps": np.full(100, 360.0 / 5580.0), "temp_c": np.full(100, 20.0)}
    assert window_state(orbit) == "|rot_dps| <= 1 deg/s"
    assert window_state({"rot_dps": np.full(100, 30.0)}) == "|rot_dps| > 1 deg/s"
    assert window_state(aux(0, 0.004)) == "pumps off, not rotating"
    log = PhaseLog()
    log.frame(60.0, orbit, {"N_dpsh": 0.003}, {"N_dpsh": True})
    s = log.summary()
    assert list(s["states"]) == ["|rot_dps| <= 1 deg/s"] and s["channels"] == ["rot_dps"]


def test_phases_split_at_every_change_and_transition_and_keep_identified_ranges():
    log = PhaseLog()
    ident = {"N_dpsh": True, "B_dph": True, "K_dphsh": False}
    seq = [(aux(1, 720), 0.03), (aux(1, 720), 0.05), ({"pumps": np.r_[np.ones(50), np.zeros(50)],
                                                      "rot_dps": np.zeros(100)}, 9.9),
           (aux(0, 0), 0.02), (aux(0, 0), 0.021), (aux(1, 720), 0.04)]
    started = [log.frame(60.0 * (i + 1), a, {"N_dpsh": n, "B_dph": 0.01, "K_dphsh": 5.0}, ident)
               for i, (a, n) in enumerate(seq)]
    assert [p.state if p else None for p in started] == [
        "pumps on, rotating", None, None, "pumps off, not rotating", None, "pumps on, rotating"]
    s = log.summary()
    assert s["transition_windows"] == 1
    drilling = s["states"]["pumps on, rotating"]
    assert len(drilling["phases"]) == 2 and drilling["windows"] == 3
    assert drilling["ranges"]["N_dpsh"] == (0.03, 0.05) and "K_dphsh" not in drilling["ranges"]
    static = s["states"]["pumps off, not rotating"]
    assert static["phases"][0]["t_first_end_s"] == 240.0 and static["ranges"]["N_dpsh"] == (0.02, 0.021)


def test_the_pipeline_reports_the_phases_of_a_drilling_run():
    """Drilling (pumps on, string rotating) with connections (pumps off, still) between
    stands; the monitor's session summary splits the run at the connections and gives each
    state its coefficient ranges; a phase event marks each phase's first window."""
    from helpers.doubles import Collect, ListSource

    from fogmon.pipeline import Pipeline, PipelineConfig

    sample_rate_hz, n = 10.0, 36_000                                     # 1 h at 10 Hz
    t = np.arange(n) / sample_rate_hz
    connection = (t % 1200.0) >= 900.0                     # 15 min drilling, 5 min connection
    pumps = np.where(connection, 0.0, 1.0)
    rot = np.where(connection, 0.0, 720.0)                 # 120 rpm while drilling
    rng = np.random.default_rng(5)
    white = 60 * 0.05 * np.sqrt(sample_rate_hz) * rng.standard_normal(n)      # N = 0.05 deg/sqrt(h)
    rate = 3600.0 * rot + white                            # the gyro reads the string's rotation
    sink = Collect()
    src = ListSource(t, rate, [3600] * 10, sample_rate_hz, aux={"pumps": pumps, "rot_dps": rot})
    summary = Pipeline(src, PipelineConfig(window_s=120.0, hop_s=30.0, keep_motion=True)).run([sink])
    states = summary.phases["states"]
    assert set(states) == {"pumps on, rotating", "pumps off, not rotating"}
    assert len(states["pumps on, rotating"]["phases"]) == 3 and len(states["pumps off, not rotating"]["phases"]) == 3
    lo, hi = states["pumps on, rotating"]["ranges"]["N_dpsh"]
    assert 0.04 < lo <= hi < 0.06
    starts = [e for e in sink.events_ if e.kind == "phase"]
    assert len(starts) == 6 and starts[0].message.startswith("pumps on, rotating")
    assert summary.phases["transition_windows"] > 0
