"""Fitted noise parameters in other tools' formats and units (``export``): Kalibr
imu.yaml, allan_variance_ros's imu.yaml with its console values, and a MATLAB
``gyroparams`` (and ``accelparams``) snippet. The one place that knows these unit
conversions (docs/exports.md has the table and the discrete-time pitfalls).

Continuous-time densities from the IEEE-952 gyro coefficients (rad = deg x pi/180):
  noise density   [rad/s/sqrt(Hz)]   = N [deg/sqrt(h)] x pi/180 / 60
  random walk     [rad/s^2/sqrt(Hz)] = K [deg/h/sqrt(h)] x pi/180 / 3600 / 60
  bias instability [rad/s]           = B [deg/h] x pi/180 / 3600
and from an accelerometer's IEEE Std 1293 coefficients (fogmon.units.ACCEL_NAMES):
  noise density   [m/s^2/sqrt(Hz)]   = VRW [m/s/sqrt(h)] / 60
  random walk     [m/s^3/sqrt(Hz)]   = AccRW [m/s/h/sqrt(h)] / 216000
  bias instability [m/s^2]           = Bias [micro-g] x 1e-6 x 9.80665
Per-sample (discrete) sigmas at rate f (Hz): white noise density x sqrt(f), random walk
/ sqrt(f). A term the record cannot identify is exported as its 95 % upper limit (a
filter tuned with it is conservative, not overconfident), and the file says so. Kalibr
and allan_variance_ros hold one value per sensor for all axes: of several axes the
largest (as allan_variance_ros takes), each axis's in a comment; MATLAB gets one value
per axis. ``update_rate`` is written only when the record's rate is known, ``rostopic``
only for a ROS source."""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

from fogmon.davar.fit import NAMES
from fogmon.errors import FogmonError
from fogmon.outputs import check_outputs, written
from fogmon.units import G0_MPS2

RAD_PER_DEG = math.pi / 180.0
FORMATS = ("kalibr", "matlab", "ros")
#: the ADEV flat floor of bias instability, in units of B: sqrt(2 ln 2 / pi)
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def noise_density_rad(n_dpsh: float) -> float:
    """Angle random walk N (deg/sqrt(h)) -> white-noise density (rad/s/sqrt(Hz))."""
    return n_dpsh * RAD_PER_DEG / 60.0


def random_walk_rad(k_dphsh: float) -> float:
    """Rate random walk K (deg/h/sqrt(h)) -> bias random-walk density (rad/s^2/sqrt(Hz))."""
    return k_dphsh * RAD_PER_DEG / 3600.0 / 60.0


def bias_instability_rad(b_dph: float) -> float:
    """Bias instability B (deg/h) -> rad/s."""
    return b_dph * RAD_PER_DEG / 3600.0


def accel_noise_density(vrw_mpsph: float) -> float:
    """Velocity random walk (m/s/sqrt(h)) -> white-noise density (m/s^2/sqrt(Hz))."""
    return vrw_mpsph / 60.0


def accel_random_walk(accrw_mpshsh: float) -> float:
    """Acceleration random walk (m/s/h/sqrt(h)) -> bias random-walk density (m/s^3/sqrt(Hz))."""
    return accrw_mpshsh / 216000.0


def accel_bias_instability(bias_ug: float) -> float:
    """Bias instability (micro-g) -> m/s^2."""
    return bias_ug * 1e-6 * G0_MPS2


def discrete_white(density: float, sample_rate_hz: float) -> float:
    """Per-sample sigma of white noise of ``density`` (per sqrt(Hz)) sampled at ``sample_rate_hz``."""
    return density * math.sqrt(sample_rate_hz)


def discrete_random_walk(density: float, sample_rate_hz: float) -> float:
    """Per-sample step sigma of a random walk of ``density`` (per sqrt(Hz)) at ``sample_rate_hz``."""
    return density / math.sqrt(sample_rate_hz)


