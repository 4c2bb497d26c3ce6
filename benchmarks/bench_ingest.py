"""JointState ingest speed: the chunk-level numpy fast path against the stock mcap_ros2 decoder.

Generates (in a temporary folder) a log of N JointState messages (7 joints, position and
velocity, zstd chunks) with ``write_run``, then decodes it in a fresh subprocess per path so
that each peak memory (VmHWM) is its own:

* ``fast``: ``read_joint_log`` (chunk decompression + vectorised CDR decode + JointLog build);
* ``stock``: ``mcap.reader`` + ``mcap_ros2.decoder.DecoderFactory`` over the first M messages
  (``--stock-messages``, default 100k), positions and velocities collected into arrays.

Usage: ``python benchmarks/bench_ingest.py [--messages N] [--stock-messages M]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def generate(path: Path, n: int) -> float:
    import numpy as np

    from wholearm_tools.logs import JointLog, Run, write_run
    from wholearm_tools.robot import RobotModel

    spec = {"joints": [{"name": f"joint_{i + 1}", "origin": [0.2 * (i > 0), 0, 0],
                        "radius": 0.03} for i in range(7)], "tip": {"offset": [0.1, 0, 0]}}
    robot = RobotModel.from_spec(spec, name="bench7")
    t = np.arange(n) * 1e-3
    phase = np.arange(7) * 0.3
    q = np.sin(t[:, None] * 0.5 + phase)
    qd = 0.5 * np.cos(t[:, None] * 0.5 + phase)
    log = JointLog(robot.joint_names, t, q, qd, t0_ns=1_700_000_000 * 10**9)
    start = time.perf_counter()
    write_run(path, Run(robot=robot, log=log), compression="zstd")
    return time.perf_counter() - start


def peak_rss_kb() -> int:
    """Peak resident memory of this process in kB (VmHWM: unlike ru_maxrss it is not inherited
    from the parent across fork + exec)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def worker(kind: str, path: str, limit: int) -> dict:
    import numpy as np
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from wholearm_tools.logs import read_joint_log

    baseline_kb = peak_rss_kb()
    start = time.perf_counter()
    if kind == "fast":
        log = read_joint_log(path)
        count, checksum = log.n_samples, float(log.q.sum() + log.qd.sum())
    else:
        positions, velocities, stamps = [], [], []
        with open(path, "rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            for _, _, _, msg in reader.iter_decoded_messages(topics=["/joint_states"]):
                stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
                positions.append(msg.position)
                velocities.append(msg.velocity)
                if len(stamps) >= limit:
                    break
        q, qd = np.array(positions), np.array(velocities)
        count, checksum = len(stamps), float(q.sum() + qd.sum())
    elapsed = time.perf_counter() - start
    peak_kb = peak_rss_kb()
    return {"kind": kind, "messages": count, "seconds": elapsed, "rate": count / elapsed,
            "peak_mb": peak_kb / 1024,
            "extra_mb": (peak_kb - baseline_kb) / 1024, "checksum": checksum}


def run_worker(kind: str, path: Path, limit: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--worker", kind, str(path), str(limit)],
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=1_000_000)
    parser.add_argument("--stock-messages", type=int, default=100_000)
    parser.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        kind, path, limit = args.worker
        print(json.dumps(worker(kind, path, int(limit))))
        return
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.mcap"
        write_s = generate(path, args.messages)
        size_mb = path.stat().st_size / 2**20
        print(f"log: {args.messages} JointState messages (7 joints, zstd), {size_mb:.1f} MB, "
              f"written in {write_s:.2f} s ({args.messages / write_s:,.0f} msg/s)")
        fast = run_worker("fast", path, args.messages)
        stock = run_worker("stock", path, min(args.stock_messages, args.messages))
    decoded_mb = args.messages * 7 * 2 * 8 / 2**20
    print(f"{'path':<28}{'messages':>10}{'seconds':>10}{'msg/s':>14}{'peak RSS MB':>14}"
          f"{'above imports':>15}")
    for name, r in (("fast (read_joint_log)", fast), ("stock mcap_ros2 decoder", stock)):
        print(f"{name:<28}{r['messages']:>10}{r['seconds']:>10.2f}{r['rate']:>14,.0f}"
              f"{r['peak_mb']:>14.0f}{r['extra_mb']:>15.0f}")
    print(f"speed-up: {fast['rate'] / stock['rate']:.1f}x (target >= 10x); decoded q+qd arrays "
          f"alone are {decoded_mb:.0f} MB")


if __name__ == "__main__":
    main()
