"""Fuzz every serial parser with >= 1e6 random and mutated inputs (default 1,000,000).

Checks, for every input:
- no exception escapes any parser;
- KVH A/B/C: the frames accepted are exactly those an independent greedy scan accepts
  with a table-driven CRC-32/MPEG-2 (so no frame with a bad CRC is ever accepted and no
  good one is missed), and bytes are fully accounted (frames x length + skipped + held);
- DSP-3000 and column-mapped lines: the output does not depend on how the bytes were
  chunked and the held buffer stays bounded;
- the plausibility gate (inputs carry NaN, inf, 1e25, 1e30, values just beyond the
  device range): no accepted sample has a rate beyond the gate or a non-finite one, no
  KVH temperature outside -60..+125 deg C is passed on, and every sample flagged valid
  whose value is implausible is counted (KVH: exactly the count an independent decode of
  the reference frames gives; ASCII: exactly the valid samples the gate made NaN).

    python validation/fuzz_parsers.py [N_INPUTS] [SEED]

Prints counts and PASS/FAIL; exit code 1 on any failure."""
from __future__ import annotations

import math
import os
import random
import struct
import sys
import time
from multiprocessing import Pool

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from fogmon.sources.codecs.kvh import FORMATS, encode_frame  # noqa: E402
from fogmon.sources.codecs.protocols import make_codec  # noqa: E402
from fogmon.sources.plausibility import TEMP_RANGE_C  # noqa: E402

#: rates (deg/s) that are garbage or just beyond a gate, mixed into the inputs
IMPLAUSIBLE_DPS = [math.nan, math.inf, -math.inf, 1e25, -1e30, 1e38, 735.01, -562.51, 1e4 + 1e-3, 1e300]
#: the float32 of a KVH frame holds at most 3.4e38
IMPLAUSIBLE_F32 = [v for v in IMPLAUSIBLE_DPS if not abs(v) < math.inf or abs(v) < 3.4e38]

_TABLE = []
for _i in range(256):
    _c = _i << 24
    for _ in range(8):
        _c = ((_c << 1) ^ 0x04C11DB7) & 0xFFFFFFFF if _c & 0x80000000 else (_c << 1) & 0xFFFFFFFF
    _TABLE.append(_c)


def crc_table(data: bytes) -> int:
    c = 0xFFFFFFFF
    for b in data:
        c = ((c << 8) & 0xFFFFFFFF) ^ _TABLE[(c >> 24) ^ b]
    return c


def reference_scan(data: bytes, fmt: str, max_dph: float) -> tuple[list[int], int]:
    """Sequence numbers of the frames a greedy left-to-right scan accepts, and how many of
    them the device flagged valid (z) with a z rate (deg/s) beyond +-``max_dph`` deg/h."""
    hdr, L, _ = FORMATS[fmt]
    seq_at = L - 7 if fmt != "c" else L - 5
    out, bad, i = [], 0, 0
    while True:
        j = data.find(hdr, i)
        if j < 0 or j + L > len(data):
            return out, bad
        if crc_table(data[j:j + L]) == 0:
            out.append(data[j + seq_at] & 0x7F)
            z = struct.unpack(">f", data[j + 12:j + 16])[0]
            bad += bool(data[j + seq_at - 1] >> 2 & 1) and not abs(z * 3600.0) <= max_dph
            i = j + L
        else:
            i = j + 1


def value(rng: random.Random, scale: float, implausible=IMPLAUSIBLE_DPS) -> float:
    """A plausible rate (deg/s) within +-scale, or one of ``implausible`` (one in four)."""
    return rng.choice(implausible) if rng.random() < 0.25 else rng.uniform(-scale, scale)


def make_input(rng: random.Random, protocol: str) -> bytes:
    if protocol.startswith("kvh"):
        fmt = protocol[-1]
        temps = [-40, 25, 80, -61, 126, 30000, -32768]
        base = b"".join(encode_frame(fmt, rng.randrange(128), tuple(value(rng, 1, IMPLAUSIBLE_F32) for _ in "xyz"),
                                     status=rng.randrange(256), temp_c=rng.choice(temps) if rng.random() < 0.2 else
                                     rng.randrange(-40, 80)) for _ in range(rng.randrange(0, 5)))
    elif protocol == "dsp3000":
        base = b"".join(f"  {value(rng, 100):.6g}   {rng.randrange(2)}\r\n".encode()
                        for _ in range(rng.randrange(0, 6)))
    else:
        base = b"".join(f"{rng.randrange(300)},{value(rng, 1):.5g};{rng.uniform(0, 50):.2f}\n".encode()
                        for _ in range(rng.randrange(0, 6)))
    kind = rng.random()
    if kind < 0.2:
        return rng.randbytes(rng.randrange(0, 200))
    data = bytearray(base)
    for _ in range(rng.randrange(1, 6)):
        op = rng.randrange(6)
        pos = rng.randrange(len(data) + 1)
        if op == 0 and data:
            data[min(pos, len(data) - 1)] ^= 1 << rng.randrange(8)
        elif op == 1:
            data[pos:pos] = rng.randbytes(rng.randrange(1, 10))
        elif op == 2:
            del data[pos:pos + rng.randrange(1, 12)]
        elif op == 3 and protocol.startswith("kvh"):
            data[pos:pos] = FORMATS[protocol[-1]][0]
        elif op == 4:
            data = data[:pos]
        elif op == 5:
            data[pos:pos] = rng.choice([b"\n", b"\r\n", b",", b"nan", b"1e999", b" ", b"-", b"\xff" * 300])
    return bytes(data)


