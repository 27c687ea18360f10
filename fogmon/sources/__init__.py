"""Sources: devices and files -> Blocks on the uniform sample grid (docs/sources.md).
``codecs/`` decode bytes and CAN frames, ``devices/`` are the live sources, ``files/``
the file readers; ``open`` picks one (the reader table), ``base`` states the contract."""