@dataclass(frozen=True)
class Term:
    """One coefficient as exported: ``value`` in IEEE-952 units, ``upper`` True when that
    is the 95 % upper limit of a term the record cannot identify, None when neither is
    known."""

    value: float | None
    upper: bool
    band_limited: bool = False  # Q only: a 1/tau slope that does not reach the shortest tau (NoiseFit.q_band_limited)

    @staticmethod
    def of(c) -> Term:
        """From a fogmon.davar.fit.Coefficient."""
        if bool(c.identifiable):
            return Term(float(c.value), False)
        up = float(c.upper)
        return Term(up if math.isfinite(up) else None, True)

    def q_label(self) -> str:
        """What a Q term is called: a quantizer's 1/tau slope reaches the shortest tau."""
        return "white angle noise Q (band-limited output, not quantization)" if self.band_limited else "quantization Q"

    def note(self, unit: str) -> str:
        if self.value is None:
            return "not identifiable from this record, no upper limit either"
        return f"{self.value:.6g} {unit}" + (" (95 % upper limit: not identifiable from this record)"
                                            if self.upper else "")


def terms(fit) -> dict[str, Term]:
    """Q, N, B, K, R as exported Terms, of a whole-record NoiseFit (fogmon.davar.fit) or
    of a sensor model's noise (fogmon.sim.model.Noise: the values as they stand); of an
    AccelFit (fogmon.davar.accel) its five coefficients by their names."""
    if hasattr(fit, "coefficients"):
        out = {name: Term.of(c) for name, c in fit.coefficients().items()}
        if getattr(fit, "q_band_limited", False):
            out["Q_arcsec"] = replace(out["Q_arcsec"], band_limited=True)
        return out
    return {name: Term(float(getattr(fit, name)), False) for name in NAMES}


#: Gyro fits of an export: one fit (a one-axis record), or axis name -> fit; None: no gyro
Gyros = Mapping[str, object] | object | None


def _by_axis(fits: Gyros) -> dict[str, dict[str, Term]]:
    """Axis ("" of one axis) -> its exported Terms."""
    if fits is None:
        return {}
    return {a: terms(f) for a, f in (fits.items() if isinstance(fits, Mapping) else (("", fits),))}


def _largest(by_axis: dict[str, dict[str, Term]], name: str) -> tuple[str, Term]:
    """The axis whose Term ``name`` is the largest (a value known beats none) and that Term."""
    known = [(t[name].value, a) for a, t in by_axis.items() if t[name].value is not None]
    if not known:
        return next(iter(by_axis)), Term(None, True)
    a = max(known)[1]
    return a, by_axis[a][name]


@dataclass(frozen=True)
class _Key:
    """A Kalibr key: its coefficient (name, symbol, unit), the conversion, the density's
    unit and how the comment says the conversion."""

    key: str
    name: str
    symbol: str
    unit: str
    convert: Callable[[float], float]
    density_unit: str
    how: str


GYRO_KEYS = (_Key("gyroscope_noise_density", "N_dpsh", "N", "deg/sqrt(h)", noise_density_rad, "rad/s/sqrt(Hz)",
                  "x pi/180 / 60"),
             _Key("gyroscope_random_walk", "K_dphsh", "K", "deg/h/sqrt(h)", random_walk_rad, "rad/s^2/sqrt(Hz)",
                  "x pi/180 / 216000"))
ACCEL_KEYS = (_Key("accelerometer_noise_density", "VRW_mpsph", "VRW", "m/s/sqrt(h)", accel_noise_density,
                   "m/s^2/sqrt(Hz)", "/ 60"),
              _Key("accelerometer_random_walk", "AccRW_mpshsh", "AccRW", "m/s/h/sqrt(h)", accel_random_walk,
                   "m/s^3/sqrt(Hz)", "/ 216000"))


def _key_value(k: _Key, by_axis: dict[str, dict[str, Term]], what: str = "axis") -> tuple[float | None, str]:
    """The exported value of key ``k`` (the largest of the axes) and its comment."""
    a, t = _largest(by_axis, k.name)
    value = None if t.value is None else k.convert(t.value)
    which = f" ({what} {a}, the largest of {', '.join(by_axis)})" if len(by_axis) > 1 else ""
    return value, f"{k.density_unit} = {k.symbol} {t.note(k.unit)} {k.how}{which}"


