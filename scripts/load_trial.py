#!/usr/bin/env python3
"""Loads a trial converted by `smocap convert` into NumPy / pandas (the README's recipe).

    pip install mcap mcap-protobuf-support numpy pandas     # in a venv outside the repository
    python3 scripts/load_trial.py smocap-out/synthetic/subj01/walk01.mcap

`load(path)` returns (q, stats, subject): q a DataFrame of every coordinate (rad or m) indexed by
frame time (s since the trial's first sample), stats a DataFrame of the solver statistics
(marker RMSE in m, iterations, status, ...), subject the decoded smocap.Subject message (names,
calibrated scales). Without pandas it returns NumPy arrays and the column names instead.
"""

import sys

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

try:
    import pandas as pd
except ImportError:
    pd = None

STATS = ["iterations", "accepted_steps", "energy", "rmse", "markers_used", "status", "bridged", "marker_rmse"]


def load(path):
    msgs = {t: [] for t in ("/smocap/subject", "/smocap/state", "/smocap/stats")}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, m in reader.iter_decoded_messages(topics=list(msgs)):
            msgs[channel.topic].append(m)
    subject = msgs["/smocap/subject"][0]
    time = np.array([s.time for s in msgs["/smocap/state"]])
    q = np.array([s.q for s in msgs["/smocap/state"]])
    stats = np.array([[getattr(s, k) for k in STATS] for s in msgs["/smocap/stats"]], dtype=float)
    if pd is None:
        return (time, q, list(subject.coordinates)), (stats, STATS), subject
    index = pd.Index(time, name="time_s")
    return (
        pd.DataFrame(q, columns=list(subject.coordinates), index=index),
        pd.DataFrame(stats, columns=STATS, index=index),
        subject,
    )


if __name__ == "__main__":
    q, stats, subject = load(sys.argv[1])
    print(f"{subject.dataset}/{subject.trial}: {len(subject.coordinates)} coordinates, {len(subject.bodies)} bodies")
    print(q.iloc[:3, :6] if pd is not None else q[1][:3, :6])
    print(stats.describe().loc[["mean", "max"], ["marker_rmse", "iterations"]] if pd is not None else "")
