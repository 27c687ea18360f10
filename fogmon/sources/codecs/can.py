"""The CAN/DBC codec: CAN frames of a gyro described in a DBC file (cantools) -> Frames
in deg/h. The live bus (fogmon.sources.devices.can_bus) and CAN logs
(fogmon.sources.files.can_log) decode with it.

The user describes the gyro's frame in a DBC file; options name the message and the
signals for rate, temperature, counter and validity (defaults: the signals called
``rate``, ``temperature``, ``counter``, ``valid``; see fogmon/data/gyro_example.dbc).
The rate signal's DBC unit (deg/h, deg/s, rad/s, or deg, rad, arcsec per sample) sets
the conversion to deg/h. Lost frames are found from the rolling counter (its wrap is
2**bit length) and from the frames' timestamps (a silence longer than half a counter
wrap, or 0.5 s without a counter, is an outage whose length the timestamps give).
Rates beyond ``max_rate_dph`` (default the generic gate of fogmon.sources.plausibility,
10,000 deg/s) make the sample invalid, counted as ``implausible_samples``.

Several axes (``can_rate`` ``x=GyroX,y=GyroY,z=GyroZ``, one signal per axis, possibly in
different messages): the message carrying the first axis's signal is the sample clock.
Each of its frames is one sample, placed on the grid by its counter and timestamps as
for one axis; its temperature, counter and valid signals serve every axis. An axis whose
signal is in another message takes the latest frame of that message received since the
previous clock frame. Failure modes: no such frame in that period (lost, or late) makes
that axis invalid for that sample, counted per axis (``axis_frames_missing_<axis>``);
more than one (a clock frame lost, or the message sent faster than the clock) keeps the
latest and counts the others (``axis_frames_superseded``); a message sent just after the
clock message of its period joins the next sample, a fixed lag of one sample period
(pick as clock, by naming its axis first, the message sent last in each period).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from fogmon import units
from fogmon.errors import FogmonError
from fogmon.sources import plausibility
from fogmon.sources.frames import Frames
from fogmon.sources.grid import check_sample_rate

STALL_S = 0.5


def load_dbc(path: str):
    """A cantools database from a DBC file, or a one-line FogmonError."""
    import cantools
    try:
        return cantools.database.load_file(path, database_format="dbc")
    except FileNotFoundError:
        raise FogmonError(f"`dbc` {path}: no such file") from None
    except Exception as e:  # cantools raises several parser error types
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FogmonError(f"`dbc` {path}: not a valid DBC file: {msg}") from None


def _find_message(db, message: str | None, rate_signal: str):
    """The DBC message named ``message``, or the one message carrying ``rate_signal``."""
    if message:
        try:
            return db.get_message_by_name(message)
        except KeyError:
            raise FogmonError(f"`can_message` {message!r} is not in the DBC (it has: "
                              f"{', '.join(m.name for m in db.messages)})") from None
    having = [m for m in db.messages if any(s.name == rate_signal for s in m.signals)]
    if len(having) != 1:
        raise FogmonError(f"`can_rate` {rate_signal!r}: {'no' if not having else len(having)} DBC "
                          f"messages carry it; name the signal with `can_rate` and the message with "
                          f"`can_message`")
    return having[0]


def _pick(msg, opt: str, given: str | None, default: str) -> str | None:
    """The signal ``given`` for option ``opt`` (a SourceOptions field; it must exist), else
    ``default`` if the message has it."""
    names = [s.name for s in msg.signals]
    if given is None:
        return default if default in names else None
    if given not in names:
        raise FogmonError(f"`{opt}` {given!r}: message {msg.name} has no such signal (it has: {', '.join(names)})")
    return given


def parse_rate_signals(spec: str) -> list[tuple[str, str]]:
    """``can_rate``: ``SIGNAL`` -> [("", SIGNAL)] (one axis), ``x=GyroX,y=GyroY`` ->
    [("x", "GyroX"), ("y", "GyroY")]. A FogmonError names a bad item."""
    if "=" not in spec:
        return [("", spec)]
    out: list[tuple[str, str]] = []
    for item in spec.split(","):
        axis, _, signal = (p.strip() for p in item.partition("="))
        if not (axis.isascii() and axis.isalnum()) or not signal or any(a == axis for a, _ in out):
            raise FogmonError(f"`can_rate` {spec!r}: write AXIS=SIGNAL,... with distinct axis names "
                              f"(letters/digits), got {item!r}")
        out.append((axis, signal))
    return out


def _rate_hz(msg, sample_rate_hz: float | None) -> float:
    """The sample rate (Hz): given, or from the message's DBC cycle time."""
    if sample_rate_hz is None:
        if not msg.cycle_time:
            raise FogmonError(f"DBC message {msg.name} has no GenMsgCycleTime: give `sample_rate_hz`")
        sample_rate_hz = 1000.0 / msg.cycle_time
    return check_sample_rate(sample_rate_hz)


