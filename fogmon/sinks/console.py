"""Console sink: events as they happen (stderr, rate-limited) and the end-of-run summary
(stdout): the whole-run Allan deviation with its confidence bounds, the IEEE-952
coefficients with their intervals, and the counters; and a replay's progress bar
(stderr, tqdm, only on a terminal). The text names the run's parameters as `name`
(fogmon.errors): plainly, or as the flags of a table given (fogmon.cli's)."""
from __future__ import annotations

import math
import sys
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import TextIO

from fogmon.block import Event
from fogmon.errors import render_names
from fogmon.sinks.base import ACCEL_COEFFICIENTS, COEFFICIENTS, AccelSummary, AxisSummary, Sink, Summary
from fogmon.stopping import stop_name
from fogmon.window import default_window_s

#: Events of one kind printed as they happen before the rest are only counted.
MAX_EVENTS_PER_KIND = 10


def format_summary(s: Summary, flags: Mapping[str, str] | None = None) -> str:
    """The summary as text (units in every heading); a run of several axes shows the
    axes side by side (``axes_lines``). Parameters are named plainly, or as their flags
    in ``flags`` (parameter name -> flag)."""
    lines = []
    state = f"interrupted ({stop_name()})" if s.interrupted else f"stopped ({s.stopped})" if s.stopped else "done"
    lines.append(f"fogmon: {state}: {s.source_name}")
    lost = "invalid/lost on some axis" if s.axes else "invalid/lost"
    speed = f"{s.speed_x:,.0f}" if s.speed_x >= 10 else f"{s.speed_x:.2g}"   # a live run: about x1
    lines.append(f"  {s.n_samples} samples at {s.sample_rate_hz:g} Hz = {s.duration_s:.2f} s of recording "
                 f"({s.n_invalid} {lost}), in {s.wall_s:.2f} s wall = x{speed} real time")
    per_axis = " per axis" if s.axes else ""
    lines.append(f"  {s.n_windows} DADEV windows{per_axis} of {s.window_s:g} s every {s.hop_s:g} s")
    if not s.n_windows:
        lines.append(f"  {no_windows_reason(s)}")
    if s.analysed != "rate_dph":
        why = (["the gyro's error against the reference rotation"] if "rot_dps" in s.analysed else []) + \
              (["the `thermal` drift subtracted sample by sample"] if "thermal" in s.analysed else [])
        lines.append(f"  analysed: {s.analysed} (deg/h): {'; '.join(why)} (`raw_rate` for rate_dph itself)")
    lines += axes_lines(s) if s.axes else condition_lines(s, s) + result_lines(s, s)
    if s.accels:
        lines += accel_lines(s)
    if s.counters or s.event_counts:
        lines.append("")
        lines.append("Counters:")
        for k, v in {**s.counters, **{f"events.{k}": v for k, v in s.event_counts.items()}}.items():
            lines.append(f"  {k:<24} {v}")
    for o in s.outputs:
        lines.append(f"Wrote {o}{_open_hint(o)}")
    return render_names("\n".join(lines), flags)


def condition_lines(x: AxisSummary, run: Summary) -> list[str]:
    """One axis's platform motion and live model check (``run``: the whole run's summary)."""
    return (motion_lines(x, run) if x.motion_spans else []) + \
        (model_check_lines(x.model_check) if x.model_check is not None else []) + \
        (phase_lines(x.phases) if x.phases is not None else [])


def result_lines(x: AxisSummary, run: Summary) -> list[str]:
    """One axis's whole-run ADEV table and IEEE-952 coefficients."""
    lines = []
    a = x.overall
    if a is not None:
        lines += ["", f"Overall Allan deviation ({_span(x, run)}, {100 * a.confidence:.1f} % confidence bounds):"]
        lines += adev_lines(a)
    f = x.overall_fit
    if f is not None:
        lines += ["", f"IEEE-952 noise coefficients (whole run, {100 * f.confidence:.1f} % intervals):"]
        lines += coefficient_lines(f)
        lines += contradiction_lines(f)
        check = model_check(a, f) if a is not None else None
        if check is not None:
            lines.append(check)
    return lines + motion_effect_lines(x)


