"""KVH DSP-1750/1760/1775 binary output Formats A, B and C: an incremental, bounded-buffer
decoder with resynchronisation.

Wire formats (big-endian):

- A, 36 bytes: header ``FE 81 FF 55``, gyro x/y/z float32, accel x/y/z float32
  (reserved on the 1760), status uint8 (bits 0-2: gyro x/y/z valid, bits 4-6: accel
  x/y/z valid), sequence uint8 (0-127, wrapping), temperature int16 (deg C),
  CRC-32/MPEG-2 uint32.
- B, 40 bytes: header ``... 56``, as A with a uint32 microsecond timestamp after the
  accelerometers (before status).
- C, 38 bytes: header ``... 57``, gyro, accel, one float32 multiplexed by sequence % 4
  (0: temperature deg C, 1-3: magnetometer x/y/z gauss), status, sequence, CRC.

The CRC (poly 0x04C11DB7, init 0xFFFFFFFF, no reflection, xorout 0) covers every byte
before it, so the CRC of a whole good frame is 0. Resync: find the header, check the CRC,
on failure drop one byte and rescan. Gyro values are delta angles (per sample) or rates,
in rad or deg, as the device is configured; they are converted to deg/h here and gated
(fogmon.sources.plausibility): a CRC-valid frame can still carry a garbage float.

Axes: by default all three gyros are decoded (a three-axis stream, ``axes`` x, y, z,
each gyro valid as its status bit says) with the accelerometers as aux channels
``accel_<axis>_g`` in g, NaN where their status bit is clear or the reading is beyond
plausibility.KVH_ACCEL_MAX_ABS_G (counted as ``implausible_accel_g``). The accelerometers send
acceleration in g (the device's default linear format) or, after ``=LINFMT``, velocity
increments per sample in m/s or ft/s (``=LINUNITS``): ``accel`` says which (``ACCEL_UNITS``)
and ``none`` leaves them out (a gyro-only DSP-1760, whose accel fields are reserved).
``units`` (``kvh_units``) is the gyros' angle unit only. One axis (``axis="z"``) is today's
one-axis stream: that gyro alone, ``temp_c`` the only aux channel; several
(``axis="x,y"``) a multi-axis stream of those gyros and their accelerometers.
"""
from __future__ import annotations

import binascii
import math
import struct

import numpy as np

from fogmon.block import parse_axes
from fogmon.errors import FogmonError
from fogmon.sources import plausibility
from fogmon.sources.frames import Frames
from fogmon.sources.grid import check_sample_rate
from fogmon.units import G0_MPS2, to_dph

#: bit-reversal of every byte value, to run CRC-32/MPEG-2 through zlib's reflected CRC-32.
_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def crc32_mpeg2(data: bytes) -> int:
    """CRC-32/MPEG-2 of ``data`` (poly 0x04C11DB7, init 0xFFFFFFFF, no reflection,
    xorout 0). Computed with zlib's reflected CRC-32 on bit-reversed bytes (C speed):
    reflecting input and output turns one into the other."""
    r = binascii.crc32(bytes(data).translate(_REV8)) ^ 0xFFFFFFFF
    return int(f"{r:032b}"[::-1], 2)


#: format letter -> (header, frame length, struct layout of the frame without CRC)
FORMATS = {
    "a": (b"\xfe\x81\xff\x55", 36, struct.Struct(">4x6fBBh")),
    "b": (b"\xfe\x81\xff\x56", 40, struct.Struct(">4x6fIBBh")),
    "c": (b"\xfe\x81\xff\x57", 38, struct.Struct(">4x7fBB")),
}
#: the same layouts as numpy records (whole frames, CRC included), to unpack many at once
_RECORDS = {
    "a": np.dtype([("hdr", "V4"), ("sensor", ">f4", 6), ("status", "u1"), ("seq", "u1"), ("temp", ">i2"),
                   ("crc", "V4")]),
    "b": np.dtype([("hdr", "V4"), ("sensor", ">f4", 6), ("time_us", ">u4"), ("status", "u1"), ("seq", "u1"),
                   ("temp", ">i2"), ("crc", "V4")]),
    "c": np.dtype([("hdr", "V4"), ("sensor", ">f4", 6), ("temp", ">f4"), ("status", "u1"), ("seq", "u1"),
                   ("crc", "V4")]),
}
AXES = ("x", "y", "z")
SEQ_MODULUS = 128
DEFAULT_RATE_HZ = 1000.0
#: accelerometer output (``kvh_accel``) -> (g per unit, per sample: a velocity increment
#: per sample, multiplied by the sample rate in Hz); "none": not decoded
ACCEL_UNITS = {"g": (1.0, False), "dv-m": (1.0 / G0_MPS2, True), "dv-ft": (0.3048 / G0_MPS2, True),
               "none": (0.0, False)}