def _per_axis(by_axis: dict[str, dict[str, Term]], names: tuple[str, ...], what: str) -> list[str]:
    """Comment lines with each axis's coefficients ``names`` (several axes only)."""
    if len(by_axis) < 2:
        return []
    from fogmon.units import coefficient_unit
    out = []
    for a, t in by_axis.items():
        cells = [("n/i" if t[n].value is None else
                  f"{'< ' if t[n].upper else ''}{t[n].value:.6g}") + f" {coefficient_unit(n)}" for n in names]
        out.append(f"#   {what} {a}: " + ", ".join(f"{n} {c}" for n, c in zip(names, cells, strict=True)))
    return out


def _g(x: float | None) -> str:
    return "null" if x is None else repr(float(x))


def _header(source: str, sample_rate_hz: float | None) -> list[str]:
    return [f"# fogmon noise fit of {source}",
            f"# sample rate {sample_rate_hz:g} Hz" if sample_rate_hz else
            "# sample rate not stated by the source (a fitted curve): no IMU rate is written"]


def _topic_rate(topic: str | None, sample_rate_hz: float | None, quote: bool = False) -> list[str]:
    """``rostopic`` (a ROS source's topic; else a comment) and ``update_rate`` (the record's
    rate when known; else a comment): never a made-up value."""
    return [f"rostopic: {topic!r}" if quote and topic else f"rostopic: {topic}" if topic else
            "# rostopic: not a ROS recording: add the topic of the bag Kalibr reads",
            f"update_rate: {sample_rate_hz!r}   # Hz, the record's sample rate" if sample_rate_hz else
            "# update_rate: the record's sample rate is not known: add the IMU rate in Hz"]


def kalibr_yaml(fit: Gyros, source: str, sample_rate_hz: float | None, topic: str | None = None,
                accels: Mapping[str, object] | None = None) -> str:
    """Kalibr imu.yaml text: continuous-time gyroscope and accelerometer densities (what
    Kalibr, VINS and OpenVINS expect), of several axes the largest; Q, B and R have no
    Kalibr field and are stated in comments. ``fit``: the gyro fit, or axis -> fit (None:
    no gyro); ``accels``: accelerometer name -> AccelFit (fogmon.davar.accel)."""
    gyros, acc = _by_axis(fit), _by_axis(accels or None)
    lines = _header(source, sample_rate_hz) + [
        "# Kalibr imu.yaml: continuous-time noise densities (Kalibr discretizes them with update_rate:",
        "# sigma_d = noise_density * sqrt(update_rate), random-walk step = random_walk / sqrt(update_rate))",
        ""]
    lines += _kalibr_section("#Accelerometers", ACCEL_KEYS, acc, sample_rate_hz, "m/s^2", "accelerometer",
                             ("VRW_mpsph", "Bias_ug", "AccRW_mpshsh"))
    if acc:
        a, b = _largest(acc, "Bias_ug")
        lines.append("# no Kalibr field for: bias instability Bias " + b.note("ug") +
                     (f" = {accel_bias_instability(b.value):.6g} m/s^2" if b.value is not None else "") +
                     (f" (accelerometer {a})" if len(acc) > 1 else ""))
    lines.append("")
    lines += _kalibr_section("#Gyroscopes", GYRO_KEYS, gyros, sample_rate_hz, "rad/s", "axis",
                             ("N_dpsh", "B_dph", "K_dphsh"))
    if gyros:
        a, b = _largest(gyros, "B_dph")
        q, r = _largest(gyros, "Q_arcsec")[1], _largest(gyros, "R_dphh")[1]
        lines += ["# no Kalibr field for: bias instability B " + b.note("deg/h") +
                  (f" = {bias_instability_rad(b.value):.6g} rad/s" if b.value is not None else "") +
                  (f" (axis {a})" if len(gyros) > 1 else "") +
                  " (Kalibr models the bias as a pure random walk: B is not in its model)",
                  "#   " + q.q_label() + " " + q.note("arcsec") + ", rate ramp R " + r.note("deg/h^2")]
    return "\n".join([*lines, "", *_topic_rate(topic, sample_rate_hz)]) + "\n"