def _rate_units(signals: list[tuple[str, Any]], rate_unit: str | None) -> list[str]:
    """The fogmon.units unit of each (signal, message) of ``signals``: ``rate_unit`` or
    the signal's DBC unit."""
    keys = []
    for sig, m in signals:
        unit = rate_unit or m.get_signal_by_name(sig).unit or ""
        key = units.canonical(unit)
        if key is None:
            raise FogmonError(f"rate signal {m.name}.{sig} has unit {unit!r}: give `can_rate_unit` "
                              f"(one of {', '.join(units.DPH_PER_UNIT)})")
        keys.append(key)
    return keys


class CanDecoder:
    """CAN frames -> Frames for one DBC message (the sample clock; with several axes also
    the messages of the other axes' signals, see the module doc). Counters: ``frames_ok``,
    ``bad_frames`` (the message's id but undecodable, e.g. wrong length), ``other_frames``
    (other ids, ignored), ``implausible_samples`` (frames flagged valid whose rate is NaN,
    inf or beyond ``max_rate_dph`` deg/h, None = plausibility.GENERIC_MAX_ABS_DPH: made
    invalid); with axes in other messages ``axis_frames_missing_<axis>`` and
    ``axis_frames_superseded``. ``axes``: () for one rate signal."""

    def __init__(self, db, message: str | None = None, rate_signal: str | None = None, rate_unit: str | None = None,
                 temp_signal: str | None = None, counter_signal: str | None = None,
                 valid_signal: str | None = None, sample_rate_hz: float | None = None,
                 max_rate_dph: float | None = None) -> None:
        rate_signal = rate_signal or "rate"
        signals = parse_rate_signals(rate_signal)
        msg = _find_message(db, message, signals[0][1])
        names = {s.name: s for s in msg.signals}
        if signals[0][1] not in names:
            raise FogmonError(f"`can_rate` {signals[0][1]!r}: message {msg.name} has no such signal "
                              f"(it has: {', '.join(names)})")
        self.message = msg
        self.rate_signal = rate_signal
        self.axes = tuple(a for a, _ in signals) if len(signals) > 1 else ()
        #: per axis: (signal, its message: the clock message or another)
        self._signals = [(sig, msg if sig in names else _find_message(db, None, sig)) for _, sig in signals]
        self.temp_signal = _pick(msg, "can_temp", temp_signal, "temperature")
        self.counter_signal = _pick(msg, "can_counter", counter_signal, "counter")
        self.valid_signal = _pick(msg, "can_valid", valid_signal, "valid")
        self.sample_rate_hz = _rate_hz(msg, sample_rate_hz)
        self.max_rate_dph = plausibility.max_rate_dph(max_rate_dph, plausibility.GENERIC_MAX_ABS_DPH)
        keys = _rate_units(self._signals, rate_unit)
        #: the rate unit: given (``can_rate_unit``, every axis) or the first signal's DBC unit
        self.rate_unit = rate_unit or self._signals[0][1].get_signal_by_name(self._signals[0][0]).unit
        self._rate_unit_given = rate_unit
        self._scale = np.array([units.dph_scale(k, self.sample_rate_hz) for k in keys])
        #: other messages' frame ids -> (message, the axes (indices) it carries)
        self._side: dict[int, tuple[Any, list[int]]] = {}
        for j, (_, m) in enumerate(self._signals):
            if m is not msg:
                self._side.setdefault(m.frame_id, (m, []))[1].append(j)
        self._latest: dict[int, float] = {}    # axis index -> the other message's value awaiting a clock frame
        self.seq_modulus = 2 ** names[self.counter_signal].length if self.counter_signal else None
        self.aux_names = ("temp_c",) if self.temp_signal else ()
        self.counters = {"frames_ok": 0, "bad_frames": 0, "other_frames": 0, plausibility.COUNTER: 0}
        if self._side:
            self.counters.update({f"axis_frames_missing_{self.axes[j]}": 0
                                  for _, js in self._side.values() for j in js})
            self.counters["axis_frames_superseded"] = 0
        self._stall_s = min(STALL_S, 0.5 * self.seq_modulus / self.sample_rate_hz) if self.seq_modulus else STALL_S
        self._last_ts: float | None = None

    def options(self) -> dict:
        return {
            "message": self.message.name,
            "rate_signal": self.rate_signal,
            "rate_unit": self._rate_unit_given if self.axes else self.rate_unit,  # several axes: each its DBC unit
            "temp_signal": self.temp_signal,
            "counter_signal": self.counter_signal,
            "valid_signal": self.valid_signal,
            "sample_rate_hz": self.sample_rate_hz,
            "max_rate_dph": self.max_rate_dph,
        }

    def describe(self) -> str:
        if not self.axes:
            return f"CAN {self.message.name}.{self.rate_signal} ({self.rate_unit}), {self.sample_rate_hz:g} Hz"
        sigs = ", ".join(f"{a}={m.name}.{s}" for a, (s, m) in zip(self.axes, self._signals, strict=True))
        return f"CAN axes {sigs} (clock {self.message.name}), {self.sample_rate_hz:g} Hz"

    def feed(self, msgs: Iterable) -> list[tuple[float | None, Frames]]:
        """Decode ``msgs`` (can.Message, in order): segments of frames, each with the
        estimated samples lost before it (None = no outage)."""
        fid = self.message.frame_id
        segs: list[tuple[float | None, Frames]] = []
        cur: dict[str, list] = {"seq": [], "rate": [], "valid": [], "temp": []}
        brk = None
        c = self.counters
        for m in msgs:
            if m.arbitration_id in self._side and not (m.is_error_frame or m.is_remote_frame):
                self._take_side(m)
                continue
            if m.arbitration_id != fid or m.is_error_frame or m.is_remote_frame:
                c["other_frames"] += 1
                continue
            row = self._decode(m)
            if row is None:
                continue
            ts = float(m.timestamp)
            if self._last_ts is not None and ts - self._last_ts > self._stall_s:
                self._close_segment(cur, brk, segs)
                brk = (ts - self._last_ts) * self.sample_rate_hz - 1.0
            self._last_ts = ts
            c["frames_ok"] += 1
            seq, rate, ok_axes, ok, temp = row
            cur["seq"].append(seq % self.seq_modulus if self.seq_modulus else -1)
            cur["rate"].append([math.nan if v is None else v for v in rate])
            cur["valid"].append([ok and a for a in ok_axes])
            cur["temp"].append(temp)
        self._close_segment(cur, brk, segs)
        return segs

    def _decode(self, m) -> tuple[int, list[float | None], list[bool], bool, float] | None:
        """A clock frame's (counter or -1, rate per axis in signal units or None, axis has
        a value, valid flag, temperature deg C or 0); None and counted when undecodable."""
        try:
            d = self.message.decode(bytes(m.data), decode_choices=False)
            rate = [self._value(j, d) for j in range(len(self._signals))]
            ok_axes = [v is not None for v in rate]
            temp = float(d[self.temp_signal]) if self.temp_signal else 0.0
            seq = int(d[self.counter_signal]) if self.counter_signal else -1
            ok = bool(d[self.valid_signal]) if self.valid_signal else True
        except Exception:  # cantools: wrong length, bad multiplexer id, ...
            self.counters["bad_frames"] += 1
            return None
        return seq, rate, ok_axes, ok, temp

    def _close_segment(self, cur: dict[str, list], brk: float | None, segs: list) -> None:
        """The frames collected in ``cur`` (then emptied), scaled to deg/h and gated, appended
        to ``segs`` with ``brk``, the samples lost before them."""
        if not cur["seq"]:
            return
        aux = {"temp_c": cur["temp"]} if self.temp_signal else {}
        with np.errstate(over="ignore"):       # a garbage 1e308 becomes inf, then gated
            rate = np.asarray(cur["rate"], dtype=np.float64).reshape(-1, len(self._scale)) * self._scale
        valid = np.asarray(cur["valid"], dtype=bool).reshape(rate.shape)
        rate, bad = plausibility.gate(rate, self.max_rate_dph, valid)
        self.counters[plausibility.COUNTER] += bad
        segs.append((brk, Frames.from_lists(cur["seq"], rate, valid, aux, axes=self.axes)))
        for v in cur.values():
            v.clear()

    def _take_side(self, m) -> None:
        """A frame of another axis's message: its values wait for the next clock frame."""
        msg, js = self._side[m.arbitration_id]
        try:
            d = msg.decode(bytes(m.data), decode_choices=False)
            values = {j: float(d[self._signals[j][0]]) for j in js}
        except Exception:  # cantools: wrong length, ...
            self.counters["bad_frames"] += 1
            return
        if js[0] in self._latest:
            self.counters["axis_frames_superseded"] += 1
        self._latest.update(values)

    def _value(self, j: int, d: dict) -> float | None:
        """Axis ``j``'s rate (signal units) for the clock frame decoded as ``d``: from ``d``,
        or the latest frame of its own message since the previous clock frame (None and
        counted when none came)."""
        sig, msg = self._signals[j]
        if msg is self.message:
            return float(d[sig])
        if j in self._latest:
            return self._latest.pop(j)
        self.counters[f"axis_frames_missing_{self.axes[j]}"] += 1
        return None
