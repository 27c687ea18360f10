"""Codecs: a device's bytes or CAN frames -> ``Frames`` in deg/h (fogmon.sources.frames):
KVH binary (``kvh``), DSP-3000 ASCII (``dsp3000``), column-mapped lines (``lines``),
their line framing (``framing``), a DBC-described CAN gyro (``can``); ``protocols`` is
the table of serial protocol names -> codecs."""