def accel_lines(s: Summary) -> list[str]:
    """The accelerometers of a run side by side: invalid samples and motion kept out, the
    whole-run ADEV (micro-g) and the IEEE Std 1293 coefficients."""
    acc = s.accels
    lines = ["", f"Accelerometers {', '.join(acc)} (aux channels accel_<name>_g, analysed in micro-g; platform "
                 f"motion as the gyro gate found it):",
             "  invalid/lost samples: " + ", ".join(f"{a} {x.n_invalid}" for a, x in acc.items())
             + ("; kept out as platform motion: " + ", ".join(f"{a} {x.motion_samples}" for a, x in acc.items())
                if any(x.motion_samples for x in acc.values()) else "")]
    done = {a: x.overall for a, x in acc.items() if x.overall is not None}
    if not done:
        return [*lines, "  no whole-run Allan deviation: no accelerometer has two valid samples in a row"]
    first: AccelSummary = next(x for x in acc.values() if x.overall is not None)
    conf = next(iter(done.values())).confidence
    lines += ["", f"Accelerometer Allan deviation ({_span(first, s)}, {100 * conf:.1f} % confidence bounds), "
                  f"adev_ug [lo_ug, hi_ug]:"]
    lines += adev_axes_lines(done)
    fits = {a: x.overall_fit for a, x in acc.items() if x.overall_fit is not None}
    fit_conf = next(iter(fits.values())).noise.confidence if fits else conf
    lines += ["", f"Accelerometer noise coefficients (IEEE Std 1293: velocity random walk, bias instability, "
                  f"acceleration random walk; whole run, {100 * fit_conf:.1f} % intervals; n/i: not identifiable, "
                  f"< its 95 % upper limit):"]
    lines += coefficient_axes_lines(fits, ACCEL_COEFFICIENTS)
    for a, x in acc.items():
        if x.overall is not None and x.overall_fit is not None:
            check = model_check(x.overall, x.overall_fit.noise)
            if check is not None:
                lines.append(check.replace("model check:", f"model check (accelerometer {a}):"))
    return lines


def _span(x: AxisSummary | AccelSummary, run: Summary) -> str:
    """The time span of the whole-run ADEV, s."""
    return f"{x.overall_first_s:.2f}..{run.t_last_s:.2f} s"


def axes_lines(s: Summary) -> list[str]:
    """The axes of a multi-axis run: invalid samples, motion and model check per axis,
    then the whole-run ADEV and the coefficients of every axis side by side."""
    axes = s.axes
    lines = ["  invalid/lost samples per axis: " + ", ".join(f"{a} {x.n_invalid}" for a, x in axes.items())]
    for a, x in axes.items():
        lines += [f"  axis {a}: {ln[2:]}" if ln[2] != " " else ln for ln in condition_lines(x, s)]
    done = {a: x.overall for a, x in axes.items() if x.overall is not None}
    if done:
        first = next(x for x in axes.values() if x.overall is not None)
        conf = next(iter(done.values())).confidence
        lines += ["", f"Overall Allan deviation per axis ({_span(first, s)}, {100 * conf:.1f} % confidence "
                      f"bounds), adev_dph [lo_dph, hi_dph]:"]
        lines += adev_axes_lines(done)
    fits = {a: x.overall_fit for a, x in axes.items() if x.overall_fit is not None}
    if fits:
        conf = next(iter(fits.values())).confidence
        lines += ["", f"IEEE-952 noise coefficients per axis (whole run, {100 * conf:.1f} % intervals; n/i: not "
                      f"identifiable from this record, < its 95 % upper limit):"]
        lines += coefficient_axes_lines(fits)
        for a, f in fits.items():
            lines += [ln.replace("  ", f"  axis {a}: ", 1) for ln in contradiction_lines(f)]
        for a, x in axes.items():
            check = model_check(x.overall, x.overall_fit) if x.overall is not None and x.overall_fit else None
            if check is not None:
                lines.append(check.replace("model check:", f"model check (axis {a}):"))
    for a, x in axes.items():
        lines += motion_effect_lines(x, a)
    return lines


