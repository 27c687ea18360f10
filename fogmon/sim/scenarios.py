"""Aux-channel generators for simulating without a recording: an MWD run, a thermal
chamber cycle and a spacecraft orbit. Each returns a ``Scenario`` (times in s, aux
channels by their replay-log names (docs/formats.md): ``temp_c`` deg C, ``rot_dps`` deg/s, ``vib_g`` g rms,
``depth_m`` m, plus scenario-specific columns) sampled at its own ``sample_rate_hz``; the
simulator interpolates them onto the gyro's sample times.

Every default is documented on its parameter class (industry ranges, docs/sim.md) and
overridable: ``mwd_run(MwdParams(rop_mph=10))`` or ``scenario_params("mwd", {"rop_mph": "10"})``.

Several axes: the parameter ``axes`` ("xyz": one axis per character) makes a scenario
for a multi-axis gyro: ``Scenario.axes`` names them, channels every axis shares stay
plain (temp_c, vib_g: one cause for every axis) and those that differ by axis become
``<ch>_<axis>`` (the rotation each sensing axis sees: ``rot_dps_z``).
"""
from __future__ import annotations

import difflib
import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np

from fogmon.errors import FogmonError


@dataclass
class Scenario:
    """Aux channels ``aux`` at times ``t_s`` (s), facts for the metadata (``meta``,
    e.g. connection times an analyst may want to mark), and the ``axes`` of a
    multi-axis scenario (() for one axis)."""

    t_s: np.ndarray
    aux: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    axes: tuple[str, ...] = ()


def _per_axis(name: str, values: list[np.ndarray], axes: str) -> dict[str, np.ndarray]:
    """Channel ``name`` of each axis as ``<name>_<axis>`` (``values`` in the order of ``axes``)."""
    return {f"{name}_{a}": v for a, v in zip(axes, values, strict=True)}


def _lags(target: np.ndarray, dt_s: float, lags_s, start: float) -> np.ndarray:
    """Cascade of first-order lags (time constants lags_s, s) driven by ``target``,
    exact exponential update per step; dT/dt and d2T/dt2 stay continuous for two lags."""
    from scipy.signal import lfilter

    x = np.asarray(target, dtype=float)
    for tau in lags_s:
        a = math.exp(-dt_s / tau)
        x, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * start])
    return x


@dataclass
class MwdParams:
    """Measurement-while-drilling run (docs/sim.md): stands drilled at ``rop_mph`` with
    pumps on and the string rotating, connections with pumps off (the tool warms toward
    the static formation temperature), an optional trip out at the end."""

    duration_s: float = 4 * 3600.0        #: s, run length (including the trip)
    sample_rate_hz: float = 10.0                 #: Hz, aux sampling rate
    start_depth_m: float = 3000.0         #: m, bit depth at the start
    stand_length_m: float = 28.5          #: m per stand (27-30 m)
    rop_mph: float = 30.0                 #: m/h, rate of penetration (5-60 m/h)
    connection_s: float = 600.0           #: s per connection, pumps off (5-15 min)
    surface_temp_c: float = 20.0          #: deg C at surface
    gradient_c_per_100m: float = 3.0      #: deg C per 100 m, geothermal gradient
    circulation_cooling_c: float = 30.0   #: deg C below static while mud circulates (25-50)
    lag1_s: float = 120.0                 #: s, first tool thermal lag (~2 min)
    lag2_s: float = 600.0                 #: s, second tool thermal lag (~10 min)
    rpm: float = 120.0                    #: rev/min, surface string speed (40-200)
    stick_slip: bool = False              #: bit speed oscillates between 0 and ratio x rpm
    stick_slip_hz: float = 0.3            #: Hz, stick-slip frequency (0.1-2)
    stick_slip_ratio: float = 2.5         #: peak bit speed / surface rpm (2-3)
    vib_drilling_g: float = 3.0           #: g rms while drilling (1-10)
    vib_static_g: float = 0.02            #: g rms pumps off, no rotation (< 0.05)
    vib_trip_g: float = 0.3               #: g rms while tripping
    vib_spread: float = 0.3               #: relative (log-normal) fluctuation of vibration, 10 s correlation
    trip_s: float = 0.0                   #: s, trip out at the end of the run (0: none)
    trip_speed_mph: float = 300.0         #: m/h, tripping speed
    axes: str = ""                        #: several gyros, one axis per character ("xyz"); "": one
    spin_axis: str = "z"                  #: with axes: the one along the tool (the others see no rotation)


