"""Oriented points for the screened-Poisson peer of benches/realscans/run.sh (Open3D).

Usage: normals.py IN OUT.ply [--knn 15]

Reads IN (PLY/XYZ; Open3D's reader), keeps its normals when it has them, otherwise estimates them
(PCA of the 15 nearest neighbours, `estimate_normals`) and orients them
(`orient_normals_consistent_tangent_plane(15)`, Hoppe et al.'s MST propagation), and writes a binary
PLY with float x y z nx ny nz for PoissonRecon. Prints one JSON line:
{"points", "estimated_normals", "seconds" (estimation + orientation, reading/writing excluded)}.
"""
import argparse
import json
import sys
import time

import open3d as o3d


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--knn", type=int, default=15)
    a = ap.parse_args()
    fmt = "xyz" if a.input.endswith(".xyz") else "auto"
    pcd = o3d.io.read_point_cloud(a.input, format=fmt)
    if len(pcd.points) == 0:
        print(f"normals.py: no points in {a.input}", file=sys.stderr)
        return 1
    t0 = time.perf_counter()
    estimated = not pcd.has_normals()
    if estimated:
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=a.knn))
        pcd.orient_normals_consistent_tangent_plane(a.knn)
    t1 = time.perf_counter()
    out = o3d.geometry.PointCloud()
    out.points = pcd.points
    out.normals = pcd.normals
    if not o3d.io.write_point_cloud(a.output, out, write_ascii=False):
        print(f"normals.py: could not write {a.output}", file=sys.stderr)
        return 1
    print(json.dumps({"points": len(pcd.points), "estimated_normals": estimated,
                      "seconds": round(t1 - t0, 3)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