def kvh_axes(axis: str | None) -> tuple[str, ...]:
    """``axis`` of a KVH decoder -> the gyros to decode: None = all three, ``"z"`` one,
    ``"x,y"`` several (in the order given). A FogmonError names a bad or repeated axis."""
    if axis is None:
        return AXES
    names = parse_axes(str(axis))
    if any(a not in AXES for a in names):
        raise FogmonError(f"`axis` must be x, y, z or several of them separated by commas (x,y), got {axis!r}")
    return names


def output_unit(mode: str, angle: str) -> str:
    """The fogmon.units name of a KVH output: ``mode`` 'rate' (angle/s) or 'delta' (angle
    per sample), ``angle`` 'deg' or 'rad'."""
    return f"{angle}/s" if mode == "rate" else angle


class KvhCodec:
    """Incremental decoder: ``feed(bytes) -> Frames``. Counters: ``frames_ok``,
    ``crc_errors`` (a header whose frame failed the CRC), ``bytes_skipped`` (every byte
    not part of a good frame), ``implausible_samples`` (frames flagged valid whose rate
    is NaN, inf or beyond ``max_rate_dph`` deg/h: made invalid), ``implausible_temp_c``
    (temperature readings outside plausibility.TEMP_RANGE_C: NaN). Invariant: bytes fed
    = frames_ok * frame length + bytes_skipped + ``pending`` (at most one frame length -
    1 bytes are held). ``max_rate_dph`` None: the DSP-17xx range x margin. Each frame's
    ``skipped`` is the bytes skipped since the previous good frame (across ``feed``
    calls): 0 when the two are back to back (the time base relies on it)."""

    seq_modulus: int | None = SEQ_MODULUS

    def __init__(self, fmt: str = "a", rot: str = "delta", units: str = "rad",
                 axis: str | None = None, sample_rate_hz: float = DEFAULT_RATE_HZ,
                 max_rate_dph: float | None = None, accel: str = "g") -> None:
        fmt = fmt.lower()
        if fmt not in FORMATS:
            raise FogmonError(f"unknown KVH format {fmt!r} (use a, b or c)")
        if rot not in ("rate", "delta"):
            raise FogmonError(f"`kvh_rot` must be rate or delta, got {rot!r}")
        if units not in ("deg", "rad"):
            raise FogmonError(f"`kvh_units` must be deg or rad, got {units!r}")
        if accel not in ACCEL_UNITS:
            raise FogmonError(f"`kvh_accel` must be one of {', '.join(ACCEL_UNITS)}, got {accel!r}")
        names = kvh_axes(axis)
        sample_rate_hz = check_sample_rate(sample_rate_hz)
        self.fmt, self.rot, self.units, self.sample_rate_hz = fmt, rot, units, float(sample_rate_hz)
        self.axis, self.accel = ",".join(names), accel
        #: () for one gyro (today's one-axis stream), else the gyros decoded
        self.axes = names if len(names) > 1 else ()
        self.max_rate_dph = plausibility.max_rate_dph(max_rate_dph, plausibility.KVH_DSP17XX_MAX_ABS_DPH)
        self.protocol = f"kvh-{fmt}"
        self.header, self.frame_len, self._layout = FORMATS[fmt]
        self._axis_i = [AXES.index(a) for a in names]
        scale, per_sample = ACCEL_UNITS[accel]
        self._accel_g = scale * (self.sample_rate_hz if per_sample else 1.0)
        self._accel_names = tuple(f"accel_{a}_g" for a in names) if self.axes and accel != "none" else ()
        self.aux_names = (*self._accel_names, "temp_c")
        self.counters = {"frames_ok": 0, "crc_errors": 0, "bytes_skipped": 0,
                         plausibility.COUNTER: 0, plausibility.TEMP_COUNTER: 0}
        if self._accel_names:
            self.counters[plausibility.ACCEL_COUNTER] = 0
        self._buf = bytearray()
        self._last_temp_c = math.nan  # format C: temperature arrives every 4th frame
        self._run = 0                 # bytes skipped since the last good frame

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a frame (< frame length)."""
        return len(self._buf)

    def options(self) -> dict:
        """What is needed to rebuild this decoder (raw-capture sidecar)."""
        opts = {"protocol": self.protocol, "kvh_rot": self.rot, "kvh_units": self.units,
                "axis": self.axis, "sample_rate_hz": self.sample_rate_hz, "max_rate_dph": self.max_rate_dph}
        return {**opts, "kvh_accel": self.accel} if self.axes else opts

    def describe(self) -> str:
        what = f"axis {self.axis}" if not self.axes else f"axes {self.axis}"
        accel = f", accel {self.accel}" if self._accel_names else ""
        return f"KVH format {self.fmt.upper()} ({self.rot}, {self.units}{accel}), {what}, {self.sample_rate_hz:g} Hz"

    def feed(self, data: bytes) -> Frames:
        self._buf += data
        return self._frames(*self._scan())

    def _scan(self) -> tuple[np.ndarray, list[int]]:
        """The whole frames in the buffer (then dropped from it; a partial frame stays),
        found by header and CRC, with counters: the good frames as numpy records and the
        bytes skipped before each. Back-to-back good frames are checked as a run (header
        compare over all of them, one C CRC call each)."""
        data = bytes(self._buf)
        n = len(data)
        L, hdr = self.frame_len, self.header
        rev = memoryview(data.translate(_REV8))       # CRCs of frames are slices of it
        starts: list[int] = []
        runs: list[int] = []
        crc_err = skipped = 0
        run = self._run
        i = 0
        while True:
            j = data.find(hdr, i)
            if j < 0:
                keep = max(i, n - (len(hdr) - 1))  # a header may straddle the chunk end
                skipped += keep - i
                run += keep - i
                i = keep
                break
            skipped += j - i
            run += j - i
            if j + L > n:
                i = j
                break
            good = _good_run(data, rev, j, L, hdr)
            if not good:
                crc_err += 1
                skipped += 1
                run += 1
                i = j + 1
                continue
            starts.extend(range(j, j + good * L, L))
            runs += [run] + [0] * (good - 1)
            run = 0
            i = j + good * L
        del self._buf[:i]
        self._run = run
        c = self.counters
        c["frames_ok"] += len(starts)
        c["crc_errors"] += crc_err
        c["bytes_skipped"] += skipped
        raw = np.frombuffer(data, np.uint8)
        rows = raw[np.asarray(starts, dtype=np.int64)[:, None] + np.arange(L)] if starts else np.zeros((0, L), np.uint8)
        return rows.view(_RECORDS[self.fmt]).reshape(-1), runs

    def _temps(self, rec: np.ndarray) -> np.ndarray:
        """Temperature (deg C) of each frame: NaN where implausible (counted); format C:
        the latest reading, sent when seq % 4 == 0 and held until the next."""
        t_lo, t_hi = plausibility.TEMP_RANGE_C
        reading = rec["temp"].astype(np.float64)
        sent = rec["seq"] % 4 == 0 if self.fmt == "c" else np.ones(len(rec), bool)
        bad = sent & ~((reading >= t_lo) & (reading <= t_hi))
        self.counters[plausibility.TEMP_COUNTER] += int(bad.sum())
        temps = np.where(bad, np.nan, reading)
        if self.fmt != "c" or not len(rec):
            return temps
        last = np.maximum.accumulate(np.where(sent, np.arange(len(rec)), -1))
        held = np.where(last >= 0, temps[np.maximum(last, 0)], self._last_temp_c)
        self._last_temp_c = float(held[-1])
        return held

    def _frames(self, rec: np.ndarray, runs: list[int]) -> Frames:
        """The scanned frames (numpy records) as Frames: rate in deg/h of the decoded axes,
        gated; aux temp_c and, with ``accel``, the accelerations in g."""
        c = self.counters
        ai = self._axis_i
        bits = rec["status"].reshape(-1, 1)
        valid = (bits >> np.asarray(ai, dtype=np.uint8) & 1).astype(bool)
        gyro_accel = rec["sensor"].astype(np.float64)
        rate_dph = to_dph(gyro_accel[:, ai], output_unit(self.rot, self.units), self.sample_rate_hz)
        if not self.axes:
            rate_dph, valid = rate_dph[:, 0], valid[:, 0]
        rate, bad = plausibility.gate(rate_dph, self.max_rate_dph, valid)
        c[plausibility.COUNTER] += bad
        aux: dict = {"temp_c": self._temps(rec)}
        if self._accel_names:
            aux = {**self._accel_aux(gyro_accel, bits), **aux}
        return Frames.from_lists(rec["seq"] & 0x7F, rate, valid, aux, runs, self.frame_len, self.axes)

    def _accel_aux(self, gyro_accel: np.ndarray, bits: np.ndarray) -> dict[str, np.ndarray]:
        """The decoded axes' accelerations (g) as aux channels: NaN where the status byte
        flags them invalid or they are implausible (counted)."""
        ai = self._axis_i
        accel_g = gyro_accel[:, [3 + i for i in ai]] * self._accel_g
        flagged = (bits >> (np.asarray(ai, dtype=np.uint8) + 4) & 1) == 1
        with np.errstate(invalid="ignore"):
            implausible = flagged & ~(np.abs(accel_g) <= plausibility.KVH_ACCEL_MAX_ABS_G)
        self.counters[plausibility.ACCEL_COUNTER] += int(implausible.sum())
        accel_g[~flagged | implausible] = np.nan
        return dict(zip(self._accel_names, accel_g.T, strict=True))


def _good_run(data: bytes, rev: memoryview, j: int, L: int, hdr: bytes) -> int:
    """How many good frames of length ``L`` follow back to back from ``j`` in ``data``
    (header in place and CRC right; ``rev`` is ``data`` bit-reversed for the CRC). Stops at
    the first bad one, so a corrupted stream costs one check per frame, not per frame left."""
    n = 0
    for a in range(j, len(data) - L + 1, L):
        if not data.startswith(hdr, a) or binascii.crc32(rev[a:a + L]) != 0xFFFFFFFF:
            break
        n += 1
    return n


def encode_frame(fmt: str, seq: int, gyro_xyz=(0.0, 0.0, 0.0), accel_xyz=(0.0, 0.0, 0.0),
                 status: int = 0x77, temp_c: float = 25.0, timestamp_us: int = 0) -> bytes:
    """One valid frame (what a KVH device sends); for fake devices in tests and for
    documentation. Format C carries ``temp_c`` only when seq % 4 == 0 (else 0.0 is sent
    in the magnetometer slot)."""
    hdr, _, _ = FORMATS[fmt]
    g, a = [float(v) for v in gyro_xyz], [float(v) for v in accel_xyz]
    if fmt == "a":
        body = hdr + struct.pack(">6fBBh", *g, *a, status, seq & 0x7F, int(round(temp_c)))
    elif fmt == "b":
        body = hdr + struct.pack(">6fIBBh", *g, *a, timestamp_us & 0xFFFFFFFF, status, seq & 0x7F,
                                 int(round(temp_c)))
    else:
        mux = float(temp_c) if seq % 4 == 0 else 0.0
        body = hdr + struct.pack(">7fBB", *g, *a, mux, status, seq & 0x7F)
    return body + struct.pack(">I", crc32_mpeg2(body))
