"""Fitted IEEE-952 noise parameters in other tools' formats and units (``export``):
Kalibr imu.yaml, allan_variance_ros's imu.yaml with its console values, and a MATLAB
``gyroparams`` snippet. The one place that knows these unit conversions (docs/exports.md
has the table and the discrete-time pitfalls).

Continuous-time densities from the IEEE-952 coefficients (rad = deg x pi/180):
  noise density   [rad/s/sqrt(Hz)]   = N [deg/sqrt(h)] x pi/180 / 60
  random walk     [rad/s^2/sqrt(Hz)] = K [deg/h/sqrt(h)] x pi/180 / 3600 / 60
  bias instability [rad/s]           = B [deg/h] x pi/180 / 3600
Per-sample (discrete) sigmas at rate f (Hz): white noise density x sqrt(f), random walk
/ sqrt(f). A term the record cannot identify is exported as its 95 % upper limit (a
filter tuned with it is conservative, not overconfident), and the file says so."""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from fogmon.davar.fit import NAMES
from fogmon.errors import FogmonError
from fogmon.outputs import check_outputs, written

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

    @staticmethod
    def of(c) -> Term:
        """From a fogmon.davar.fit.Coefficient."""
        if bool(c.identifiable):
            return Term(float(c.value), False)
        up = float(c.upper)
        return Term(up if math.isfinite(up) else None, True)

    def note(self, unit: str) -> str:
        if self.value is None:
            return "not identifiable from this record, no upper limit either"
        return f"{self.value:.6g} {unit}" + (" (95 % upper limit: not identifiable from this record)"
                                            if self.upper else "")


def terms(fit) -> dict[str, Term]:
    """Q, N, B, K, R as exported Terms, of a whole-record NoiseFit (fogmon.davar.fit) or
    of a sensor model's noise (fogmon.sim.model.Noise: the values as they stand)."""
    if hasattr(fit, "coefficients"):
        return {name: Term.of(c) for name, c in fit.coefficients().items()}
    return {name: Term(float(getattr(fit, name)), False) for name in NAMES}


def _g(x: float | None) -> str:
    return "null" if x is None else repr(float(x))


def _header(source: str, sample_rate_hz: float | None) -> list[str]:
    return [f"# fogmon IEEE-952 fit of {source}",
            f"# sample rate {sample_rate_hz:g} Hz" if sample_rate_hz else "# sample rate unknown (a fitted curve)"]


def kalibr_yaml(fit, source: str, sample_rate_hz: float | None, topic: str | None = None) -> str:
    """Kalibr imu.yaml text: continuous-time gyroscope densities (what Kalibr, VINS and
    OpenVINS expect); Q, B and R have no Kalibr field and are stated in comments; the
    accelerometer fields are left for the user (a gyro recording cannot give them)."""
    t = terms(fit)
    nd = None if t["N_dpsh"].value is None else noise_density_rad(t["N_dpsh"].value)
    rw = None if t["K_dphsh"].value is None else random_walk_rad(t["K_dphsh"].value)
    lines = _header(source, sample_rate_hz) + [
        "# Kalibr imu.yaml: continuous-time noise densities (Kalibr discretizes them with update_rate:",
        "# sigma_d = noise_density * sqrt(update_rate), random-walk step = random_walk / sqrt(update_rate))",
        "",
        "#Accelerometers: not measured by fogmon (a gyro recording); fill in before using this file with Kalibr",
        "#accelerometer_noise_density: ",
        "#accelerometer_random_walk: ",
        "",
        "#Gyroscopes",
        f"gyroscope_noise_density: {_g(nd)}   # rad/s/sqrt(Hz) = N {t['N_dpsh'].note('deg/sqrt(h)')} x pi/180 / 60",
        f"gyroscope_random_walk: {_g(rw)}   # rad/s^2/sqrt(Hz) = K {t['K_dphsh'].note('deg/h/sqrt(h)')} "
        "x pi/180 / 216000",
        "# no Kalibr field for: bias instability B " + t["B_dph"].note("deg/h") +
        (f" = {bias_instability_rad(t['B_dph'].value):.6g} rad/s" if t["B_dph"].value is not None else "") +
        " (Kalibr models the bias as a pure random walk: B is not in its model)",
        "#   quantization Q " + t["Q_arcsec"].note("arcsec") + ", rate ramp R " + t["R_dphh"].note("deg/h^2"),
    ]
    if sample_rate_hz and nd is not None and rw is not None:
        lines.append(
            f"# per-sample (discrete) at {sample_rate_hz:g} Hz: "
            f"white sigma {discrete_white(nd, sample_rate_hz):.6g} rad/s, "
            f"bias step sigma {discrete_random_walk(rw, sample_rate_hz):.6g} rad/s (not what Kalibr reads)"
        )
    lines += ["", f"rostopic: {topic or '/imu0'}" + ("" if topic else "   # the IMU topic: make sure this is correct"),
              f"update_rate: {_g(sample_rate_hz)}   # Hz" + ("" if sample_rate_hz else ": the IMU rate, fill in")]
    return "\n".join(lines) + "\n"


