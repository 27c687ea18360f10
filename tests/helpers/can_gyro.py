"""The example gyro of fogmon/data/gyro_example.dbc on a CAN bus: its DBC file and the
frames it sends (python-can Messages), for the CAN source, archive and conformance tests."""
from __future__ import annotations

from importlib import resources

import can

from fogmon.sources.codecs.can import load_dbc

DBC = str(resources.files("fogmon") / "data" / "gyro_example.dbc")
FS = 100.0     # GenMsgCycleTime 10 ms in the example DBC


def gyro_msgs(ks, t0=1_000_000.0, invalid=(), extra=True):
    """Frames of the example gyro: frame k carries rate k * 0.001 deg/s (= 3.6 k deg/h),
    counter k % 16, timestamp t0 + k / FS; plus a foreign frame and a short frame."""
    m = load_dbc(DBC).get_message_by_name("GYRO_RATE")
    out = []
    for k in ks:
        data = m.encode({"rate": 0.001 * k, "temperature": 20 + 0.01 * k, "counter": k % 16,
                         "valid": int(k not in invalid)})
        out.append(can.Message(timestamp=t0 + k / FS, arbitration_id=0x100, is_extended_id=False, data=data))
        if extra and k == 3:
            out.append(can.Message(timestamp=t0 + k / FS + 1e-3, arbitration_id=0x200, is_extended_id=False,
                                   data=b"\1\2"))
            out.append(can.Message(timestamp=t0 + k / FS + 2e-3, arbitration_id=0x100, is_extended_id=False,
                                   data=b"\1\2\3"))
    return out
