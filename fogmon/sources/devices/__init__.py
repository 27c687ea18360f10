"""Live sources: a serial gyro (``serial_port``), a CAN gyro on a bus (``can_bus``), and a
simulated gyro streamed like one (``simulated``). Opened by fogmon.sources.open."""
