"""Screened Poisson reconstruction (Open3D) of a point file, the peer in benches/large_scans.sh.

Usage: poisson.py IN.ply OUT.ply [--depth 10]

Reads the points (and normals, if the PLY has them), estimates and orients normals when missing
(estimate_normals + orient_normals_consistent_tangent_plane, k = 15), runs
create_from_point_cloud_poisson(depth) and writes the mesh as PLY. Prints one JSON line:
{"seconds": wall time of the reconstruction including normal estimation (reading and writing
excluded), "read_s", "write_s", "peak_rss_mib": ru_maxrss of this process, "vertices",
"triangles", "estimated_normals"}.
"""

import argparse
import json
import resource
import sys
import time

import open3d as o3d


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--depth", type=int, default=10)
    a = ap.parse_args()

    t0 = time.perf_counter()
    pcd = o3d.io.read_point_cloud(a.input)
    if len(pcd.points) == 0:
        print(f"poisson.py: no points in {a.input}", file=sys.stderr)
        return 1
    t1 = time.perf_counter()
    estimated = not pcd.has_normals()
    if estimated:
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=15))
        pcd.orient_normals_consistent_tangent_plane(15)
    mesh, _densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pcd, depth=a.depth
    )
    t2 = time.perf_counter()
    if not o3d.io.write_triangle_mesh(a.output, mesh, write_ascii=False):
        print(f"poisson.py: could not write {a.output}", file=sys.stderr)
        return 1
    t3 = time.perf_counter()
    # ru_maxrss is in KiB on Linux.
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(
        json.dumps(
            {
                "seconds": round(t2 - t1, 3),
                "read_s": round(t1 - t0, 3),
                "write_s": round(t3 - t2, 3),
                "peak_rss_mib": round(rss, 1),
                "vertices": len(mesh.vertices),
                "triangles": len(mesh.triangles),
                "estimated_normals": estimated,
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
