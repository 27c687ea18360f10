"""One comparison of a residual with a null (``Analysis``: map, z-scores, regions,
score) and the context the candidates are fitted in (``whittle_context``: the model PSD
calibrated to the residual)."""
from __future__ import annotations

import math
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, replace

import numpy as np

from fogmon.explain import detectors, mismatch
from fogmon.explain.candidates.base import Candidate, Context, calibrated_psd, white_level_rms_dpsh
from fogmon.explain.candidates.spikes import spike_scan
from fogmon.explain.fitting import Whittle, model_psd, rfft_omega
from fogmon.sim.model import SensorModel


@dataclass
class Analysis:
    """One comparison of a residual with a null: ln avar of the map and whole record,
    z-scores, regions and score."""

    cell: np.ndarray
    whole: np.ndarray
    z: np.ndarray
    z_whole: np.ndarray
    regions: list
    score: mismatch.Score
    null: mismatch.Null


def whittle_context(stoch: SensorModel, ctx_aux: dict, t: np.ndarray, valid: np.ndarray, y: np.ndarray,
                    copy: bool = True) -> Context:
    """The context of the candidates: the model PSD calibrated to the residual over the
    model's pass band (``in_passband``), and no weight outside it: an octave
    band holding a filter's zero would otherwise take its factor from bins where the
    model is floored, and the bins next to them would show a false excess. ``copy``
    False: ``y`` becomes the context's residual (written into: 0 where not valid, its
    first sample less the wrap spike below; memory: no record-length copy)."""
    n = len(y)
    omega = rfft_omega(n)
    S_model = model_psd(stoch, omega, n, white_level_rms_dpsh(stoch, t, ctx_aux))
    if copy:
        yy = np.where(valid, y, 0.0)
    else:
        yy = y
        yy[~valid] = 0.0
    Yf = np.fft.rfft(yy)
    wh = Whittle(calibrated_psd(stoch, S_model, Yf, n), n, valid)
    # The circular DFT joins the record's last sample to its first; for blue
    # (quantization) noise the angle mismatch there is a one-sample rate spike at index 0
    # that the GLS sees clearly: project it out (a nuisance regressor) before any test.
    amp0 = detectors.spike_at_start(wh, Yf)
    first = float(yy[0])
    yy[0] -= amp0
    Yf -= amp0
    ctx = Context(t, ctx_aux, valid, float(stoch.sample_rate_hz), yy, stoch, wh, Yf, y_first=first)
    ctx.cache["model_psd"] = S_model
    return ctx


def matched_tests_figure(cands: list[Candidate], penalty: float, contradicted: AbstractSet[str]) -> float:
    """The score's ``tests``: the strongest candidate's sqrt(gain / its bar) (k ln n, or its
    search's chance bar when higher: ``Candidate.bar``, so below 1 when none passes), candidates
    of a kind the map contradicted (``contradicted``: added, it opened a whole-record
    deficit, ``Selection.judge``) left out - their statistic measured a misfit their shape does
    not describe, and the map's own figures keep that misfit."""
    return max([math.sqrt(max(c.gain, 0.0) / c.bar(penalty)) for c in cands if c.kind not in contradicted],
               default=0.0)


def analyse(ctx: Context, null: mismatch.Null, grid: mismatch.Grid, cands: list[Candidate],
            contradicted: AbstractSet[str], maps: tuple[np.ndarray, np.ndarray] | None = None) -> Analysis:
    """Map, regions and score of the context's residual (``Context.residual``; its ln avar
    cells and whole-record taus ``maps`` when already taken, ``mismatch.log_avar``;
    candidates: the matched tests run on it, those of the ``contradicted`` kinds not
    counted, ``matched_tests_figure``)."""
    cell, whole = maps if maps is not None else mismatch.log_avar(ctx.residual(np.nan), ctx.valid, grid)
    z, zw = mismatch.zscores(cell, whole, null)
    _, zs = spike_scan(ctx)  # (computed once per context)
    nv = int(ctx.valid.sum())
    spike_ratio = float(np.max(np.abs(zs))) / detectors.expected_max_abs_z(nv) if nv else 0.0
    regions = mismatch.find_regions(z, zw, null, grid)
    tests = matched_tests_figure(cands, ctx.penalty, contradicted)
    return Analysis(cell, whole, z, zw, regions, mismatch.score(z, null, spike_ratio, tests), null)


def rescored(a: Analysis, cands: list[Candidate], penalty: float, contradicted: AbstractSet[str]) -> Analysis:
    """``a`` with its score's ``tests`` taken again without the ``contradicted`` kinds."""
    return replace(a, score=replace(a.score, tests=matched_tests_figure(cands, penalty, contradicted)))
