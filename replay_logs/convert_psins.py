"""Rebuild replay_logs/lasergyro_z_100hz.csv from the PSINS ring-laser-gyro file.

Usage: python replay_logs/convert_psins.py PATH/TO/lasergyro.imu replay_logs/lasergyro_z_100hz.csv

The PSINS SIMU text file (BSD-2-Clause, (c) 2009-2015 Gongmin Yan) has three parameter
rows, then one row per 10 ms of six integers: gyro increments x/y/z in counts of
0.1 arcsec, then accelerometer increments. One gyro count per 10 ms is
0.1 arcsec / 0.01 s = 10 arcsec/s = 10 deg/h, so rate_dph = 10 * count (exact)."""
from __future__ import annotations

import sys

import numpy as np

from fogmon.formats.replay_log import write_replay_log

ARCSEC_PER_COUNT = 0.1
TS_S = 0.01


def convert(src: str, dst: str) -> None:
    """Write the z-axis rate (deg/h) of a PSINS .imu file as a replay log v1."""
    with open(src, encoding="ascii") as f:
        rows = [ln for ln in f.read().splitlines() if ln.strip() and not ln.startswith("%")]
    counts = np.array([[int(float(x)) for x in r.split()] for r in rows[3:]], dtype=np.int64)
    rate_dph = counts[:, 2] * (ARCSEC_PER_COUNT / TS_S)  # 1 arcsec/s == 1 deg/h
    t_s = np.round(np.arange(len(counts)) * TS_S, 2)
    write_replay_log(dst, t_s, rate_dph, meta={
        "sample_rate_hz": "100",
        "sensor": "navigation-grade ring-laser-gyro IMU, axis Z (up), stationary vehicle with disturbances",
        "source": "PSINS toolbox data/lasergyro.imu (c) 2009-2015 Gongmin Yan, BSD-2-Clause; see replay_logs/README.md",
        "units": "rate_dph = 10 x (0.1 arcsec counts per 10 ms); quantized in steps of 10 deg/h",
    })


if __name__ == "__main__":
    convert(sys.argv[1], sys.argv[2])
