"""Fair competition between a channel law (``aux_response``) and the catalogue kinds it can
look like (docs/explain.md, "Laws outside the catalogue"): conditions switched in steps
look like bias steps, an oscillating channel like a periodic term, a temperature-driven
drift like a ramp, a rectified vibration's long-tau power like a wrong B or N.

The rule, applied by the forward selection (fogmon.explain.selection) in three places:

1. **The law is judged first** in its round (``first``) when it passes its bar: what a
   channel explains must not be named as something else first (a catalogue kind, or
   ``noise``, the model's own coefficients).
2. **Unless the catalogue explains more** (``refusal``): for every mean-type catalogue
   candidate of the round that passes its own bar, the joint GLS of both designs gives
   each one's gain beyond the other. The law is deferred when it adds no more than its
   bar beyond that candidate while the candidate adds more than its own bar beyond the
   law: the channel does not predict the timing and the sizes, the catalogue kind does.
   When neither adds anything beyond the other (one switch of a channel, one step of
   the bias) the channel, which predicts the timing, is preferred - unless the
   catalogue kind follows a channel itself (``scale_factor`` on rot_dps,
   ``thermal_drift`` on temp_c: a rotation switched between 0 and one rate makes
   rot_dps^2 the same feature as rot_dps), then its named physics is kept.
3. **The evidence names what was refused** (``explained``): every catalogue kind (mean-
   or noise-type) that passed its bar before the law was accepted and no longer does
   after it is a look-alike the law explains; the accepted law's evidence says so with
   both BIC gains.

A Gauss-Markov term (``markov``) and a wrong IEEE-952 coefficient (``noise``) are
look-alikes too: both raise the residual's spectrum over the whole record. The Gauss-
Markov term is a hump in the Allan deviation (rising ~ sqrt(tau), falling ~ 1/sqrt(tau)
after tau ~ 1.9 tau_c), a wrong N a flat offset of the white slope, a wrong B or K a
lasting rise; both are scored by the Whittle likelihood of the same binned periodogram,
so the likelihood decides:

4. **The one the data support more is judged first** (``ahead``): ``noise`` is judged in
   the first tier (a wrong coefficient fakes steps and ramps in its GLS tests), ``markov``
   in the second; when markov's BIC gain is the larger and the noise kind passes its
   bar, markov takes the noise kind's place in the first tier, just before it (so the
   noise kind is still judged if markov is refused).
5. **The evidence names what was refused** (``explained``, as in 3): the other one, when
   it passed its bar before and no longer does after; when the two BIC gains lie less
   than TIE_BIC apart the likelihood does not prefer either (Kass & Raftery 1995: a BIC
   difference below 2 is "not worth more than a bare mention"), and the evidence and a
   ``lookalike`` warning say the record cannot tell them apart (``tie``). A Gauss-Markov
   term of tau_c 60 s, sigma 0.25 deg/h beside N 0.02 deg/sqrt(h), B 0.02 deg/h over 2 h
   at 10 Hz was named "your B is 0.195 deg/h [0.154, 0.229], not 0.02" (BIC gains 134.35
   against markov's 134.3), described as "corrected IEEE-952 slopes describe the residual
   better".
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from fogmon.explain.candidates.base import Candidate, Context
from fogmon.sim.model import EFFECT_KINDS

LAW = "aux_response"
#: the kinds each accepted kind's evidence names as refused look-alikes (``explained``;
#: the law: every catalogue kind)
RIVALS = {"markov": ("noise",), "noise": ("markov",)}
#: BIC gains of an accepted kind and its refused rival closer than this: a tie (``explained``)
TIE_BIC = 2.0
#: why the likelihood preferred the accepted kind over its rival (``explained``)
_PREFERRED = {"markov": "a hump in the Allan deviation (a Gauss-Markov term) describes the residual better than "
                       "corrected IEEE-952 slopes",
              "noise": "corrected IEEE-952 slopes describe the residual better than a Gauss-Markov hump"}


def first(cands: list[Candidate], penalty: float) -> list[Candidate]:
    """``cands`` (best BIC gain first) with the channel law moved to the front when it
    passes its bar."""
    law = next((c for c in cands if c.kind == LAW), None)
    if law is None or law.bic_gain(penalty) <= 0:
        return cands
    return [law, *(c for c in cands if c is not law)]


def ahead(first: list[Candidate], second: list[Candidate], penalty: float) -> tuple[list[Candidate], list[Candidate]]:
    """The selection's two tiers with ``markov`` moved from the second into the first,
    just before ``noise``, when its BIC gain is the larger (module docstring, 4) and the
    selection reaches the noise kind: it and every candidate ahead of it pass their bar
    (the first one that does not ends the tier; markov then stays in the second)."""
    mk = next((c for c in second if c.kind == "markov"), None)
    at = next((i for i, c in enumerate(first) if c.kind == "noise"), None)
    if (mk is None or at is None or not mk.bic_gain(penalty) > first[at].bic_gain(penalty)
            or not all(c.bic_gain(penalty) > 0 for c in first[:at + 1])):
        return first, second
    return [*first[:at], mk, *first[at:]], [c for c in second if c is not mk]


def _gain(ctx: Context, X: np.ndarray) -> float:
    return ctx.wh.gls(ctx.wh.fft(X), ctx.Yf).chi2_gain


def refusal(law: Candidate, cands: list[Candidate], ctx: Context,
            refit: Callable[[Candidate], Candidate | None] = lambda c: None) -> str | None:
    """Why the law ``law`` is a look-alike of a mean-type catalogue candidate of the round
    that explains more (module docstring, 2), or None. A candidate kept without its
    design (the selection's bounded memory) is fitted again by ``refit``."""
    if law.kind != LAW or law.design is None:
        return None
    pen = ctx.penalty
    g_law = _gain(ctx, law.design)
    for o in cands:
        if o.kind == LAW or o.nature != "mean" or o.bic_gain(pen) <= 0:
            continue
        design = o.design
        if design is None:
            again = refit(o)
            if again is None or again.design is None:
                continue
            design = again.design
        g_o = _gain(ctx, design)
        joint = _gain(ctx, np.column_stack((law.design, design)))
        law_beyond, o_beyond = joint - g_o, joint - g_law
        if law_beyond > law.bar(pen):
            continue
        if o_beyond > o.bar(pen):
            return (f"a look-alike of {o.kind}: beyond it the law adds chi2 {law_beyond:.1f} (its bar "
                    f"{law.bar(pen):.1f}), while {o.kind} adds {o_beyond:.1f} beyond the law (bar {o.bar(pen):.1f}): "
                    f"the channels do not predict what {o.kind} fits")
        if EFFECT_KINDS[o.kind].aux is not None:
            return (f"a look-alike of {o.kind}: neither adds more than its bar beyond the other (the law "
                    f"{law_beyond:.1f}, {o.kind} {o_beyond:.1f}), and {o.kind} follows a channel "
                    f"({EFFECT_KINDS[o.kind].aux}) too: the catalogue's physics is kept")
    return None


def explained(c: Candidate, before: list[Candidate], after: list[Candidate], penalty: float) -> Candidate:
    """``c`` with its evidence naming the look-alikes it explains (module docstring, 3 and
    5): candidates of ``before`` (the round it was accepted in) of a kind it rivals (the
    law: every catalogue kind; ``RIVALS``) that passed their bar, whose kind in ``after``
    (the next round) no longer does."""
    if c.kind != LAW and c.kind not in RIVALS:
        return c
    now = {o.kind: o.bic_gain(penalty) for o in after}
    gone = [(o.kind, o.bic_gain(penalty), now.get(o.kind)) for o in before
            if o.kind != c.kind and (c.kind == LAW or o.kind in RIVALS[c.kind])
            and o.bic_gain(penalty) > 0 and not now.get(o.kind, 0.0) > 0]
    if not gone:
        return c
    text = "; ".join(f"{k} (BIC gain {b:.1f} before {'the law' if c.kind == LAW else c.kind}, "
                     f"{'not fitted' if a is None else f'{a:.1f}'} after)" for k, b, a in gone)
    if c.kind == LAW:
        return replace(c, evidence=f"{c.evidence}. Look-alikes refused, explained by the law: {text}")
    own = c.bic_gain(penalty)
    kind, gain, _ = max(gone, key=lambda g: g[1])
    if own - gain < TIE_BIC:
        rival = next(o for o in before if o.kind == kind)
        return replace(c, evidence=f"{c.evidence}. Look-alike refused: {text}: the record cannot tell them apart "
                                   f"(BIC gains {own:.2f} and {gain:.2f}, less than {TIE_BIC:g} apart); "
                                   f"{c.kind} is named for its larger gain",
                       tie={"kind": kind, "params": dict(rival.params), "bic_gain": gain, "own_bic_gain": own})
    return replace(c, evidence=f"{c.evidence}. Look-alike refused: {text}: {_PREFERRED[c.kind]}")
