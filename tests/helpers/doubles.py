"""Test doubles shared by the test modules: a source serving pre-made blocks, a sink
collecting what the pipeline hands it, white-noise data, and source options from a
command line."""
from __future__ import annotations

import argparse

import numpy as np

from fogmon.block import Block
from fogmon.cli.source_options import add_source_arguments, source_options
from fogmon.sinks.base import Sink
from fogmon.sources.base import OfflineSource
from fogmon.sources.options import SourceOptions


class ListSource(OfflineSource):
    """A finite source serving pre-made blocks (block sizes chosen by the test); with
    ``axes``, ``rate`` has one column per axis (NaN: an invalid sample of that axis)."""

    def __init__(self, t, rate, sizes, sample_rate_hz, aux=None, events=(), interrupt_after=None, axes=()):
        self.name, self.sample_rate_hz, self.counters = "test source", sample_rate_hz, {"frames_ok": 0}
        self.n_samples = len(t)
        self._t, self._r, self._sizes, self._aux = t, rate, sizes, aux or {}
        self._events, self._interrupt_after, self.axes = events, interrupt_after, tuple(axes)
        self.closed = False

    def blocks(self):
        i = 0
        for k, n in enumerate(self._sizes):
            if self._interrupt_after is not None and k == self._interrupt_after:
                raise KeyboardInterrupt
            sl = slice(i, i + n)
            ev = tuple(e for e in self._events if self._t[sl][0] <= e.t_s <= self._t[sl][-1])
            self.counters["frames_ok"] += n
            yield Block.make(self._t[sl], self._r[sl], aux={k2: v[sl] for k2, v in self._aux.items()}, events=ev,
                             axes=self.axes)
            i += n

    def close(self):
        self.closed = True


class Collect(Sink):
    """Keeps everything the pipeline hands it; ``frames_`` of every axis, ``by_axis``
    the frames per axis name ("" for a one-axis stream)."""

    def __init__(self):
        self.info, self.frames_, self.blocks, self.events_, self.summary = None, [], [], [], None
        self.by_axis = {}
        self.counters = []

    def start(self, info):
        self.info = info

    def block(self, b):
        self.blocks.append(b)

    def frames(self, d, fit, t_end, axis=""):
        self.frames_.append((d, fit, t_end))
        self.by_axis.setdefault(axis, []).append((d, fit, t_end))

    def source_counters(self, t_s, counters):
        self.counters.append((t_s, counters))

    def events(self, ev):
        self.events_.extend(ev)

    def finish(self, summary):
        self.summary = summary


def white_noise(n, sample_rate_hz, seed=1, t0=0.0):
    """(t_s, rate_dph): n samples at fs Hz of 3 deg/h bias plus white noise N = 0.05 deg/sqrt(h)."""
    rng = np.random.default_rng(seed)
    return t0 + np.arange(n) / sample_rate_hz, 3.0 + 60 * 0.05 * np.sqrt(sample_rate_hz) * rng.standard_normal(n)


def args_for(*argv: str) -> SourceOptions:
    """The SourceOptions of a command line's source options (e.g. "--protocol", "kvh-a")."""
    p = argparse.ArgumentParser()
    add_source_arguments(p)
    return source_options(p.parse_args(list(argv)))


def archive_in(parent) -> str:
    """The archive folder `fogmon monitor --archive PARENT` made in PARENT: its one
    ``fogmon-archive-*`` folder ("" before there is one)."""
    import glob
    import os

    found = glob.glob(os.path.join(str(parent), "fogmon-archive-*"))
    assert len(found) <= 1, found
    return found[0] if found else ""