def ros_yaml(fit, source: str, sample_rate_hz: float | None, topic: str | None = None) -> str:
    """allan_variance_ros-style output: its imu.yaml key layout (Kalibr's gyroscope keys,
    rostopic, update_rate) and, as comments, the values its analysis prints (angle random
    walk deg/sqrt(s) and deg/sqrt(hr), bias instability deg/s and deg/hr, rate random walk
    deg/s/sqrt(s)). allan_variance_ros reads bias instability off the ADEV minimum, which
    is the flicker floor 0.664 B, not B: both are given."""
    t = terms(fit)
    n, b, k = t["N_dpsh"], t["B_dph"], t["K_dphsh"]
    nd = None if n.value is None else noise_density_rad(n.value)
    rw = None if k.value is None else random_walk_rad(k.value)
    lines = _header(source, sample_rate_hz) + [
        "# allan_variance_ros-style imu.yaml (gyroscope only: fogmon reads one gyro axis)",
        "#Gyroscope",
        f"gyroscope_noise_density: {_g(nd)} ",
        f"gyroscope_random_walk: {_g(rw)} ",
        "",
        f"rostopic: {topic or '/sensors/imu'!r}" + ("" if topic else " #Make sure this is correct"),
        f"update_rate: {_g(sample_rate_hz)}" + ("" if sample_rate_hz else " #Make sure this is correct"),
        "",
        "# GYROSCOPE (allan_variance_ros's printed units):",
    ]
    if n.value is not None:
        lines.append(f"# Angle Random Walk: {n.value / 60.0:.6g} deg/sqrt(s) {n.value:.6g} deg/sqrt(hr)"
                     + (" (95 % upper limit)" if n.upper else ""))
    if b.value is not None:
        floor = FLICKER_FLOOR * b.value
        lines.append(f"# Bias Instability: {b.value / 3600.0:.6g} deg/s {b.value:.6g} deg/hr (B; the ADEV floor "
                     f"allan_variance_ros reads is 0.664 B = {floor:.6g} deg/hr)"
                     + (" (95 % upper limit)" if b.upper else ""))
    if k.value is not None:
        lines.append(f"# Rate Random Walk: {k.value / 3600.0 / 60.0:.6g} deg/s/sqrt(s) {k.value:.6g} deg/hr/sqrt(hr)"
                     + (" (95 % upper limit)" if k.upper else ""))
    return "\n".join(lines) + "\n"


def matlab_snippet(fit, source: str, sample_rate_hz: float | None, topic: str | None = None) -> str:
    """A MATLAB ``gyroparams`` call (Navigation / Sensor Fusion Toolbox units: NoiseDensity
    (rad/s)/sqrt(Hz), BiasInstability rad/s, RandomWalk (rad/s)*sqrt(Hz))."""
    t = terms(fit)
    n, b, k = t["N_dpsh"], t["B_dph"], t["K_dphsh"]
    rows = []
    if n.value is not None:
        rows.append(("NoiseDensity", noise_density_rad(n.value),
                     f"(rad/s)/sqrt(Hz) = N {n.note('deg/sqrt(h)')} x pi/180/60"))
    if b.value is not None:
        rows.append(("BiasInstability", bias_instability_rad(b.value), f"rad/s = B {b.note('deg/h')} x pi/180/3600"))
    if k.value is not None:
        rows.append(("RandomWalk", random_walk_rad(k.value),
                     f"(rad/s)*sqrt(Hz) = K {k.note('deg/h/sqrt(h)')} x pi/180/216000"))
    lines = ["% " + s[2:] for s in _header(source, sample_rate_hz)]
    lines.append("params = gyroparams( ...")
    for i, (key, v, why) in enumerate(rows):
        lines.append(f"    '{key}', {v!r}{', ...' if i < len(rows) - 1 else ');'}   % {why}")
    if not rows:
        lines[-1] = "params = gyroparams();   % no noise term could be fitted"
    lines.append(f"% not in gyroparams: quantization Q {t['Q_arcsec'].note('arcsec')}, rate ramp R "
                 f"{t['R_dphh'].note('deg/h^2')}")
    if sample_rate_hz:
        lines.append(f"% imuSensor('SampleRate', {sample_rate_hz!r}) discretizes these densities at the sample rate")
    return "\n".join(lines) + "\n"


WRITERS = {"kalibr": kalibr_yaml, "ros": ros_yaml, "matlab": matlab_snippet}


def write_export(
    kind: str, path: str, fit, source: str, sample_rate_hz: float | None, topic: str | None = None
) -> None:
    """Write ``fit`` (a whole-record NoiseFit) to ``path`` in format ``kind`` (FORMATS):
    complete or not at all (a disk error is a FogmonError naming the file)."""
    if fit is None:
        raise FogmonError(f"`export` {kind} {path}: no noise fit to export (the record gave no Allan deviation)")
    text = WRITERS[kind](fit, source, sample_rate_hz, topic)
    with written(path, f"`export` {kind}") as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)


def check_export(kind: str, path: str, inputs: Iterable[str | None] = ()) -> None:
    """FogmonError unless ``kind`` is one of FORMATS and ``path`` can be written (and is
    none of ``inputs``): checked before any work."""
    if kind not in FORMATS:
        raise FogmonError(f"`export` {kind}: unknown format (one of {', '.join(FORMATS)})")
    check_outputs({f"`export` {kind}": path}, inputs)
