"""argparse value types with their ranges: a wrong value (nan, inf, out of range, wrong
type) is a usage error naming the option (exit 2) before any work starts."""
from __future__ import annotations

import argparse
import math


def number(lo: float | None = None, hi: float | None = None, *, integer: bool = False, above: bool = False,
           below: bool = False):
    """argparse ``type=``: a finite float (an int with ``integer``) with lo <= v <= hi
    (lo < v with ``above``, v < hi with ``below``); None leaves a side open."""
    kind = "an integer" if integer else "a finite number"

    def fmt(v: float) -> str:
        if not integer:
            return f"{v:g}"
        return f"{int(v):,}" if abs(v) >= 100_000 else str(int(v))

    if lo is not None and hi is not None and not above and not below:
        rule = f"{kind} in {fmt(lo)}..{fmt(hi)}"
    else:
        bounds = ([f"{'>' if above else '>='} {fmt(lo)}"] if lo is not None else []) + \
            ([f"{'<' if below else '<='} {fmt(hi)}"] if hi is not None else [])
        rule = f"{kind} {' and '.join(bounds)}".strip()

    def parse(text: str):
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {rule}, got {text!r}") from None
        in_lo = lo is None or (v > lo if above else v >= lo)
        in_hi = hi is None or (v < hi if below else v <= hi)
        if not (math.isfinite(v) and in_lo and in_hi):
            raise argparse.ArgumentTypeError(f"must be {rule}, got {text!r}")
        return v

    return parse


#: > 0 and finite: lengths, durations, rates.
positive = number(0, above=True)
