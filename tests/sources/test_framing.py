"""Line framing holds at most ``max_line`` bytes, however long a device sends without a
newline: an over-long line is one counted framing error, not unbounded buffering."""
from fogmon.sources.codecs.dsp3000 import Dsp3000Codec
from fogmon.sources.codecs.framing import LineFramer


def test_an_endless_line_fed_in_pieces_stays_bounded_and_counts_once():
    fr = LineFramer(64)
    most = 0
    for _ in range(256):                              # 1 MiB without a newline, 4 KiB at a time
        assert fr.feed(b"\x00" * 4096) == []
        most = max(most, fr.pending)
    assert most <= 64 and fr.dropped_lines == 1
    assert fr.feed(b"tail\n  0.5 1\n") == [b"  0.5 1\n"]  # the rest of the long line goes, the next line is kept
    assert fr.dropped_lines == 1 and fr.dropped_bytes == (1 << 20) + len(b"tail\n")


def test_dsp3000_counts_an_endless_line_as_one_bad_line():
    c = Dsp3000Codec()
    for _ in range(64):
        c.feed(b"9" * 1000)
    f = c.feed(b"\r\n   0.25   1\r\n")
    assert list(f.rate_dph) == [900.0] and c.counters["bad_lines"] == 1 and c.pending == 0
    assert c.counters["bytes_skipped"] == 64_000 + 2
