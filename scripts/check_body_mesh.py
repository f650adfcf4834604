#!/usr/bin/env python3
"""Checks posed body meshes written by `smocap export --mesh DIR`: each OBJ is watertight,
consistently wound outward (positive volume), and its volume and height are printed.

    python3 scripts/check_body_mesh.py DIR_OR_FILES...

Needs trimesh (and numpy). Exit status 1 if any mesh is not watertight or winds inward.
"""
import pathlib
import sys

import trimesh


def main(args):
    files = []
    for a in args:
        p = pathlib.Path(a)
        files += sorted(p.glob("*.obj")) if p.is_dir() else [p]
    if not files:
        print("no OBJ files given", file=sys.stderr)
        return 2
    bad = 0
    for f in files:
        m = trimesh.load(f, process=False, force="mesh")
        ok = m.is_watertight and m.is_winding_consistent and m.volume > 0
        bad += not ok
        height = m.bounds[1][2] - m.bounds[0][2]
        print(f"{f.name}: {len(m.vertices)} vertices, {len(m.faces)} triangles, watertight {m.is_watertight}, "
              f"winding consistent {m.is_winding_consistent}, volume {m.volume * 1e3:.2f} L, height {height:.4f} m")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
