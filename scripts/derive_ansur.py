#!/usr/bin/env python3
"""Derives the anthropometric prior that smocap ships (models/anthropometry/ansur2.toml) from the
ANSUR II public release in ../shared/anthropometry/ (see its SOURCE.md): per sex, the mean and the
covariance of the measurements the landmark files use, with stature (mm) and mass (kg).

Pure Python (no numpy), deterministic: `python3 scripts/derive_ansur.py > models/anthropometry/ansur2.toml`.
"""
import csv
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = os.path.join(HERE, "..", "..", "shared", "anthropometry")
# The measurements a model's landmarks can determine (ANSUR II names, standing posture, mm).
COLUMNS = [
    "stature",
    "weightkg",
    "cervicaleheight",
    "acromialheight",
    "trochanterionheight",
    "lateralfemoralepicondyleheight",
    "lateralmalleolusheight",
    "acromionradialelength",
    "radialestylionlength",
    "biacromialbreadth",
    "footlength",
    "bicristalbreadth",
]


def stats(path):
    rows = []
    with open(path, newline="", encoding="latin-1") as f:
        for r in csv.DictReader(f):
            v = [float(r[c]) for c in COLUMNS]
            v[1] /= 10.0  # weightkg is in tenths of a kilogram
            rows.append(v)
    n = len(rows)
    k = len(COLUMNS)
    mean = [sum(r[i] for r in rows) / n for i in range(k)]
    cov = [[sum((r[i] - mean[i]) * (r[j] - mean[j]) for r in rows) / (n - 1) for j in range(k)] for i in range(k)]
    return n, mean, cov


def main():
    out = sys.stdout
    out.write("# ANSUR II (2012 U.S. Army Anthropometric Survey, public release; Gordon et al. 2014,\n")
    out.write("# NATICK/TR-15/007), as redistributed in nimblephysics data/osim/ANSUR/ (commit c405b056).\n")
    out.write("# Derived by scripts/derive_ansur.py from ../shared/anthropometry/ANSUR_II_{MALE,FEMALE}_Public.csv:\n")
    out.write("# per sex, the sample mean and covariance (n - 1) of these measurements.\n")
    out.write("# Units: millimetres, except weightkg in kilograms. Standing posture.\n\n")
    out.write("columns = [%s]\n" % ", ".join('"%s"' % c for c in COLUMNS))
    for sex, fname in (("male", "ANSUR_II_MALE_Public.csv"), ("female", "ANSUR_II_FEMALE_Public.csv")):
        n, mean, cov = stats(os.path.join(SRC, fname))
        out.write("\n[%s]\nsubjects = %d\n" % (sex, n))
        out.write("mean = [%s]\n" % ", ".join("%.4f" % m for m in mean))
        out.write("covariance = [\n")
        for row in cov:
            out.write("    [%s],\n" % ", ".join("%.4f" % v for v in row))
        out.write("]\n")


if __name__ == "__main__":
    main()