def _kalibr_section(title: str, keys: tuple[_Key, ...], by_axis: dict[str, dict[str, Term]],
                    sample_rate_hz: float | None, unit: str, what: str, names: tuple[str, ...]) -> list[str]:
    """One sensor's Kalibr keys (commented out, with the reason, when the record has none
    of it), each axis's values and the per-sample sigmas."""
    if not by_axis:
        none = ("none in this record (a gyro recording)" if what == "accelerometer" else
                "none in this curve (an accelerometer curve)")
        return [f"{title}: {none}; fill in before using this file with Kalibr",
                *(f"#{k.key}: " for k in keys)]
    lines = [title]
    values = []
    for k in keys:
        v, note = _key_value(k, by_axis, what)
        values.append(v)
        lines.append(f"{k.key}: {_g(v)}   # {note}")
    lines += _per_axis(by_axis, names, what)
    nd, rw = values
    if sample_rate_hz and nd is not None and rw is not None:
        lines.append(f"# per-sample (discrete) at {sample_rate_hz:g} Hz: "
                     f"white sigma {discrete_white(nd, sample_rate_hz):.6g} {unit}, "
                     f"bias step sigma {discrete_random_walk(rw, sample_rate_hz):.6g} {unit} (not what Kalibr reads)")
    return lines


def ros_yaml(fit: Gyros, source: str, sample_rate_hz: float | None, topic: str | None = None,
             accels: Mapping[str, object] | None = None) -> str:
    """allan_variance_ros-style output: its imu.yaml key layout (Kalibr's accelerometer
    and gyroscope keys, of several axes the largest as it takes them, rostopic,
    update_rate) and, as comments, the values its analysis prints per axis in its units
    (velocity random walk m/s/sqrt(s) and m/s/sqrt(hr), bias instability m/s^2 and
    m/hr^2, accel random walk m/s^2/sqrt(s); angle random walk deg/sqrt(s) and
    deg/sqrt(hr), bias instability deg/s and deg/hr, rate random walk deg/s/sqrt(s)).
    allan_variance_ros reads bias instability off the ADEV minimum, which is the flicker
    floor 0.664 B, not B: both are given."""
    gyros, acc = _by_axis(fit), _by_axis(accels or None)
    lines = _header(source, sample_rate_hz) + ["# allan_variance_ros-style imu.yaml"]
    for title, keys, by_axis in (("#Accelerometer", ACCEL_KEYS, acc), ("#Gyroscope", GYRO_KEYS, gyros)):
        if not by_axis:
            lines += [f"{title}: none in this {'record' if title == '#Accelerometer' else 'curve'}",
                      *(f"#{k.key}: " for k in keys), ""]
            continue
        lines.append(title)
        lines += [f"{k.key}: {_g(_key_value(k, by_axis)[0])} " for k in keys]
        lines.append("")
    lines += [*_topic_rate(topic, sample_rate_hz, quote=True), ""]
    if acc:
        lines.append("# ACCELEROMETER (allan_variance_ros's printed units):")
        for a, t in acc.items():
            lines += _ros_accel_lines(a.upper() + " " if len(acc) > 1 or a else "", t)
    if gyros:
        lines.append("# GYROSCOPE (allan_variance_ros's printed units):")
        for a, t in gyros.items():
            lines += _ros_gyro_lines(a.upper() + " " if a else "", t)
    return "\n".join(lines) + "\n"


def _upper(t: Term) -> str:
    return " (95 % upper limit)" if t.upper else ""


