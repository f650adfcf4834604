#!/usr/bin/env python3
"""Fetches the Unitree G1 29-DoF MJCF (models/robots/g1/g1.xml) and, on request, its meshes,
from the pinned `mjlab` wheel on PyPI (the model is mujoco_menagerie's unitree_g1, BSD-3-Clause,
Unitree Robotics; models/robots/g1/LICENSE). Standard library only.

    python3 scripts/fetch_g1.py            # checks that the committed g1.xml is the wheel's, byte for byte
    python3 scripts/fetch_g1.py --meshes   # also writes the 35 STL meshes to models/robots/g1/assets/
                                           # (19 MB, git-ignored) so MuJoCo can load g1.xml as it is
    python3 scripts/fetch_g1.py --write    # (re)writes g1.xml from the wheel
    python3 scripts/fetch_g1.py --wheel PATH.whl ...   # uses a wheel already on disk

smocap itself needs only g1.xml (kinematics, joint ranges, collision capsules and spheres);
MuJoCo needs the meshes too, because the visual geoms name them.
"""
import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
import zipfile

WHEEL_NAME = "mjlab-1.6.0-py3-none-any.whl"
WHEEL_SPEC = "mjlab==1.6.0"
WHEEL_SHA256 = "03d003854e2f44c48330c6dcf4c2253ff7641bb569747846825a21b9efa8540b"
ROOT = "mjlab/asset_zoo/robots/unitree_g1/xmls/"
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "models", "robots", "g1")


def wheel(path):
    """The pinned wheel: `path`, or pip-downloaded into a temporary folder; its sha256 checked."""
    if path is None:
        tmp = tempfile.mkdtemp(prefix="smocap-g1-")
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "--dest", tmp, WHEEL_SPEC],
                       check=True)
        path = os.path.join(tmp, WHEEL_NAME)
    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    if digest != WHEEL_SHA256:
        sys.exit(f"{path}: sha256 {digest}, expected {WHEEL_SHA256} ({WHEEL_SPEC})")
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--wheel", help="the mjlab wheel on disk (else pip downloads it)")
    ap.add_argument("--meshes", action="store_true", help="write the STL meshes to models/robots/g1/assets/")
    ap.add_argument("--write", action="store_true", help="(re)write g1.xml")
    args = ap.parse_args()
    with zipfile.ZipFile(wheel(args.wheel)) as z:
        xml = z.read(ROOT + "g1.xml")
        target = os.path.join(OUT, "g1.xml")
        if args.write:
            with open(target, "wb") as f:
                f.write(xml)
        with open(target, "rb") as f:
            if f.read() != xml:
                sys.exit(f"{target} differs from {WHEEL_SPEC}'s {ROOT}g1.xml (rerun with --write)")
        print(f"{target}: identical to {WHEEL_SPEC}'s copy")
        if args.meshes:
            meshes = sorted(n for n in z.namelist() if n.startswith(ROOT + "assets/") and n.endswith(".STL"))
            os.makedirs(os.path.join(OUT, "assets"), exist_ok=True)
            for n in meshes:
                with open(os.path.join(OUT, "assets", os.path.basename(n)), "wb") as f:
                    f.write(z.read(n))
            print(f"{len(meshes)} meshes written to {os.path.join(OUT, 'assets')}")


if __name__ == "__main__":
    main()