@dataclass
class ChamberParams:
    """Thermal-chamber cycle: plateaus joined by ramps at ``ramp_c_per_min``; the sensor
    follows the chamber air through two lags."""

    plateaus_c: tuple = (20.0, -40.0, 60.0, 20.0)  #: deg C, plateau temperatures in order
    dwell_s: float = 1800.0               #: s at each plateau
    ramp_c_per_min: float = 1.0           #: deg C/min between plateaus
    lag1_s: float = 60.0                  #: s, air-to-case lag
    lag2_s: float = 300.0                 #: s, case-to-coil lag
    sample_rate_hz: float = 1.0                  #: Hz, aux sampling rate
    axes: str = ""                        #: several gyros, one axis per character ("xyz"); "": one


@dataclass
class OrbitParams:
    """Low Earth orbit: sunlit/eclipse heating through a thermal lag, and the orbital
    pitch rate of a nadir-pointing spacecraft seen by the gyro axis."""

    duration_s: float = 6 * 5580.0        #: s, run length (6 orbits)
    period_s: float = 5580.0              #: s, orbital period
    eclipse_fraction: float = 0.36        #: fraction of each orbit in Earth's shadow
    temp_mean_c: float = 20.0             #: deg C, mean sensor temperature
    temp_swing_c: float = 4.0             #: deg C, sunlit minus eclipse equilibrium
    lag_s: float = 900.0                  #: s, sensor thermal lag
    axis_factor: float = 1.0              #: one axis: cosine of its sensing axis to the orbit normal
    sample_rate_hz: float = 1.0                  #: Hz, aux sampling rate
    axes: str = ""                        #: several gyros, one axis per character ("xyz"); "": one
    axis_factors: tuple = (0.0, 1.0, 0.0)  #: with axes: each axis's cosine to the orbit normal, in axes order


def mwd_run(p: MwdParams | None = None, seed: int | None = None) -> Scenario:
    """MWD aux channels: temp_c, rot_dps (string or bit speed, 1 rpm = 6 deg/s),
    vib_g, depth_m, pumps (1 on / 0 off); meta lists connection start times. With
    ``axes``: rot_dps_<axis>, the string speed on ``spin_axis`` and 0 on the others;
    temperature and vibration shared."""
    p = MwdParams() if p is None else p
    dt = 1.0 / p.sample_rate_hz
    n = int(round(p.duration_s * p.sample_rate_hz))
    t = np.arange(n) * dt
    stand_s = p.stand_length_m / p.rop_mph * 3600.0
    cycle = stand_s + p.connection_s
    drill_end = max(p.duration_s - p.trip_s, 0.0)
    phase = np.mod(t, cycle)
    drilling = (phase < stand_s) & (t < drill_end)
    tripping = t >= drill_end
    n_done = np.floor(t / cycle)
    depth_drill = p.start_depth_m + p.rop_mph / 3600.0 * (n_done * stand_s + np.minimum(phase, stand_s))
    depth_end = p.start_depth_m + p.rop_mph / 3600.0 * (
        np.floor(drill_end / cycle) * stand_s + min(np.mod(drill_end, cycle), stand_s))
    depth = np.where(tripping, depth_end - p.trip_speed_mph / 3600.0 * (t - drill_end), depth_drill)
    depth = np.maximum(depth, 0.0)
    static = p.surface_temp_c + p.gradient_c_per_100m * depth / 100.0
    target = np.where(drilling, static - p.circulation_cooling_c, static)
    temp = _lags(target, dt, (p.lag1_s, p.lag2_s), float(target[0]) if n else 0.0)
    rpm = np.where(drilling, p.rpm, 0.0)
    if p.stick_slip:
        rpm = np.maximum(rpm * (1.0 + (p.stick_slip_ratio - 1.0) * np.sin(2 * np.pi * p.stick_slip_hz * t)), 0.0)
    rng = np.random.default_rng(seed)
    a = math.exp(-dt / 10.0)
    wobble = _lags(rng.standard_normal(n) * math.sqrt((1 + a) / (1 - a)), dt, (10.0,), 0.0)
    level = np.where(drilling, p.vib_drilling_g, np.where(tripping, p.vib_trip_g, p.vib_static_g))
    vib = level * np.exp(p.vib_spread * wobble - 0.5 * p.vib_spread ** 2)
    conns = [f"{c:g}" for c in np.arange(stand_s, drill_end, cycle)]
    rot = {"rot_dps": 6.0 * rpm} if not p.axes else _per_axis(
        "rot_dps", [6.0 * rpm if a == p.spin_axis else np.zeros(n) for a in p.axes], p.axes)
    return Scenario(t, {"temp_c": temp, **rot, "vib_g": vib, "depth_m": depth, "pumps": drilling.astype(float)},
                    {"scenario": "mwd", "connections_s": " ".join(conns)}, tuple(p.axes))


