#!/usr/bin/env python3
"""Loads a trial converted by `smocap convert` into NumPy / pandas (the recipe of
docs/guide/python.md), with the smocap Python package (`smocap.read_trial`).

    pip install .                                  # at the repository root, in a virtual env
    python3 scripts/load_trial.py smocap-out/synthetic/subj01/walk01.mcap

`load(path)` returns (q, stats, subject): q a DataFrame of every coordinate (rad or m) indexed by
frame time (s, as in the input file), stats a DataFrame of the solver statistics (marker RMSE in
m, iterations, status, ...), subject a dict of names (coordinates, bodies, markers, ...) and the
calibrated scales by body.
"""

import sys

import smocap


def load(path):
    trial = smocap.read_trial(path)
    return trial.q, trial.stats, trial.subject


if __name__ == "__main__":
    q, stats, subject = load(sys.argv[1])
    print(f"{subject['dataset']}/{subject['trial']}: {len(subject['coordinates'])} coordinates, {len(subject['bodies'])} bodies")
    print(q.iloc[:3, :6])
    print(stats.describe().loc[["mean", "max"], ["marker_rmse", "iterations"]])