#: Width of one axis's column in the side-by-side tables.
AXIS_COLUMN = 28


def adev_axes_lines(results: dict, rows=None) -> list[str]:
    """AdevResults of several axes (same taus) side by side: tau_s, then per axis
    adev_dph [lo_dph, hi_dph]; ``rows``: the indices shown (None: all)."""
    out = [f"  {'tau_s':>10} " + " ".join(f"{a:>{AXIS_COLUMN}}" for a in results)]
    tau_s = next(iter(results.values())).tau_s
    for i in range(len(tau_s)) if rows is None else rows:
        cells = [(f"{r.adev_dph[i]:.5g} [{r.lo_dph[i]:.4g}, {r.hi_dph[i]:.4g}]" if _has_interval(r, i)
                  else f"{r.adev_dph[i]:.5g} [no interval]") if r.n_terms[i] else "no valid term"
                 for r in results.values()]
        out.append(f"  {tau_s[i]:10.4g} " + " ".join(f"{c:>{AXIS_COLUMN}}" for c in cells))
    return out + _no_interval_note(results.values(), rows)


def _has_interval(a, i: int) -> bool:
    return bool(math.isfinite(float(a.lo_dph[i])) and math.isfinite(float(a.hi_dph[i])))


def _no_interval_note(results, rows=None) -> list[str]:
    """The footnotes of ADEV tables: a tau (of ``rows``; None: all) printed without its
    interval (its EDF below ``confidence.MIN_EDF``, where a chi-square interval can
    exclude its own estimate), an ADEV of inf (a sample beyond the engine's ceiling), a
    record whose rate never changes."""
    from fogmon.davar.confidence import MIN_EDF
    from fogmon.davar.kernels import CEILING_DPH

    shown = [(r, i) for r in results for i in (range(len(r.tau_s)) if rows is None else rows) if r.n_terms[i]]
    out = []
    if any(not _has_interval(r, i) and math.isfinite(float(r.adev_dph[i])) for r, i in shown):
        out.append(f"  no interval: EDF below {MIN_EDF:g} (less than one independent Allan term at that tau), "
                   f"where the chi-square interval would not hold the estimate")
    if any(not math.isfinite(float(r.adev_dph[i])) for r, i in shown):
        out.append(f"  inf: an Allan term at that tau spans a sample beyond {CEILING_DPH:g} deg/h (the engine's "
                   f"ceiling; a plausibility gate `max_rate_dph` above it lets such samples through)")
    if shown and all(float(r.adev_dph[i]) == 0.0 for r, i in shown):
        out.append("  the rate never changes (every Allan deviation is 0): a stuck or saturated output, not a "
                   "sensor's noise; no coefficient can be fitted")
    return out


def coefficient_axes_lines(fits: dict, names: Mapping[str, str] = COEFFICIENTS) -> list[str]:
    """The five IEEE-952 coefficients of whole-record NoiseFits of several axes side by
    side: name, unit, then per axis value [lo, hi] or n/i (< 95 % upper limit); ``names``
    (name -> unit) ACCEL_COEFFICIENTS for AccelFits."""
    w = max(11, *(len(n) for n in names))
    out = [f"  {'coefficient':<{w}} {'unit':<14}" + " ".join(f"{a:>{AXIS_COLUMN}}" for a in fits)]
    for name, unit in names.items():
        cells = []
        for f in fits.values():
            c = getattr(f, name)
            if bool(c.identifiable):
                cells.append(f"{float(c.value):.4g} [{float(c.lo):.4g}, {float(c.hi):.4g}]")
            else:
                up = float(c.upper)
                cells.append(f"n/i (< {up:.4g})" if math.isfinite(up) else "n/i")
        out.append(f"  {name:<{w}} {unit:<14}" + " ".join(f"{c:>{AXIS_COLUMN}}" for c in cells))
    return out