def chunks(rng: random.Random, data: bytes):
    i = 0
    while i < len(data):
        n = rng.randrange(1, 40)
        yield data[i:i + n]
        i += n


def worker(args) -> dict:
    seed, n = args
    rng = random.Random(seed)
    stats = {"inputs": 0, "bytes": 0, "frames": 0, "crc_errors": 0, "implausible": 0, "implausible_temp": 0,
             "accepted_beyond": 0, "failures": 0, "first_failure": None}
    protocols = ["kvh-a", "kvh-b", "kvh-c", "dsp3000", "lines"]
    for i in range(n):
        protocol = protocols[i % len(protocols)]
        data = make_input(rng, protocol)
        try:
            opts = {"kvh_rot": "rate", "kvh_units": "deg", "axis": "z"} if protocol.startswith("kvh") else {}
            c1 = make_codec(protocol, columns="seq:256,rate_dps,temp_c", **opts)
            c2 = make_codec(protocol, columns="seq:256,rate_dps,temp_c", **opts)
            whole = c1.feed(data)
            parts = [c2.feed(ch) for ch in chunks(rng, data)]
            seq_parts = [int(s) for p in parts for s in p.seq]
            rate_parts = [float(r) for p in parts for r in p.rate_dph]
            valid_parts = [bool(v) for p in parts for v in p.valid]
            ok = list(map(int, whole.seq)) == seq_parts and len(rate_parts) == len(whole)
            ok &= [r == r for r in map(float, whole.rate_dph)] == [r == r for r in rate_parts]
            # the gate: what is not NaN is within it; every NaN in a valid sample was counted
            beyond = sum(not abs(r) <= c2.max_rate_dph for r in rate_parts if r == r)
            stats["accepted_beyond"] += beyond
            k = c2.counters
            ok &= beyond == 0 and k["implausible_samples"] == c1.counters["implausible_samples"]
            stats["implausible"] += k["implausible_samples"]
            if protocol.startswith("kvh"):
                L = FORMATS[protocol[-1]][1]
                ref_seq, ref_bad = reference_scan(data, protocol[-1], c2.max_rate_dph)
                ok &= seq_parts == ref_seq and k["implausible_samples"] == ref_bad
                ok &= k["frames_ok"] * L + k["bytes_skipped"] + c2.pending == len(data)
                temps = [float(t) for p in parts for t in p.aux["temp_c"]]
                ok &= all(TEMP_RANGE_C[0] <= t <= TEMP_RANGE_C[1] for t in temps if t == t)
                stats["crc_errors"] += k["crc_errors"]
                stats["implausible_temp"] += k["implausible_temp_c"]
            else:
                ok &= k["implausible_samples"] == sum(v and r != r
                                                      for r, v in zip(rate_parts, valid_parts, strict=True))
                ok &= c2.pending <= 512
            stats["frames"] += len(whole)
        except Exception as e:  # noqa: BLE001 - the point is that nothing escapes
            ok = False
            data = data + f" [{type(e).__name__}: {e}]".encode()
        stats["inputs"] += 1
        stats["bytes"] += len(data)
        if not ok:
            stats["failures"] += 1
            if stats["first_failure"] is None:
                stats["first_failure"] = (protocol, data[:300].hex())
    return stats


def main() -> int:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 1_000_000
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    jobs = 2 * (os.cpu_count() or 2)
    per = [n // jobs + (1 if j < n % jobs else 0) for j in range(jobs)]
    t0 = time.perf_counter()
    with Pool(os.cpu_count() or 2) as pool:
        results = pool.map(worker, [(seed * 1000 + j, m) for j, m in enumerate(per)])
    total = {k: sum(r[k] for r in results) for k in ("inputs", "bytes", "frames", "crc_errors", "implausible",
                                                     "implausible_temp", "accepted_beyond", "failures")}
    wall = time.perf_counter() - t0
    print(f"inputs {total['inputs']:,}  bytes {total['bytes']:,}  frames accepted {total['frames']:,}  "
          f"KVH CRC rejections {total['crc_errors']:,}  in {wall:.1f} s")
    print(f"implausible samples counted invalid {total['implausible']:,}  KVH implausible temperatures "
          f"{total['implausible_temp']:,}  accepted beyond the gate {total['accepted_beyond']:,}")
    bad = [r["first_failure"] for r in results if r["first_failure"]]
    if total["failures"] or total["inputs"] < n:
        print(f"FAIL: {total['failures']} inputs failed; first: {bad[0] if bad else None}")
        return 1
    print("PASS: no exception escaped; KVH output == reference scan (no bad-CRC frame accepted, none missed); "
          "ASCII parsers chunking-invariant and bounded; no implausible rate or temperature accepted, every "
          "implausible valid sample counted")
    return 0


if __name__ == "__main__":
    sys.exit(main())
