"""CAN logs python-can reads (.asc .blf .trc .csv .log .mf4), decoded with the DBC codec
(fogmon.sources.codecs.can); the pieces of an archive's ASC log (frames-NNNN.asc) as one
stream.

Time comes from the log's time stamps (fogmon.sources.files.timing): every frame of the
gyro's message that decodes is one sample, stamped by the logger; the sample rate and the
grid are estimated from those stamps (gaps from the stamps, refined by the rolling counter
where the DBC has one). The DBC cycle time (GenMsgCycleTime) or ``sample_rate_hz`` is
only checked against them: more than 1 % off is an error with both numbers, unless
``force_rate``. The whole log is decoded when it is opened (about 40 bytes per sample of
memory), so a broken log, a message that never occurs or a wrong rate is a one-line
error before any work."""
from __future__ import annotations

import contextlib
import os
import sys
from collections import Counter

import can
import numpy as np

from fogmon import units
from fogmon.errors import FogmonError
from fogmon.formats.capture import CAN_DECODER_FIELDS
from fogmon.sources import plausibility
from fogmon.sources.codecs import can as can_codec
from fogmon.sources.codecs.can import CanDecoder, load_dbc
from fogmon.sources.files.capture import read_capture_sidecar
from fogmon.sources.files.listing import Entry, reading, stamped_entry
from fogmon.sources.files.stamped import StampedSource
from fogmon.sources.options import SourceOptions

CHUNK = 4096


class _StampingDecoder(CanDecoder):
    """A CanDecoder that keeps the log time stamp of every frame it decodes (``stamps``,
    s, in the order of the samples it yields)."""

    def __init__(self, db, **options) -> None:
        super().__init__(db, **options)
        self.stamps: list[float] = []

    def _decode(self, m):
        row = super()._decode(m)
        if row is not None:
            self.stamps.append(float(m.timestamp))
        return row

    def delta_factor(self, rate_hz: float, rate_unit: str | None) -> np.ndarray:
        """Per axis: deg/h at ``rate_hz`` / deg/h at the rate decoded with, for a rate
        signal in an angle per sample (1 for a rate)."""
        keys = can_codec._rate_units(self._signals, rate_unit)   # noqa: SLF001 (the codec's unit table)
        return np.array([units.dph_scale(k, rate_hz) / units.dph_scale(k, self.sample_rate_hz) for k in keys])


def _messages(paths: list[str], first: str):
    """Every frame of the log(s) ``paths`` in order (python-can LogReader; pieces with
    their absolute time stamps), chunked; a one-line FogmonError naming the file for a
    log python-can cannot read."""
    kwargs = {"relative_timestamp": False} if len(paths) > 1 else {}
    for path in paths:
        if path.lower().endswith(".mf4"):   # python-can reads it with asammdf: its layout checked first
            from fogmon.sources.files.mdf import check_layout
            check_layout(path)
        with reading(f"{path}: cannot read as a CAN log"):   # unknown suffix, unreadable header, ...
            reader = can.LogReader(path, **kwargs)
            it = iter(reader)
        n = 0
        try:
            while True:
                chunk: list = []
                with reading(f"{path}: unreadable CAN log after {n} frames"):    # a corrupt log
                    for m in it:
                        chunk.append(m)
                        if len(chunk) >= CHUNK:
                            break
                if not chunk:
                    break
                n += len(chunk)
                yield chunk
        finally:
            with contextlib.suppress(FogmonError), reading(f"{path}: closing"):
                reader.stop()