def adev_lines(a, unit: str = "dph", rows=None) -> list[str]:
    """An AdevResult as a table: tau_s, adev_dph, lo_dph, hi_dph, edf, n_terms (``unit``
    "ug" for an accelerometer's, in micro-g); ``rows``: the indices shown (None: all);
    "-" and a footnote where a tau has no interval (EDF below 1)."""
    out = [f"  {'tau_s':>10} {'adev_' + unit:>12} {'lo_' + unit:>12} {'hi_' + unit:>12} {'edf':>10} {'n_terms':>9}"]
    for i in range(len(a.tau_s)) if rows is None else rows:
        if not a.n_terms[i]:
            out.append(f"  {a.tau_s[i]:10.4g}   no valid Allan term (the record is too short, or every term "
                       f"spans a gap or platform motion)")
            continue
        lo, hi = (f"{a.lo_dph[i]:12.5g}", f"{a.hi_dph[i]:12.5g}") if _has_interval(a, i) else (f"{'-':>12}",) * 2
        out.append(f"  {a.tau_s[i]:10.4g} {a.adev_dph[i]:12.5g} {lo} {hi} {a.edf[i]:10.4g} {int(a.n_terms[i]):9d}")
    return out + _no_interval_note([a], rows)


def coefficient_lines(f, names: Mapping[str, str] = COEFFICIENTS) -> list[str]:
    """The five IEEE-952 coefficients of a whole-record NoiseFit with their intervals, or
    "not identifiable" with the 95 % upper limit; ``names`` (name -> unit)
    ACCEL_COEFFICIENTS for an AccelFit."""
    out = []
    w = max(9, *(len(n) for n in names))
    for name, unit in names.items():
        c = getattr(f, name)
        if bool(c.identifiable):
            tag = "  white angle noise, not quantization" if name == "Q_arcsec" and _q_band_limited(f) else ""
            out.append(f"  {name:<{w}} = {float(c.value):.4g} {unit}  [{float(c.lo):.4g}, {float(c.hi):.4g}]{tag}")
        else:
            up = float(c.upper)
            bound = f" (< {up:.4g} {unit}, 95 % upper limit)" if math.isfinite(up) else ""
            out.append(f"  {name:<{w}}   not identifiable from this record{bound}")
    return out


def _q_band_limited(f) -> bool:
    return bool(getattr(f, "q_band_limited", False))


