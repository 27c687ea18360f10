"""Rebuild the real gyro recordings of validation/real_recordings.toml as fogmon replay logs.

Usage:
    python validation/real_recordings.py [MIRROR ...] [--out DIR] [--describe]

MIRROR: a folder holding repository snapshots as ``owner+name/repo`` bare git
directories (default /work/.mirror), or such a git directory itself. Every original is
read with ``git --git-dir=... show COMMIT:PATH`` at the commit the manifest names, its
sha256 is checked, and it is converted to a replay log v1 (docs/formats.md: time_s in
s, rate_dph in deg/h) under DIR (default $FOGMON_REALDATA or /work/realdata). The sha256
of each written file is compared with the manifest; exit 1 on any mismatch or missing
snapshot. ``--describe`` also prints the raw-data statistics the manifest's evidence
quotes (block standard deviations, the moving-RMS peak, the spectrum, gaps, > 8 MAD
outliers).

Readers beyond fogmon's own dependencies, needed only here: pymseed (miniSEED), pyulog
(PX4 ULog) and rdata (R data files), all on PyPI. The fetched data is never committed
(GPL-3.0 and CC BY-NC-SA 4.0 data among it is used for validation only).
"""
from __future__ import annotations

import argparse
import hashlib
import io
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np

from fogmon.formats.replay_log import read_replay_log, write_replay_log

REPO_ROOT = Path(__file__).resolve().parent.parent
MANIFEST = Path(__file__).with_name("real_recordings.toml")
DEFAULT_DATA = os.environ.get("FOGMON_REALDATA", "/work/realdata")


def load_manifest(path: Path = MANIFEST) -> list[dict]:
    """The manifest's recordings, each with the fields of its ``same_source_as`` or
    ``excerpt_of`` entry filled in (an excerpt keeps its own name, file, window and facts)."""
    entries = tomllib.loads(path.read_text(encoding="utf-8"))["recording"]
    by_name = {e["name"]: e for e in entries}
    out = []
    for e in entries:
        base = by_name.get(e.get("same_source_as") or e.get("excerpt_of") or "", {})
        keep = {k: v for k, v in base.items()
                if k not in ("name", "file", "motion_s", "transient_t_s", "quiet", "sha256_converted")}
        out.append({**keep, **e})
    return out


def data_path(entry: dict, data_dir: str | os.PathLike) -> Path:
    """Where the converted replay log of ``entry`` lives (bundled files: in the repository)."""
    f = Path(entry["file"])
    return REPO_ROOT / f if f.parts[0] == "replay_logs" else Path(data_dir) / f


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def find_git_dir(roots: list[str], repo: str) -> Path | None:
    """The snapshot of ``repo`` (owner/name) under one of ``roots``."""
    key = repo.replace("/", "+")
    for root in map(Path, roots):
        for cand in (root / key / "repo", root / key, root):
            if (cand / "objects").is_dir() and key in str(cand.resolve()):
                return cand
    return None


def read_original(entry: dict, roots: list[str]) -> bytes:
    """The original file's bytes at the manifest's commit, sha256-checked."""
    git = find_git_dir(roots, entry["repo"])
    if git is None:
        raise SystemExit(f"{entry['name']}: no snapshot of {entry['repo']} under {', '.join(roots)} "
                         f"(fetch github:{entry['repo']})")
    data = subprocess.run(["git", f"--git-dir={git}", "show", f"{entry['commit']}:{entry['path']}"],
                          check=True, capture_output=True).stdout
    if sha256(data) != entry["sha256_original"]:
        raise SystemExit(f"{entry['name']}: {entry['repo']}@{entry['commit']}:{entry['path']} has sha256 "
                         f"{sha256(data)}, the manifest says {entry['sha256_original']}")
    return data