def open_can_log(path: str | list[str], dbc: str | None, options: dict, sidecar: dict | None,
                 force_rate: bool = False, resample_hz: float | None = None) -> StampedSource:
    """The CAN log ``path`` (or the pieces of one ASC log, in order) decoded with the DBC
    ``dbc`` (or the sidecar's copy, which fogmon.formats.capture.read_sidecar has
    confined to the sidecar's folder) and the decoder ``options`` (CanDecoder's names),
    the sidecar's where not given; on the grid of its time stamps."""
    paths = [path] if isinstance(path, str) else list(path)
    first = paths[0]
    opts = {}
    if sidecar:
        opts.update({k: sidecar[k] for k in CAN_DECODER_FIELDS if sidecar.get(k) is not None})
        if not dbc and sidecar.get("dbc"):
            dbc = os.path.join(os.path.dirname(os.path.abspath(first)), sidecar["dbc"])
    opts.update({k: v for k, v in options.items() if v is not None})
    if not dbc:
        raise FogmonError(f"{first}: a CAN log needs `dbc` F describing the gyro's frames (fogmon info {first} "
                          f"lists the ids it holds)")
    db = load_dbc(dbc)
    nominal = opts.pop("sample_rate_hz", None)
    gate = plausibility.max_rate_dph(opts.pop("max_rate_dph", None), plausibility.GENERIC_MAX_ABS_DPH)
    try:   # decoded at the nominal rate or 1 Hz, ungated: the rate and the gate are the stamped source's
        dec = _StampingDecoder(db, sample_rate_hz=nominal or 1.0, max_rate_dph=sys.float_info.max, **opts)
    except FogmonError as e:
        raise FogmonError(f"{first}: {e.message}") from None
    msg = dec.message
    what = "`sample_rate_hz`"
    if nominal is None and msg.cycle_time:
        nominal, what = 1000.0 / msg.cycle_time, f"the DBC cycle time of {msg.name} ({msg.cycle_time} ms)"
    ids: Counter = Counter()
    segs = []
    for chunk in _messages(paths, first):
        ids.update(m.arbitration_id for m in chunk)
        segs += [f for _, f in dec.feed(chunk)]
    stamps = np.asarray(dec.stamps, dtype=np.float64)
    name = os.path.basename(first) + (f" .. {os.path.basename(paths[-1])} ({len(paths)} pieces)"
                                      if len(paths) > 1 else "")
    fid = msg.frame_id
    if len(stamps) < 2:
        have = ", ".join(f"0x{i:x} ({n})" for i, n in sorted(ids.items())[:20])
        raise FogmonError(f"{first}: {len(stamps)} frame(s) of DBC message {msg.name} (id 0x{fid:x}) decoded "
                          f"({ids.get(fid, 0)} with its id, {dec.counters['bad_frames']} undecodable); the log "
                          f"holds ids: {have or 'none'}{' ...' if len(ids) > 20 else ''} (fogmon info {first})")
    seq = np.concatenate([f.seq for f in segs])
    rate = np.concatenate([f.rate_dph for f in segs])
    valid = np.concatenate([f.valid for f in segs])
    aux = {k: np.concatenate([f.aux[k] for f in segs]) for k in dec.aux_names}
    counters = {k: v for k, v in dec.counters.items() if k != "implausible_samples"}
    where = f"{first} message {msg.name}"
    src = StampedSource(stamps - stamps[0], rate, aux, name=f"CAN log {name}: {dec.describe()}", where=where,
                        meta={"t0_log_s": repr(float(stamps[0]))},
                        time_field="timestamp", max_abs_dph=gate, counters=counters, axes=dec.axes, valid=valid,
                        seq=seq if dec.seq_modulus else None, modulus=dec.seq_modulus, nominal_hz=nominal,
                        nominal_what=what, force_rate=force_rate, resample_hz=resample_hz)
    if resample_hz is None:
        factor = dec.delta_factor(src.sample_rate_hz, opts.get("rate_unit"))
        if np.any(factor != 1.0):
            src._rate = src._rate * (factor if dec.axes else factor[0])   # noqa: SLF001 (decoded at 1 Hz: rescaled)
    src.name = f"CAN log {name}: {dec.describe().rsplit(',', 1)[0]}, {src.sample_rate_hz:.6g} Hz from the time stamps"
    return src


def info(path: str, opts: SourceOptions) -> list[Entry]:
    """One Entry per CAN id of the log ``path`` (with ``dbc``: its message name and
    signals' units)."""
    db = load_dbc(opts.dbc) if opts.dbc else None
    stamps: dict[int, list[float]] = {}
    for chunk in _messages([path], path):
        for m in chunk:
            if not (m.is_error_frame or m.is_remote_frame):
                stamps.setdefault(m.arbitration_id, []).append(float(m.timestamp))
    out = []
    for fid, t in sorted(stamps.items()):
        kind, unit = "CAN frame", ""
        if db is not None:
            try:
                m = db.get_message_by_frame_id(fid)
                kind = f"CAN {m.name} ({', '.join(s.name for s in m.signals)})"
                unit = ", ".join(sorted({s.unit for s in m.signals if s.unit}))
            except KeyError:
                pass
        out.append(stamped_entry(f"0x{fid:x}", kind, t, unit))
    return out


def open_source(path: str, opts: SourceOptions) -> StampedSource:
    """The CAN log ``path`` with the DBC and decoder options ``opts`` gives, else its
    sidecar's."""
    return open_can_log(path, opts.dbc, opts.can_options(), read_capture_sidecar(path), opts.force_rate,
                        opts.resample_hz)