def _ros_gyro_lines(axis: str, t: dict[str, Term]) -> list[str]:
    n, b, k = t["N_dpsh"], t["B_dph"], t["K_dphsh"]
    lines = []
    if n.value is not None:
        lines.append(f"# {axis}Angle Random Walk: {n.value / 60.0:.6g} deg/sqrt(s) {n.value:.6g} deg/sqrt(hr)"
                     + _upper(n))
    if b.value is not None:
        floor = FLICKER_FLOOR * b.value
        lines.append(f"# {axis}Bias Instability: {b.value / 3600.0:.6g} deg/s {b.value:.6g} deg/hr (B; the ADEV floor "
                     f"allan_variance_ros reads is 0.664 B = {floor:.6g} deg/hr)" + _upper(b))
    if k.value is not None:
        lines.append(f"# {axis}Rate Random Walk: {k.value / 3600.0 / 60.0:.6g} deg/s/sqrt(s) {k.value:.6g} "
                     f"deg/hr/sqrt(hr)" + _upper(k))
    return lines


def _ros_accel_lines(axis: str, t: dict[str, Term]) -> list[str]:
    n, b, k = t["VRW_mpsph"], t["Bias_ug"], t["AccRW_mpshsh"]
    lines = []
    if n.value is not None:
        lines.append(f"# {axis}Velocity Random Walk: {n.value / 60.0:.6g} m/s/sqrt(s) {n.value:.6g} m/s/sqrt(hr)"
                     + _upper(n))
    if b.value is not None:
        ms2 = accel_bias_instability(b.value)
        lines.append(f"# {axis}Bias Instability: {ms2:.6g} m/s^2 {ms2 * 3600.0**2:.6g} m/hr^2 (Bias {b.value:.6g} ug; "
                     f"the ADEV floor allan_variance_ros reads is 0.664 Bias = {FLICKER_FLOOR * ms2:.6g} m/s^2)"
                     + _upper(b))
    if k.value is not None:
        lines.append(f"# {axis}Accel Random Walk: {accel_random_walk(k.value):.6g} m/s^2/sqrt(s) {k.value:.6g} "
                     f"m/s/hr/sqrt(hr)" + _upper(k))
    return lines


#: MATLAB parameters of gyroparams / accelparams: (parameter, coefficient, conversion, unit, formula)
_MATLAB = {
    "gyroparams": (("NoiseDensity", "N_dpsh", noise_density_rad, "(rad/s)/sqrt(Hz)", "N x pi/180/60", "deg/sqrt(h)"),
                   ("BiasInstability", "B_dph", bias_instability_rad, "rad/s", "B x pi/180/3600", "deg/h"),
                   ("RandomWalk", "K_dphsh", random_walk_rad, "(rad/s)*sqrt(Hz)", "K x pi/180/216000",
                    "deg/h/sqrt(h)")),
    "accelparams": (("NoiseDensity", "VRW_mpsph", accel_noise_density, "(m/s^2)/sqrt(Hz)", "VRW / 60", "m/s/sqrt(h)"),
                    ("BiasInstability", "Bias_ug", accel_bias_instability, "m/s^2", "Bias x 1e-6 x 9.80665", "ug"),
                    ("RandomWalk", "AccRW_mpshsh", accel_random_walk, "(m/s^2)*sqrt(Hz)", "AccRW / 216000",
                     "m/s/h/sqrt(h)")),
}


def matlab_snippet(fit: Gyros, source: str, sample_rate_hz: float | None, topic: str | None = None,
                   accels: Mapping[str, object] | None = None) -> str:
    """MATLAB ``gyroparams`` (and with accelerometers ``accelparams``) calls (Navigation /
    Sensor Fusion Toolbox units: NoiseDensity (rad/s)/sqrt(Hz) or (m/s^2)/sqrt(Hz),
    BiasInstability rad/s or m/s^2, RandomWalk (rad/s)*sqrt(Hz) or (m/s^2)*sqrt(Hz)); of
    several axes one value per axis ([x y z])."""
    lines = ["% " + s[2:] for s in _header(source, sample_rate_hz)]
    gyros, acc = _by_axis(fit), _by_axis(accels or None)
    if gyros:
        lines += _matlab_call("params", "gyroparams", gyros)
        q, r = _largest(gyros, "Q_arcsec")[1], _largest(gyros, "R_dphh")[1]
        lines.append(f"% not in gyroparams: {q.q_label()} {q.note('arcsec')}, rate ramp R {r.note('deg/h^2')}")
    if acc:
        lines += _matlab_call("accParams", "accelparams", acc)
    if sample_rate_hz:
        lines.append(f"% imuSensor('SampleRate', {sample_rate_hz!r}) discretizes these densities at the sample rate")
    return "\n".join(lines) + "\n"