def thermal_chamber(p: ChamberParams | None = None, seed: int | None = None) -> Scenario:
    """Chamber cycle aux channels: temp_c (sensor), chamber_c (air), rot_dps = 0; the
    same for every axis of ``axes``."""
    p = ChamberParams() if p is None else p
    pts_t, pts_c = [0.0], [float(p.plateaus_c[0])]
    for c in p.plateaus_c[1:]:
        pts_t.append(pts_t[-1] + p.dwell_s)
        pts_c.append(pts_c[-1])
        pts_t.append(pts_t[-1] + abs(c - pts_c[-1]) / p.ramp_c_per_min * 60.0)
        pts_c.append(float(c))
    pts_t.append(pts_t[-1] + p.dwell_s)
    pts_c.append(pts_c[-1])
    dt = 1.0 / p.sample_rate_hz
    t = np.arange(int(round(pts_t[-1] * p.sample_rate_hz))) * dt
    air = np.interp(t, pts_t, pts_c)
    temp = _lags(air, dt, (p.lag1_s, p.lag2_s), pts_c[0])
    return Scenario(t, {"temp_c": temp, "chamber_c": air, "rot_dps": np.zeros(len(t))},
                    {"scenario": "chamber", "plateaus_c": " ".join(f"{c:g}" for c in p.plateaus_c)}, tuple(p.axes))


def orbit(p: OrbitParams | None = None, seed: int | None = None) -> Scenario:
    """Orbit aux channels: temp_c (sunlit/eclipse through a lag), rot_dps (orbital rate
    360/period deg/s times axis_factor). With ``axes`` (a three-axis unit, as in the
    in-orbit evaluation): rot_dps_<axis>, the orbital rate times that axis's entry of
    ``axis_factors``; one temperature for every axis."""
    p = OrbitParams() if p is None else p
    dt = 1.0 / p.sample_rate_hz
    t = np.arange(int(round(p.duration_s * p.sample_rate_hz))) * dt
    eclipse = np.mod(t, p.period_s) >= (1.0 - p.eclipse_fraction) * p.period_s
    sun = p.temp_mean_c + p.temp_swing_c * (np.where(eclipse, 0.0, 1.0) - (1.0 - p.eclipse_fraction))
    temp = _lags(sun, dt, (p.lag_s,), p.temp_mean_c)
    orbital_dps = 360.0 / p.period_s
    rot = {"rot_dps": np.full(len(t), orbital_dps * p.axis_factor)} if not p.axes else _per_axis(
        "rot_dps", [np.full(len(t), orbital_dps * c) for c in p.axis_factors], p.axes)
    return Scenario(t, {"temp_c": temp, **rot}, {"scenario": "orbit", "period_s": f"{p.period_s:g}"}, tuple(p.axes))


