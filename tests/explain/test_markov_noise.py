"""Issue 28 item 9: a Gauss-Markov term and a wrong IEEE-952 coefficient are look-alikes
(both raise the residual's spectrum over the whole record); the Whittle likelihood
decides which is judged first (``lookalike.ahead``), and the accepted one's evidence names
the other as a refused look-alike (``lookalike.explained``)."""
import math
from dataclasses import replace

import numpy as np

from fogmon.explain import lookalike
from fogmon.explain.analysis import whittle_context
from fogmon.explain.candidates.base import Candidate
from fogmon.explain.candidates.coefficients import noise
from fogmon.explain.candidates.mean import bias_step
from fogmon.explain.candidates.spectral import markov
from fogmon.explain.selection import tiers
from fogmon.sim.model import Effect, Noise, SensorModel
from fogmon.sim.simulate import simulate

FS = 1.0
FOG = Noise(N_dpsh=0.01, B_dph=0.01)


def _ctx(truth: SensorModel, model: SensorModel, seed: int = 1):
    rec = simulate(truth, duration_s=12 * 3600.0, seed=seed)
    y = rec.rate_dph - rec.rate_dph.mean()
    return whittle_context(model, {}, rec.t_s, np.ones(len(y), bool), y)


def test_a_gauss_markov_hump_is_judged_before_the_corrected_coefficients_it_looks_like():
    # tau_c 300 s in 12 h: the noise kind reads the hump as a wrong B (about 0.1 deg/h)
    ctx = _ctx(SensorModel(FS, 0.0, FOG, [Effect("markov", {"tau_c_s": 300.0, "sigma_dph": 0.12})]),
               SensorModel(FS, 0.0, FOG, []))
    nz, mk, step = noise(ctx), markov(ctx), bias_step(ctx)
    assert nz is not None and mk is not None and step is not None
    assert nz.bic_gain(ctx.penalty) > 0 and mk.bic_gain(ctx.penalty) > nz.bic_gain(ctx.penalty)
    first, second = tiers(sorted([nz, mk, step], key=lambda c: -c.bic_gain(ctx.penalty)), ctx.penalty)
    assert [c.kind for c in first] == ["markov", "noise", "bias_step"] and second == []


def test_a_wrong_b_keeps_the_noise_kind_ahead():
    ctx = _ctx(SensorModel(FS, 0.0, Noise(N_dpsh=0.01, B_dph=0.05), []), SensorModel(FS, 0.0, Noise(N_dpsh=0.01,
                                                                                                   B_dph=0.02), []))
    nz, mk = noise(ctx), markov(ctx)
    assert nz is not None and "B_dph" in nz.params
    assert mk is None or mk.bic_gain(ctx.penalty) < nz.bic_gain(ctx.penalty)
    cands = [c for c in (nz, mk) if c is not None]
    first, second = tiers(sorted(cands, key=lambda c: -c.bic_gain(ctx.penalty)), ctx.penalty)
    assert [c.kind for c in first] == ["noise"] and [c.kind for c in second] == (["markov"] if mk else [])


def test_the_accepted_kind_names_its_refused_rival():
    pen = math.log(43200)
    mk = Candidate("markov", {}, {}, gain=1714.0, k=2, evidence="Whittle fit")
    nz_before = Candidate("noise", {}, {}, gain=1700.0, k=2, evidence="")
    nz_after = Candidate("noise", {}, {}, gain=3.0, k=2, evidence="")
    told = lookalike.explained(mk, [mk, nz_before], [nz_after], pen)
    assert told.evidence.startswith("Whittle fit. Look-alike refused: noise (BIC gain 1678.7 before markov, "
                                    "-18.3 after)")
    assert "Gauss-Markov" in told.evidence
    # a rival still past its bar after is not named; a kind with no rival is left alone
    assert lookalike.explained(mk, [mk, nz_before], [nz_before], pen).evidence == "Whittle fit"
    step = Candidate("bias_step", {}, {}, gain=100.0, k=3, evidence="step")
    assert lookalike.explained(step, [step, nz_before], [nz_after], pen) is step


def test_markov_stays_in_the_second_tier_when_the_noise_kind_is_below_its_bar():
    pen = math.log(36000)
    step = Candidate("bias_step", {}, {}, gain=12.0, k=2, evidence="")
    nz = Candidate("noise", {}, {}, gain=-1500.0, k=2, evidence="")
    mk = Candidate("markov", {}, {}, gain=2900.0, k=2, evidence="")
    first, second = tiers([mk, step, nz], pen)
    assert [c.kind for c in first] == ["bias_step", "noise"] and second == [mk]


def test_rivals_whose_gains_lie_less_than_2_apart_are_a_tie_the_report_warns_of():
    from types import SimpleNamespace

    from fogmon.explain import mismatch
    from fogmon.explain.caveats import lookalike_warnings

    pen = math.log(72000)
    nz = Candidate("noise", {"B_dph": 0.195, "B_dph_lo": 0.154, "B_dph_hi": 0.229}, {}, gain=134.35 + 2 * pen, k=2,
                   evidence="fit")
    mk_before = Candidate("markov", {"sigma_dph": 0.268, "tau_c_s": 66.3}, {}, gain=134.26 + 2 * pen, k=2, evidence="")
    mk_after = Candidate("markov", {}, {}, gain=2 * pen - 19.4, k=2, evidence="")
    told = lookalike.explained(nz, [nz, mk_before], [mk_after], pen)
    assert "the record cannot tell them apart (BIC gains 134.35 and 134.26, less than 2 apart)" in told.evidence
    assert told.tie == {"kind": "markov", "params": mk_before.params, "bic_gain": mk_before.bic_gain(pen),
                        "own_bic_gain": nz.bic_gain(pen)}
    grid = mismatch.make_grid(72000, 10.0)
    model = SensorModel(10.0, 0.0, Noise(N_dpsh=0.02, B_dph=0.02), [])
    (w,) = lookalike_warnings([SimpleNamespace(cand=told)], model, grid)
    assert w["kind"] == "lookalike" and (w["t_start_s"], w["t_end_s"]) == (0.0, 7200.0)
    assert "your B is 0.195 deg/h [0.154, 0.229], not 0.02; or Gauss-Markov noise 0.268 deg/h" in w["text"]
    # 2 or more apart: the likelihood prefers the accepted one, no tie
    far = replace(mk_before, gain=nz.gain - 2.0)
    told = lookalike.explained(nz, [nz, far], [mk_after], pen)
    assert told.tie is None and "describe the residual better" in told.evidence
    assert lookalike_warnings([SimpleNamespace(cand=told)], model, grid) == []