def contradiction_lines(f) -> list[str]:
    """A line per term of a whole-record NoiseFit that the measured ADEV contradicts
    (``NoiseFit.contradicted``, fogmon.davar.termcheck): a Q that is band-limited white
    angle noise, not quantization; a B, K or R printed as not identifiable, and why."""
    out = []
    count = float(getattr(f, "quantized_count_arcsec", math.nan))
    if math.isfinite(count):
        out.append(f"  Q_arcsec: the output is quantized: its samples lie on a lattice of {count:.4g} arcsec of angle "
                   f"per sample (a white quantizer of that count: Q = {count / math.sqrt(12.0):.4g} arcsec); the 1/tau "
                   f"slope does not reach the shortest taus because the quantization error is not white when the "
                   f"angle moves less than a count per sample, so the ADEV does not bound the quantizer")
    for c in getattr(f, "contradicted", ()):
        unit = COEFFICIENTS[c.name]
        level = f"{100 * c.limit_confidence:g} % upper limit"
        bound = (f"{c.adev_dph:.4g} deg/h (upper bound {c.bound_dph:.4g} deg/h at {100 * c.bound_confidence:.2f} %, "
                 f"family-wise {100 * (1 - c.limit_confidence):g} % over the taus)")
        if c.name == "Q_arcsec":
            out.append(f"  {c.name}: white angle noise, not quantization: its 1/tau slope (own ADEV "
                       f"{c.term_adev_dph:.4g} deg/h at tau {c.tau_s:.4g} s) does not reach the shortest taus, where "
                       f"the ADEV is {bound}; a quantizer on the output would (it is white in angle up to Nyquist): "
                       f"the output is band-limited (filtered or decimated: a sensor model's bandwidth effect) or the "
                       f"slope is the far side of a narrowband signal; an output quantizer is < {c.limit:.4g} arcsec "
                       f"({level})")
        else:
            what = {"B_dph": "flicker floor", "K_dphsh": "rate random walk", "R_dphh": "rate ramp"}[c.name]
            out.append(f"  {c.name}: the fit's {c.value:.4g} {unit} is not identified: its {what} (own ADEV "
                       f"{c.term_adev_dph:.4g} deg/h at tau {c.tau_s:.4g} s) lies above the measured ADEV there, "
                       f"{bound}; the terms add in variance, so none exceeds the record's ADEV: the fit took a hump "
                       f"(correlated noise, a transient) for a {what}; the ADEV bounds it: < {c.limit:.4g} {unit} "
                       f"({level})")
    return out


#: Platform-motion spans listed in the summary before the rest is only counted.
MAX_MOTION_SPANS = 20


def model_check_lines(mc: dict) -> list[str]:
    """The live model check of the session (``model``): time inside / outside the band
    and every departure."""
    out = [f"  model band (`model`, family-wise {mc['alpha_per_window']:g} per window): inside "
           f"{mc['time_inside_s']:.1f} s, outside {mc['time_outside_s']:.1f} s, not judged "
           f"{mc['time_unjudged_s']:.1f} s; {mc['n_departures']} departure(s)"]
    for d in mc["departures"]:
        end = f"{d['end_s']:.2f} s" if d["end_s"] is not None else "the end (still out)"
        out.append(f"    {d['start_s']:.2f} s .. {end}: peak {d['peak_ratio']:.3g}x the model at tau "
                   f"{d['peak_tau_s']:.4g} s; {d['shape']}; likely cause: {d['cause']}")
    if mc["left_out_effects"]:
        out.append(f"    not in the band (need aux channels or a schedule): {', '.join(mc['left_out_effects'])}")
    return out


def phase_lines(ph: dict) -> list[str]:
    """The operating phases of the session (from the pumps / rot_dps channels it has) and,
    per state, the range of every coefficient the window fits identified (docs/monitor.md)."""
    src = " / ".join(ph.get("channels") or ("pumps", "rot_dps"))
    out = [f"  phases (from {src}; {ph['transition_windows']} window(s) straddling a change are in none):"]
    for state, s in ph["states"].items():
        spans = ", ".join(f"{p['t_first_end_s']:.0f}..{p['t_last_end_s']:.0f} s" for p in s["phases"][:4])
        more = f", ... ({len(s['phases']) - 4} more)" if len(s["phases"]) > 4 else ""
        ranges = "; ".join(f"{n} {lo:.4g}..{hi:.4g} {COEFFICIENTS[n]}" for n, (lo, hi) in s["ranges"].items())
        out.append(f"    {state}: {len(s['phases'])} phase(s), {s['windows']} window(s) ending {spans}{more}")
        out.append(f"      {ranges or 'no coefficient identified in its windows'}")
    return out


