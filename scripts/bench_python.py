#!/usr/bin/env python3
"""Speed of the Python binding against the command line, measured side by side (BENCHMARKS.md).

    pip install .                                           # release build of the package
    cargo build --release                                   # the command line to compare against
    python scripts/bench_python.py --smocap target/release/smocap [--frames 10000] [--reps 5]

1. Per-frame speed: one synthetic trial of `--frames` frames (`smocap synth`, shipped model),
   solved by `smocap solve --threads T` (frames / the report's `solve_wall_s`: calibration and
   file reading excluded) and by `Subject.solve(Markers(...), threads=T)` from NumPy arrays (frames /
   the call's wall time: building the `Markers` from the arrays, conversion, solve and results
   included; calibration excluded), alternating, `--reps` times each, for T = 1 and T = 2.
2. Threads: two trials of `--frames / 2` frames each, solved with `threads=1` one after the other,
   and by two Python threads at once; the ratio of the medians (parallel / serial).

Prints a table, and the load average before and after (the machine may be shared).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import smocap


def synth(exe, frames, seed, out):
    subprocess.run(
        [exe, "synth", "--frames", str(frames), "--noise-mm", "2", "--seed", str(seed), "--out", str(out),
         "--truth", str(out.with_suffix(".json"))],
        check=True, capture_output=True,
    )


def cli_fps(exe, trial, threads, tmp):
    report = tmp / "report.json"
    subprocess.run(
        [exe, "solve", str(trial), "--threads", str(threads), "--backend", "cpu", "--report-json", str(report)],
        check=True, capture_output=True,
    )
    t = json.loads(report.read_text())["trials"][0]
    return t["frames"] / t["solve_wall_s"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smocap", default="target/release/smocap", help="the smocap binary")
    ap.add_argument("--frames", type=int, default=10000)
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args()
    exe = str(Path(a.smocap).resolve())
    print(f"load average before: {os.getloadavg()}", flush=True)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        trial = tmp / "walk.trc"
        synth(exe, a.frames, 5, trial)
        m = smocap.read_markers(trial)
        labels, xyz, rate, units = m.labels, m.xyz, m.rate_hz, m.units  # NumPy arrays from here on
        subject = smocap.calibrate(None, [smocap.Markers(labels, xyz, rate, units=units)])
        print(f"trial: {len(m)} frames, {len(labels)} markers; {subject}", flush=True)
        rows = []
        for threads in (1, 2):
            cli, py = [], []
            for _ in range(a.reps):
                cli.append(cli_fps(exe, trial, threads, tmp))
                t0 = time.perf_counter()
                motion = subject.solve(smocap.Markers(labels, xyz, rate, units=units), threads=threads)
                py.append(len(motion) / (time.perf_counter() - t0))
            c, p = statistics.median(cli), statistics.median(py)
            rows.append((threads, c, p))
            print(f"threads={threads}: CLI {c:.0f} frames/s, Python {p:.0f} frames/s, Python/CLI {p / c:.3f} "
                  f"(CLI {[round(x) for x in cli]}, Python {[round(x) for x in py]})", flush=True)

        half = [tmp / "a.trc", tmp / "b.trc"]
        for seed, p in zip((6, 7), half):
            synth(exe, a.frames // 2, seed, p)
        inputs = [smocap.read_markers(p) for p in half]
        subject2 = smocap.calibrate(None, inputs)
        serial, parallel, busy, busy1 = [], [], [], []
        for _ in range(a.reps):
            t0, c0 = time.perf_counter(), time.process_time()
            for x in inputs:
                subject2.solve(x, threads=1)
            serial.append(time.perf_counter() - t0)
            busy1.append((time.process_time() - c0) / serial[-1])
            ts = [threading.Thread(target=subject2.solve, args=(x,), kwargs={"threads": 1}) for x in inputs]
            t0, c0 = time.perf_counter(), time.process_time()
            for t in ts:
                t.start()
            for t in ts:
                t.join()
            parallel.append(time.perf_counter() - t0)
            busy.append((time.process_time() - c0) / parallel[-1])
        s, p = statistics.median(serial), statistics.median(parallel)
        print(f"two trials of {a.frames // 2} frames, threads=1 each: one after the other {s:.2f} s, two Python "
              f"threads at once {p:.2f} s, ratio {p / s:.3f}; cores busy: {statistics.median(busy1):.2f} one after the "
              f"other, {statistics.median(busy):.2f} at once "
              f"(serial {[round(x, 2) for x in serial]}, parallel {[round(x, 2) for x in parallel]})", flush=True)
        c1, c2 = rows[0][1], rows[1][1]
        print(f"for comparison, the CLI's own speed-up from 1 to 2 threads in this run: {c2 / c1:.2f}", flush=True)
    print(f"load average after: {os.getloadavg()}; cores: {os.cpu_count()}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
