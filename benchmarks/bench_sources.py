"""Throughput of the source layer, as ratios to a reference measured in the same run.

- KVH Format A decoder (CRC check, resync, conversion) vs a bare ``struct.unpack_from``
  loop over the same frames (no CRC, no search: a lower bound on the cost of reading).
- Raw-capture replay (decoder + sample grid + blocks) in samples/s, as a multiple of a
  1 kHz gyro's real time.
- CAN decoding with the example DBC (cantools) in frames/s.

    python benchmarks/bench_sources.py [N_FRAMES]
"""
from __future__ import annotations

import os
import struct
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from fogmon.sources.codecs.kvh import KvhCodec, encode_frame  # noqa: E402
from fogmon.sources.files.capture import RawCaptureSource  # noqa: E402


def timed(fn, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 200_000
    data = b"".join(encode_frame("a", k % 128, (1e-6 * k,) * 3) for k in range(n))
    layout = struct.Struct(">4x6fBBhI")

    def bare():
        for i in range(0, len(data), 36):
            layout.unpack_from(data, i)

    def codec():
        c = KvhCodec("a")
        for i in range(0, len(data), 1 << 16):
            c.feed(data[i:i + (1 << 16)])

    t_ref, t_dec = timed(bare), timed(codec)
    print(f"KVH A decode: {n / t_dec:,.0f} frames/s; bare struct loop {n / t_ref:,.0f} frames/s; "
          f"decoder costs {t_dec / t_ref:.2f}x the bare unpack")
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "cap.bin")
        with open(p, "wb") as fh:
            fh.write(data)
        t_rep = timed(lambda: sum(len(b) for b in RawCaptureSource(p, {"protocol": "kvh-a"}).blocks()))
    print(f"raw-capture replay: {n / t_rep:,.0f} samples/s = {n / t_rep / 1000:,.0f}x real time of a 1 kHz gyro")
    from importlib import resources

    import can

    from fogmon.sources.codecs.can import CanDecoder, load_dbc
    db = load_dbc(str(resources.files("fogmon") / "data" / "gyro_example.dbc"))
    m = db.get_message_by_name("GYRO_RATE")
    nc = min(n, 50_000)
    msgs = [can.Message(timestamp=k / 100, arbitration_id=0x100, is_extended_id=False,
                        data=m.encode({"rate": 1e-3 * (k % 1000), "temperature": 25, "counter": k % 16, "valid": 1}))
            for k in range(nc)]
    t_can = timed(lambda: CanDecoder(db).feed(msgs))
    t_cref = timed(lambda: [m.decode(x.data) for x in msgs])
    print(f"CAN decode: {nc / t_can:,.0f} frames/s; bare cantools decode {nc / t_cref:,.0f} frames/s; "
          f"ratio {t_can / t_cref:.2f}x")


if __name__ == "__main__":
    main()
