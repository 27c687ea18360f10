"""Reference for bench_pipeline.py's "before the first sample": the CPU s of a process
(interpreter start-up included) that only imports numpy and the Rerun SDK, opens an .rrd
and sends one block of samples to it, as any program putting a gyro's first block into
a Rerun recording must. Prints ``first_sample=<CPU s>`` and ``rc=0`` (replay_split.py's
``key=value`` lines).

    python benchmarks/rerun_floor.py RRD [SAMPLES]
"""
import sys
import time

import numpy as np
import rerun as rr


def main() -> None:
    rrd, n = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 8192
    rr.init("rerun_floor", spawn=False)
    rr.save(rrd)
    rr.send_columns("/rate/rate_dph", indexes=[rr.TimeColumn("time", duration=np.arange(n) / 100.0)],
                    columns=rr.Scalars.columns(scalars=np.zeros(n)))
    print(f"first_sample={time.process_time()}")
    print("rc=0")


if __name__ == "__main__":
    main()
