#!/usr/bin/env python3
"""Synthetic single-view range scans of a mesh, in the Stanford range-grid PLY layout.

    python3 benches/range_images.py MESH.off OUT_PREFIX [--azimuth 0] [--elevation 20]
                                    [--pixels 400] [--noise 1e-4] [--grazing 80] [--seed 1]

A perspective camera 2.5 diagonals from the mesh's centre, looking at it from `--azimuth` degrees
around the vertical (y) axis and `--elevation` degrees above it, sees a z-buffer of dense
area-uniform surface samples (about 40 per covered pixel): per pixel the nearest sample, kept
when the surface there faces the camera less than `--grazing` degrees off the view ray (a
scanner loses steeper returns), moved along its ray by Gaussian depth noise of `--noise` times the
diagonal. Writes OUT_PREFIX.ply (ASCII: `obj_info num_cols/num_rows`, the points, and a
`range_grid` element with one optional vertex index per pixel, rows bottom to top, as Stanford's
scans; `benches/range_pieces.py` reads it) and OUT_PREFIX.xyz (the points alone, what the
reconstruction gets). MESH.off: an OFF triangle mesh (e.g. the CGAL data that
benches/realscans/prepare.sh unpacks into target/realscans/cache/cgal/data/meshes). Needs numpy.
"""

import argparse
import os
import sys

import numpy as np

# Camera distance from the mesh's centre, in bounding-box diagonals.
DISTANCE = 2.5

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "realscans"))
from prepare import read_off  # noqa: E402


def camera(v, azimuth, elevation):
    """Eye position and an orthonormal frame (right, up, forward) looking at the box centre."""
    lo, hi = v.min(0), v.max(0)
    centre, diag = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    a, e = np.radians(azimuth), np.radians(elevation)
    back = np.array([np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)])
    eye = centre + DISTANCE * diag * back
    fwd = -back
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return eye, (right, up, fwd), diag


def scan(v, f, a):
    rng = np.random.default_rng(a.seed)
    eye, (right, up, fwd), diag = camera(v, a.azimuth, a.elevation)
    tri = v[f]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(normal, axis=1)
    normal /= np.maximum(2 * area, 1e-300)[:, None]
    # The view fits the bounding sphere in 90 % of the image.
    focal = 0.45 * a.pixels / np.tan(np.arcsin(0.5 / DISTANCE))
    n = 40 * a.pixels * a.pixels
    pick = rng.choice(len(f), size=n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    p = (tri[pick, 0] * (1 - r1)[:, None] + tri[pick, 1] * (r1 * (1 - r2))[:, None]
         + tri[pick, 2] * (r1 * r2)[:, None])
    d = p - eye
    depth = d @ fwd
    col = np.floor(a.pixels / 2 + focal * (d @ right) / depth).astype(np.int64)
    row = np.floor(a.pixels / 2 + focal * (d @ up) / depth).astype(np.int64)
    inside = (col >= 0) & (col < a.pixels) & (row >= 0) & (row < a.pixels)
    pix = np.where(inside, row * a.pixels + col, -1)
    order = np.lexsort((depth, pix))
    pix_sorted = pix[order]
    first = np.ones(n, dtype=bool)
    first[1:] = pix_sorted[1:] != pix_sorted[:-1]
    front = order[first & (pix_sorted >= 0)]
    ray = d[front] / np.linalg.norm(d[front], axis=1)[:, None]
    seen = np.abs(np.sum(ray * normal[pick[front]], axis=1)) >= np.cos(np.radians(a.grazing))
    front, ray = front[seen], ray[seen]
    points = p[front] + ray * rng.normal(0.0, a.noise * diag, size=len(front))[:, None]
    return points, pix[front]


def write(prefix, points, pix, pixels):
    grid = -np.ones(pixels * pixels, dtype=np.int64)
    grid[pix] = np.arange(len(pix))
    with open(prefix + ".ply", "w") as out:
        out.write("ply\nformat ascii 1.0\n")
        out.write(f"obj_info num_cols {pixels}\nobj_info num_rows {pixels}\n")
        out.write(f"element vertex {len(points)}\nproperty float x\nproperty float y\n"
                  "property float z\n")
        out.write(f"element range_grid {pixels * pixels}\n"
                  "property list uchar int vertex_indices\nend_header\n")
        out.writelines(f"{x:.7g} {y:.7g} {z:.7g}\n" for x, y, z in points)
        out.writelines("0\n" if g < 0 else f"1 {g}\n" for g in grid)
    np.savetxt(prefix + ".xyz", points, fmt="%.7g")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("prefix")
    ap.add_argument("--azimuth", type=float, default=0.0)
    ap.add_argument("--elevation", type=float, default=20.0)
    ap.add_argument("--pixels", type=int, default=400)
    ap.add_argument("--noise", type=float, default=1e-4)
    ap.add_argument("--grazing", type=float, default=80.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    verts, faces = read_off(a.mesh)
    v, f = np.array(verts, dtype=float), np.array(faces, dtype=np.int64)
    points, pix = scan(v, f, a)
    write(a.prefix, points, pix, a.pixels)
    print(f"{a.prefix}: {len(points)} points")


if __name__ == "__main__":
    main()