#: name -> (generator, parameter class)
SCENARIOS: dict[str, tuple[Callable[..., Scenario], type]] = {
    "mwd": (mwd_run, MwdParams), "chamber": (thermal_chamber, ChamberParams), "orbit": (orbit, OrbitParams)}


def _parse_value(name: str, key: str, text: str, default):
    """The text value of parameter ``key`` of scenario ``name``, of the type of its
    ``default`` (bool, tuple of floats, float: finite; str: axis names, one per
    character, letters and digits, none twice); a one-line FogmonError if not."""
    try:
        if isinstance(default, str):
            if not (text.isascii() and text.isalnum() and len(set(text)) == len(text)):
                raise ValueError
            return text
        if isinstance(default, bool):
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return text.lower() in ("true", "1", "yes")
        if isinstance(default, tuple):
            values = tuple(float(x) for x in text.replace(";", ",").split(",") if x.strip())
            if len(values) < 1 or not all(math.isfinite(x) for x in values):
                raise ValueError
            return values
        v = float(text)
        if not math.isfinite(v):
            raise ValueError
        return v
    except ValueError:
        raise FogmonError(f"scenario {name}: parameter {key}: bad value {text!r}") from None


def scenario_params(name: str, overrides: dict[str, str], duration_s: float | None = None):
    """Parameter object of scenario ``name`` with ``overrides`` (key -> text value)
    applied and, when given, ``duration_s``; unknown keys or bad values are one-line
    FogmonErrors."""
    if name not in SCENARIOS:
        raise FogmonError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    cls = SCENARIOS[name][1]
    params = cls()
    known = {f.name: f for f in fields(cls)}
    values = {}
    for k, text in overrides.items():
        if k not in known:
            m = difflib.get_close_matches(k, known, n=1)
            raise FogmonError(f"scenario {name}: unknown parameter {k!r} (known: {', '.join(known)})"
                              + (f"; did you mean {m[0]!r}?" if m else ""))
        v = _parse_value(name, k, text, getattr(params, k))
        if isinstance(v, float) and v < 0 and not k.endswith("_c"):
            raise FogmonError(f"scenario {name}: parameter {k} must be >= 0, got {text}")
        values[k] = v
    if duration_s is not None:
        if "duration_s" not in known:
            raise FogmonError(f"scenario {name}: the duration follows from its profile; "
                              "change dwell_s/plateaus_c instead of `duration_s`")
        values["duration_s"] = float(duration_s)
    params = replace(params, **values)
    for k in ("sample_rate_hz", "lag1_s", "lag2_s", "lag_s", "period_s", "rop_mph", "stand_length_m", "ramp_c_per_min"):
        if k in known and getattr(params, k) <= 0:
            raise FogmonError(f"scenario {name}: parameter {k} must be > 0")
    _check_axes(name, params)
    if "duration_s" in known and params.duration_s * params.sample_rate_hz < 2:
        raise FogmonError(f"scenario {name}: duration_s {params.duration_s:g} s holds fewer than 2 samples at "
                          f"sample_rate_hz {params.sample_rate_hz:g} Hz")
    return params


def _check_axes(name: str, p) -> None:
    """The per-axis parameters must fit ``axes``."""
    if not p.axes:
        return
    if getattr(p, "spin_axis", p.axes[0]) not in p.axes:
        raise FogmonError(f"scenario {name}: spin_axis {p.spin_axis!r} is not one of axes {p.axes!r}")
    if len(getattr(p, "axis_factors", p.axes)) != len(p.axes):
        raise FogmonError(f"scenario {name}: axis_factors needs one cosine per axis of {p.axes!r}, "
                          f"got {len(p.axis_factors)}")


def make_scenario(name: str, overrides: dict[str, str] | None = None, duration_s: float | None = None,
                  seed: int | None = None) -> Scenario:
    """Generate scenario ``name`` ("mwd", "chamber", "orbit") with text overrides."""
    params = scenario_params(name, overrides or {}, duration_s)
    return SCENARIOS[name][0](params, seed)