def motion_lines(s: AxisSummary, run: Summary) -> list[str]:
    """The platform-motion spans kept out of the analysis (all, or the first
    MAX_MOTION_SPANS and where the rest are); ``run`` the whole run's summary."""
    from fogmon.motion import REFERENCE_S

    spans = s.motion_spans
    pct = 100.0 * s.motion_samples / max(run.n_samples, 1)
    steps = sum(m.level_change for m in spans)
    step_note = (f"; {steps} ended in a new level the rate held: a step, such as a bias change, which the live "
                 f"gate cannot tell from motion until it has held for {REFERENCE_S / 2:g} s" if steps else "")
    out = [f"  platform motion: {len(spans)} span(s), {s.motion_samples} samples ({pct:.1f} %) kept out of "
           f"DAVAR and the fits (`keep_motion` analyses them; docs/motion.md){step_note}:"]
    shown = [f"{m.t_start_s:.2f}..{m.t_end_s:.2f} s (peak {m.peak_dph:.3g} deg/h"
             f"{', then a new level: a step' if m.level_change else ''})" for m in spans[:MAX_MOTION_SPANS]]
    for i in range(0, len(shown), 3):
        out.append("    " + ", ".join(shown[i:i + 3]))
    if len(spans) > MAX_MOTION_SPANS:
        rrd = [o for o in run.outputs if o.endswith(".rrd")]
        where = f"all are in the event log of {rrd[0]}" if rrd else "`rrd_path` keeps all of them in its event log"
        out.append(f"    ... and {len(spans) - MAX_MOTION_SPANS} more ({where})")
    return out


def motion_effect_lines(x: AxisSummary, axis: str = "") -> list[str]:
    """What keeping platform motion out changed (``axis``: its name in a multi-axis run):
    the whole-run coefficients without and with the samples the motion gate kept out,
    value [lo, hi] or n/i (< 95 % upper limit)."""
    if x.fit_with_motion is None or x.overall_fit is None or x.overall is None:
        return []
    pct = 100.0 * x.motion_in_tail / max(x.overall.n_samples, 1)
    where = f" (axis {axis})" if axis else ""
    rows = []
    for name, unit in COEFFICIENTS.items():
        cells = []
        for f in (x.overall_fit, x.fit_with_motion):
            c = getattr(f, name)
            cells.append(f"{float(c.value):.4g} [{float(c.lo):.4g}, {float(c.hi):.4g}]" if bool(c.identifiable)
                         else f"n/i (< {float(c.upper):.4g})")
        rows.append((name, unit, *cells))
    w = max(len(r[k]) for r in rows for k in (2, 3)) + 2
    return ["", f"IEEE-952 noise coefficients{where} without and with platform motion ({x.motion_in_tail} samples, "
                f"{pct:.1f} %, kept out above; `keep_motion` analyses them; {100 * x.overall_fit.confidence:.1f} % "
                f"intervals; n/i: not identifiable from this record, < its 95 % upper limit):",
            f"  {'coefficient':<11} {'unit':<14}{'motion kept out':>{w}}{'motion analysed':>{w}}"] + \
        [f"  {n:<11} {u:<14}{a:>{w}}{b:>{w}}" for n, u, a, b in rows]


def _open_hint(output: str) -> str:
    """How to look at an output: one .rrd, or .rrd pieces NAME-0001.rrd .. (all at once)."""
    if output.endswith(".rrd"):
        return f" (open it with: rerun {output})"
    first = output.split(" .. ")[0]
    if " .. " in output and first.endswith("-0001.rrd"):
        return f" (open them with: rerun {first[:-len('0001.rrd')]}*.rrd)"
    return ""


def no_windows_reason(s: Summary) -> str:
    """Why a run of at least one sample gave no DADEV window (it was shorter than one
    window) and the ``window_s`` that would give some."""
    w = round(s.window_s * s.sample_rate_hz)
    run_s = s.n_samples / s.sample_rate_hz
    return (
        f"no DADEV window: the window is {w} samples = {s.window_s:g} s at {s.sample_rate_hz:g} Hz and the run had "
        f"{s.n_samples:,} samples ({run_s:g} s); use `window_s` {default_window_s(s.sample_rate_hz, s.n_samples):g} "
        f"(or any window up to {run_s:g} s)"
    )


