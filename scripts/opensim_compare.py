#!/usr/bin/env python3
"""Side-by-side comparison of smocap against OpenSim 4.6 (Scale + IK) on the shared datasets.

Runs, in one process and one after the other on the same machine:
  - OpenSim's InverseKinematicsTool on the OpenSim-scaled model from ../shared/reference, with the
    dataset's IK setup, timed over the whole trial and over its first frame (marginal ms/frame =
    difference / (frames - 1); model loading excluded), `repeats` times (median reported);
  - `smocap solve` (release binary) from the GENERIC model + static trial + motion trial with the
    dataset's Scale and IK setups, one thread, `repeats` times; its ms/frame is the solve wall time
    per frame (calibration and file I/O excluded), median over runs.
Prints a table (marker RMSE mean, ms/frame, ratio) and writes JSON when --json is given.

Needs: `pip install opensim==4.6` (the official wheel), and `cargo build --release`.
Usage: python3 scripts/opensim_compare.py [--repeats 5] [--json out.json]
"""
import argparse, json, os, statistics, subprocess, sys, tempfile, time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared")
BIN = os.path.join(ROOT, "target", "release", "smocap")

DATASETS = [
    dict(name="gait2354_subject01 walk1",
         generic="datasets/gait2354_subject01/gait2354_simbody.osim",
         scale_setup="datasets/gait2354_subject01/subject01_Setup_Scale.xml",
         markerset="datasets/gait2354_subject01/gait2354_Scale_MarkerSet.xml",
         static="datasets/gait2354_subject01/subject01_static.trc",
         trial="datasets/gait2354_subject01/subject01_walk1.trc",
         ik_setup="datasets/gait2354_subject01/subject01_Setup_IK.xml",
         scaled="reference/opensim-4.6/gait2354_subject01/subject01_scaled_by_opensim.osim",
         summary="reference/opensim-4.6/gait2354_subject01/subject01_walk1_summary.json"),
    dict(name="rajagopal2016_walk",
         generic="datasets/rajagopal2016_walk/Rajagopal2016.osim",
         scale_setup="datasets/rajagopal2016_walk/scale_setup_walk_scaleOnly.xml",
         markerset="datasets/rajagopal2016_walk/markerset_walk_preScale.xml",
         static="datasets/rajagopal2016_walk/static_walk_1.trc",
         trial="datasets/rajagopal2016_walk/motion_capture_walk.trc",
         ik_setup="datasets/rajagopal2016_walk/ik_setup_walk.xml",
         scaled="reference/opensim-4.6/rajagopal2016_walk/subject_scaled_walk_by_opensim.osim",
         summary="reference/opensim-4.6/rajagopal2016_walk/motion_capture_walk_summary.json"),
]


def s(rel):
    return os.path.join(SHARED, rel)


def opensim_ik_seconds(osim, d, t1, out_dir):
    """Seconds for OpenSim IK from t0 to t1 (model loaded before timing)."""
    model = osim.Model(s(d["scaled"]))
    model.initSystem()
    ik = osim.InverseKinematicsTool(s(d["ik_setup"]))
    ik.setModel(model)
    ik.set_marker_file(s(d["trial"]))
    ik.setStartTime(0.0)
    ik.setEndTime(t1)
    ik.setResultsDir(out_dir)
    ik.setOutputMotionFileName(os.path.join(out_dir, "ik.mot"))
    start = time.perf_counter()
    ik.run()
    return time.perf_counter() - start


def trial_times(path):
    rows = []
    with open(path) as f:
        for i, line in enumerate(f):
            if i >= 5:
                p = line.split("\t")
                if len(p) > 2 and p[1].strip():
                    rows.append(float(p[1]))
    return rows


def smocap_run(d, report):
    cmd = [BIN, "solve", "--model", s(d["generic"]), "--scale-setup", s(d["scale_setup"]),
           "--markerset", s(d["markerset"]), "--static", s(d["static"]), "--ik-setup", s(d["ik_setup"]),
           "--threads", "1", "--report-json", report, s(d["trial"])]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t = json.load(open(report))["trials"][0]
    return t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json")
    a = ap.parse_args()
    import opensim as osim
    osim.Logger.setLevelString("error")
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for d in DATASETS:
            times = trial_times(s(d["trial"]))
            n = len(times)
            marginal = []
            ours = []
            for _ in range(a.repeats):
                full = opensim_ik_seconds(osim, d, times[-1], tmp)
                one = opensim_ik_seconds(osim, d, times[0], tmp)
                marginal.append((full - one) / (n - 1) * 1e3)
                t = smocap_run(d, os.path.join(tmp, "r.json"))
                ours.append(t["solve_wall_s"] / t["frames"] * 1e3)
            ref = json.load(open(s(d["summary"])))
            row = dict(dataset=d["name"], frames=n,
                       opensim_ms_per_frame=statistics.median(marginal),
                       smocap_ms_per_frame=statistics.median(ours),
                       opensim_rmse_mean_mm=ref["rms_mean_m"] * 1e3,
                       smocap_rmse_mean_mm=t["marker_rmse_mm"]["mean"])
            row["speedup"] = row["opensim_ms_per_frame"] / row["smocap_ms_per_frame"]
            out.append(row)
    print(f"{'dataset':28} {'frames':>6} {'OpenSim ms/f':>12} {'smocap ms/f':>12} {'ratio':>7} "
          f"{'OpenSim RMSE':>12} {'smocap RMSE':>12}")
    for r in out:
        print(f"{r['dataset']:28} {r['frames']:6} {r['opensim_ms_per_frame']:12.3f} {r['smocap_ms_per_frame']:12.4f} "
              f"{r['speedup']:6.0f}x {r['opensim_rmse_mean_mm']:10.2f}mm {r['smocap_rmse_mean_mm']:10.2f}mm")
    if a.json:
        json.dump(out, open(a.json, "w"), indent=1)


if __name__ == "__main__":
    sys.exit(main())