# --------------------------------------------------------------------------- readers
def read_mseed(data: bytes, channel: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(time s from the first sample, samples in file units, sample rate Hz) of the one
    trace whose FDSN source id ends with ``channel``; several segments keep their gaps."""
    import pymseed

    traces = pymseed.MS3TraceList.from_buffer(data, unpack_data=True)
    (tid,) = [t for t in traces if t.sourceid.endswith(channel)]
    segs = list(tid)
    sample_rate_hz = float(segs[0].samprate)
    t0 = segs[0].starttime
    t = np.concatenate([(s.starttime - t0) * 1e-9 + np.arange(s.numsamples) / sample_rate_hz for s in segs])
    x = np.concatenate([np.asarray(s.datasamples, dtype=float) for s in segs])
    return t, x, sample_rate_hz


def read_csv_column(data: bytes, column: str) -> tuple[np.ndarray, np.ndarray]:
    """(time s from the first row, column values) of a CSV with a header row whose first
    column is the time in s."""
    header = data.split(b"\n", 1)[0].decode("utf-8").strip().split(",")
    m = np.loadtxt(io.BytesIO(data), delimiter=",", skiprows=1)
    return m[:, 0] - m[0, 0], m[:, header.index(column)]


def read_ulog(data: bytes, topic: str, column: str) -> tuple[np.ndarray, np.ndarray]:
    """(time s from the first message, field values) of a PX4 ULog topic (timestamps in us)."""
    import pyulog

    (d,) = [d for d in pyulog.ULog(io.BytesIO(data), [topic]).data_list if d.multi_id == 0]
    ts = d.data["timestamp"].astype(np.int64)
    return (ts - ts[0]) * 1e-6, d.data[column].astype(float)


def read_rda(data: bytes, column: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(time s = k / freq, the named column, freq Hz) of an R data file (.rda) holding one
    ``imu`` matrix of the imudata/gmwm R packages: columns named in its ``dimnames``, the
    sample rate in its ``freq`` attribute, no time stamps (uniform sampling)."""
    import warnings

    import rdata

    obj = rdata.parser.parse_data(data).object.value[0]
    attrs = {}
    node = obj.attributes
    with warnings.catch_warnings():  # rdata has no constructor for the class "imu": fine, we read it raw
        warnings.simplefilter("ignore")
        while node is not None and node.info.type.name == "LIST":
            attrs[node.tag.value.value.decode()] = rdata.conversion.convert(node.value[0])
            node = node.value[1] if len(node.value) > 1 else None
        values = np.asarray(rdata.conversion.convert(obj), dtype=float)
    names = [str(n) for n in attrs["dimnames"][1]]
    matrix = values.reshape(attrs["dim"], order="F") if values.ndim == 1 else values
    sample_rate_hz = float(np.asarray(attrs["freq"]).ravel()[0])
    return np.arange(matrix.shape[0]) / sample_rate_hz, matrix[:, names.index(column)], sample_rate_hz


def snap(t_s: np.ndarray, sample_rate_hz: float, name: str) -> tuple[np.ndarray, float]:
    """Timestamps moved to the nearest slot of the fs grid; (snapped times, largest shift s).
    Two samples in one slot would be a conversion error."""
    k = np.rint(t_s * sample_rate_hz)
    if np.any(np.diff(k) < 1):
        raise SystemExit(f"{name}: two samples fall into one {1 / sample_rate_hz:g} s slot; cannot snap")
    return k / sample_rate_hz, float(np.max(np.abs(k / sample_rate_hz - t_s)))


def convert(entry: dict, original: bytes) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(time_s, rate_dph, sample rate Hz, largest timestamp shift s) of ``entry``'s
    recording, its excerpt window applied."""
    shift = 0.0
    if entry["reader"] == "mseed":
        t, x, sample_rate_hz = read_mseed(original, entry["channel"])
    elif entry["reader"] == "rda":
        t, x, sample_rate_hz = read_rda(original, entry["column"])
    else:
        if entry["reader"] == "csv":
            t, x = read_csv_column(original, entry["column"])
        else:
            t, x = read_ulog(original, entry["topic"], entry["column"])
        sample_rate_hz = entry["snap_hz"]
        t, shift = snap(t, sample_rate_hz, entry["name"])
    keep = (t >= entry.get("t_start_s", -np.inf)) & (t < entry.get("t_end_s", np.inf))
    return np.round(t[keep], 9), x[keep] * entry["scale_to_dph"], sample_rate_hz, shift


def metadata(entry: dict, sample_rate_hz: float) -> dict:
    return {
        "sample_rate_hz": f"{sample_rate_hz:g}",
        "sensor": f"{entry['sensor']}, axis {entry['axis']}",
        "source": (f"github.com/{entry['repo']} commit {entry['commit']} {entry['path']} "
                   f"({entry['licence_spdx']}; see fogmon validation/real_recordings.toml)"),
        "units": f"rate_dph in deg/h from {entry['original_units']}: {entry['conversion']}",
        **({"excerpt": f"{entry['t_start_s']:g}..{entry['t_end_s']:g} s of {entry['excerpt_of']}"}
           if "excerpt_of" in entry else {}),
    }


# --------------------------------------------------------------------------- evidence
def describe(entry: dict, path: Path) -> None:
    """The raw-data statistics the manifest's evidence quotes, from the converted log."""
    blk = read_replay_log(path).to_block()
    ok = blk.valid
    y = blk.rate_dph
    sample_rate_hz = 1.0 / float(np.median(np.diff(blk.t_s)))
    med = float(np.median(y[ok]))
    mad = float(np.median(np.abs(y[ok] - med)))
    n_out = int(np.sum(np.abs(y[ok] - med) > 8 * mad))
    scale = entry.get("scale_to_dph", 1.0)
    print(f"  {int(ok.sum())} samples, {len(y) - int(ok.sum())} missing (gaps), {blk.t_s[0]:g}..{blk.t_s[-1]:g} s, "
          f"median {med:.6g} deg/h, MAD {mad:.4g} deg/h, {n_out} samples beyond 8 MAD")
    b = int(round(entry.get("describe_block_s", 5.0) * sample_rate_hz))
    if b < 2 or len(y) < 2 * b:
        return
    blocks = y[: len(y) // b * b].reshape(-1, b)
    sd = np.array([np.std(r[np.isfinite(r)]) if np.isfinite(r).sum() > 1 else np.nan for r in blocks])
    print(f"  {b / sample_rate_hz:g}-s block standard deviations (original units): "
          + " ".join(f"{v / scale:.3g}" for v in sd))
    from scipy.signal import welch

    f, psd = welch(np.where(ok, y - med, 0.0), fs=sample_rate_hz, nperseg=min(4096, len(y) // 4))
    rel = psd / np.median(psd[1:])
    edges = sample_rate_hz / 2 / 2.0 ** np.arange(9)[::-1]
    bands = [f"{a:.3g}-{b:.3g} Hz {np.mean(rel[(f >= a) & (f < b)]):.2g}"
             for a, b in zip(edges[:-1], edges[1:], strict=True) if np.any((f >= a) & (f < b))]
    i = int(np.argmax(np.where(f > 0.05, rel, 0)))
    print(f"  Welch PSD / its median, octave bands: {'; '.join(bands)}; strongest peak above 0.05 Hz "
          f"{rel[i]:.3g}x at {f[i]:.4g} Hz; 0.9-1 x Nyquist {np.mean(rel[f >= 0.45 * sample_rate_hz]):.2g}")
    dev2 = np.where(ok, (y - med) ** 2, 0.0)
    ker = np.ones(b)
    rms = np.sqrt(np.convolve(dev2, ker, "same") / np.maximum(np.convolve(ok.astype(float), ker, "same"), 1))
    i = int(np.argmax(rms))
    hi = np.flatnonzero(rms > 3 * np.median(rms))
    span = f"{blk.t_s[hi[0]]:.1f}..{blk.t_s[hi[-1]]:.1f} s" if len(hi) else "nowhere"
    print(f"  {b / sample_rate_hz:g}-s moving RMS (original units): median {np.median(rms) / scale:.4g}, peak "
          f"{rms[i] / scale:.4g} at t = {blk.t_s[i]:.1f} s, above 3x the median {span}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mirror", nargs="*", default=["/work/.mirror"], help="snapshot folder(s) or git dir(s)")
    ap.add_argument("--out", default=DEFAULT_DATA, help=f"folder for the replay logs (default {DEFAULT_DATA})")
    ap.add_argument("--describe", action="store_true", help="print the raw-data statistics the evidence quotes")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    bad = 0
    for entry in load_manifest():
        out = data_path(entry, args.out)
        if "reader" in entry:
            t, rate, sample_rate_hz, shift = convert(entry, read_original(entry, args.mirror))
            write_replay_log(out, t, rate, meta=metadata(entry, sample_rate_hz))
            note = f", timestamps snapped (largest shift {1e3 * shift:.3g} ms)" if shift else ""
            print(f"{entry['name']}: wrote {out} ({len(t)} samples at {sample_rate_hz:g} Hz{note})")
        digest = sha256(out.read_bytes())
        want = entry.get("sha256_converted")
        ok = digest == want
        bad += not ok
        print(f"  sha256 {digest} {'matches the manifest' if ok else f'MISMATCH (manifest: {want})'}")
        if args.describe:
            describe(entry, out)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