def _factor(x: float) -> str:
    """A factor >= 1 at 3 significant digits, or at as many more (up to 6) as it takes not
    to print "1" for a factor that is not 1 (a departure of 0.4 % at an EDF of 1e5 is beyond
    chance, and "model 1x below" would say there is none)."""
    for d in range(3, 7):
        text = f"{x:.{d}g}"
        if float(text) != 1.0 or x == 1.0:
            return text
    return text


def model_check(a, fit) -> str | None:
    """Lines testing the fitted IEEE-952 model against the measured ADEV
    (``fogmon.davar.adequacy.check_model``: chi-square with each tau's EDF, family-wise
    over the taus): a WARNING naming every tau where the model departs beyond chance and
    by how much, else the largest factor; then the taus the robust fit flagged
    (``fit.misfit``)."""
    import numpy as np

    from fogmon.davar.adequacy import check_model

    c = check_model(a, fit)
    if c is None:
        return None
    misfit = np.asarray(fit.misfit, dtype=bool)
    where = "every tau" if not misfit.any() else f"the {c.n_taus} taus it describes"
    test = f"chi-square with each tau's EDF, family-wise {100 * c.level:g} % over {c.n_taus} taus"
    if not c.departs:
        line = (f"  model check: the fitted model agrees with the measured ADEV within chance at {where} ({test}; "
                f"largest factor {c.worst_ratio:.2f} at tau {c.worst_tau_s:.4g} s)")
    else:
        taus = ", ".join(f"{t:.4g} s (model {_factor(max(r, 1 / r))}x {'above' if r > 1 else 'below'}, p {p:.2g})"
                         for t, r, p in zip(c.tau_s, c.ratio, c.p, strict=True))
        line = (f"  model check: WARNING the fitted model departs from the measured ADEV beyond chance ({test}) at "
                f"tau {taus}: the five IEEE-952 terms do not describe this record (periodic or vibration terms, "
                f"non-stationarity) or the fit failed; read the coefficients with care")
    if misfit.any():
        taus = ", ".join(f"{t:.4g}" for t in np.asarray(a.tau_s)[misfit])
        line += (f"\n  model check: tau {taus} s not described by the five terms (vibration or periodic "
                 f"humps, quantization, steps): flagged and left out of the fit")
    return line


class ConsoleSink(Sink):
    """Prints events to ``err`` as they happen and the summary to ``out`` at the end,
    parameters named as their flags in ``flags`` (parameter name -> flag; None: plainly)."""

    finish_order = 10

    def __init__(self, quiet: bool = False, out: TextIO | None = None, err: TextIO | None = None,
                 flags: Mapping[str, str] | None = None):
        self.quiet = quiet
        self.out, self.err = out, err
        self.flags = flags
        self._seen: Counter = Counter()

    def events(self, events: Sequence[Event]) -> None:
        err = self.err or sys.stderr
        for e in events:
            self._seen[e.kind] += 1
            n = self._seen[e.kind]
            if n <= MAX_EVENTS_PER_KIND:
                axis = f" (axis {e.axis})" if e.axis else ""
                err.write(f"[{e.t_s:10.2f} s] {e.kind}{axis}: {render_names(e.message, self.flags)}\n")
            elif n == MAX_EVENTS_PER_KIND + 1:
                err.write(f"[{e.t_s:10.2f} s] {e.kind}: more of these are only counted (see the summary)\n")

    def finish(self, summary: Summary) -> None:
        """The summary, unless quiet, failed, or empty (no sample: the command says so)."""
        if not self.quiet and not summary.failed and summary.n_samples:
            out = self.out or sys.stdout
            out.write(format_summary(summary, self.flags) + "\n")
            out.flush()
