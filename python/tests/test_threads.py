"""The GIL is released while Rust works: Python threads solve at once, and get the results they
get one after the other."""

import threading
import time

import numpy as np

import smocap


def test_two_threads_solving_at_once_give_the_serial_results(synthetic, long_synthetic):
    subject = smocap.calibrate(None, [synthetic, long_synthetic])
    serial = [subject.solve(t, threads=1).q for t in (synthetic, long_synthetic)]
    results = [None, None]
    errors = []

    def solve(i, trial):
        try:
            results[i] = subject.solve(trial, threads=1).q
        except Exception as e:  # noqa: BLE001 - reported by the assertion below
            errors.append(e)

    threads = [threading.Thread(target=solve, args=(i, t)) for i, t in enumerate((synthetic, long_synthetic))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    for got, want in zip(results, serial):
        assert np.array_equal(got.to_numpy(), want.to_numpy()) and list(got.columns) == list(want.columns)


def test_python_runs_while_a_trial_is_solved(long_synthetic):
    subject = smocap.calibrate(None, [long_synthetic])
    started, stop = threading.Event(), threading.Event()
    spans = []

    def solve():
        started.set()
        while not stop.is_set():
            t0 = time.perf_counter()
            subject.solve(long_synthetic, threads=1)
            spans.append((t0, time.perf_counter()))

    worker = threading.Thread(target=solve)
    worker.start()
    started.wait()
    time.sleep(0.05)
    # This line runs inside a solve only if the solve released the GIL.
    now = time.perf_counter()
    stop.set()
    worker.join()
    assert any(t0 < now < t1 - 0.02 for t0, t1 in spans), (now, spans)