def _matlab_call(var: str, fn: str, by_axis: dict[str, dict[str, Term]]) -> list[str]:
    """``var = fn(...)`` with the parameters every axis has a value for."""
    rows = []
    for key, name, convert, unit, how, coef_unit in _MATLAB[fn]:
        ts = [t[name] for t in by_axis.values()]
        if any(t.value is None for t in ts):
            continue
        vals = [convert(t.value) for t in ts]   # type: ignore[arg-type]
        text = repr(vals[0]) if len(vals) == 1 else "[" + " ".join(repr(v) for v in vals) + "]"
        notes = ts[0].note(coef_unit) if len(ts) == 1 else ", ".join(
            f"{a} {t.note(coef_unit)}" for a, t in zip(by_axis, ts, strict=True))
        rows.append((key, text, f"{unit} = {how}; {name.split('_')[0]}: {notes}" if len(ts) > 1 else
                     f"{unit} = {how.split(' ', 1)[0]} {notes} {how.split(' ', 1)[1]}"))
    if not rows:
        return [f"{var} = {fn}();   % no noise term could be fitted"]
    axes = f"   % axes {', '.join(by_axis)}" if len(by_axis) > 1 else ""
    out = [f"{var} = {fn}( ...{axes}"]
    for i, (key, v, why) in enumerate(rows):
        out.append(f"    '{key}', {v}{', ...' if i < len(rows) - 1 else ');'}   % {why}")
    return out


WRITERS = {"kalibr": kalibr_yaml, "ros": ros_yaml, "matlab": matlab_snippet}


def write_export(kind: str, path: str, fit: Gyros, source: str, sample_rate_hz: float | None,
                 topic: str | None = None, accels: Mapping[str, object] | None = None,
                 notes: Sequence[str] = ()) -> None:
    """Write ``fit`` (a whole-record NoiseFit, or axis name -> NoiseFit) and ``accels``
    (accelerometer name -> AccelFit) to ``path`` in format ``kind`` (FORMATS);
    ``sample_rate_hz`` None when the record's rate is not known, ``topic`` the ROS topic
    of a ROS source; ``notes``: what the reader of the file must know of the record (one
    comment line each, after the header: platform motion kept out); complete or not at
    all (a disk error is a FogmonError naming the file)."""
    if isinstance(fit, Mapping):
        fit = {a: f for a, f in fit.items() if f is not None} or None
    accels = {a: f for a, f in (accels or {}).items() if f is not None}
    if fit is None and not accels:
        raise FogmonError(f"`export` {kind} {path}: no noise fit to export (the record gave no Allan deviation)")
    text = WRITERS[kind](fit, source, sample_rate_hz, topic, accels)
    if notes:
        mark = "%" if kind == "matlab" else "#"
        parts = text.split("\n", 2)            # the header's two lines, then the rest
        text = "\n".join([*parts[:2], *(f"{mark} {n}" for n in notes), *parts[2:]])
    with written(path, f"`export` {kind}") as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)


def check_export(kind: str, path: str, inputs: Iterable[str | None] = ()) -> None:
    """FogmonError unless ``kind`` is one of FORMATS and ``path`` can be written (and is
    none of ``inputs``): checked before any work."""
    if kind not in FORMATS:
        raise FogmonError(f"`export` {kind}: unknown format (one of {', '.join(FORMATS)})")
    check_outputs({f"`export` {kind}": path}, inputs)
