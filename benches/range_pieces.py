#!/usr/bin/env python3
"""Compares the sheets of a mesh made from a single-view range scan with the scan's own pieces.

    python3 benches/range_pieces.py SCAN.ply MESH.obj [--break 8] [--min-points 20]

SCAN.ply is a Stanford-style range image (ASCII PLY with `obj_info num_cols/num_rows` and a
`range_grid` element: one optional vertex index per pixel). Its *pieces* are the connected sets
of pixels under 8-neighbour adjacency, an edge kept when its 3D length (per unit of pixel
distance) is at most `--break` times the median: depth discontinuities and silhouettes cut the
scan into pieces, independently of any reconstruction. Pieces of fewer than `--min-points` points
are too small to make a sheet of their own.

MESH.obj is a reconstruction of the scan's points (`rbfsurf reconstruct SCAN.ply -o MESH.obj`).
For each connected component of the mesh, its vertices' nearest scan points name the pieces it
lies on; for each piece, the share of its points within 2 median spacings of the mesh says
whether it is covered. Prints per piece and per component, and one summary line:
`pieces P, components C, components on one piece K, pieces covered V`.
Needs numpy and scipy.
"""

import argparse

import numpy as np
from scipy.spatial import cKDTree


def read_range_ply(path):
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode().strip()
            header.append(line)
            if line == "end_header":
                break
        body = f.read().decode().split("\n")
    value = lambda key: int(next(h for h in header if key in h).split()[-1])
    cols, rows = value("num_cols"), value("num_rows")
    nv = int(next(h for h in header if h.startswith("element vertex")).split()[-1])
    pts = np.array([[float(x) for x in body[i].split()[:3]] for i in range(nv)])
    grid = -np.ones(rows * cols, dtype=np.int64)
    for k in range(rows * cols):
        t = body[nv + k].split()
        if t and t[0] != "0":
            grid[k] = int(t[1])
    return pts, grid.reshape(rows, cols)


def pieces(pts, grid, brk):
    rows, cols = grid.shape
    edges = []
    for dr, dc in [(0, 1), (1, 0), (1, 1), (1, -1)]:
        ca, cb = (slice(0, cols - dc), slice(dc, cols)) if dc >= 0 else (slice(-dc, cols), slice(0, cols + dc))
        a, b = grid[: rows - dr, ca], grid[dr:, cb]
        ok = (a >= 0) & (b >= 0)
        ea, eb = a[ok], b[ok]
        d = np.linalg.norm(pts[ea] - pts[eb], axis=1) / np.hypot(dr, dc)
        edges.append((ea, eb, d))
    d_all = np.concatenate([e[2] for e in edges])
    med = float(np.median(d_all))
    pairs = [(a, b) for ea, eb, d in edges for a, b in zip(ea[d <= brk * med], eb[d <= brk * med])]
    return connected_labels(len(pts), pairs), med


def connected_labels(n, pairs):
    """Per item of `0..n`, a representative of its connected set under the `pairs`."""
    parent = np.arange(n)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b in pairs:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    return np.array([find(i) for i in range(n)])


def read_obj(path):
    v, f = [], []
    for line in open(path):
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            f.append([int(x.split("/")[0]) - 1 for x in line.split()[1:4]])
    return np.array(v), np.array(f, dtype=np.int64)


def components(v, f):
    return connected_labels(len(v), [(t[0], t[k]) for t in f for k in (1, 2)])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scan")
    ap.add_argument("mesh")
    ap.add_argument("--break", dest="brk", type=float, default=8.0)
    ap.add_argument("--min-points", type=int, default=20)
    a = ap.parse_args()
    pts, grid = read_range_ply(a.scan)
    labels, med = pieces(pts, grid, a.brk)
    ids, counts = np.unique(labels, return_counts=True)
    big = {int(i): int(c) for i, c in zip(ids, counts) if c >= a.min_points}
    v, f = read_obj(a.mesh)
    used = np.unique(f)
    comp = components(v, f)
    tree = cKDTree(pts)
    _, nearest = tree.query(v[used])
    on_piece = labels[nearest]
    mesh_tree = cKDTree(v[used])
    dist, _ = mesh_tree.query(pts)
    covered = 0
    for p, n in sorted(big.items(), key=lambda x: -x[1]):
        share = float(np.mean(dist[labels == p] <= 2 * med))
        covered += share >= 0.5
        print(f"piece {p}: {n} points, {share:.0%} within 2 spacings of the mesh")
    one = 0
    comps = np.unique(comp[used])
    for c in comps:
        sel = comp[used] == c
        names, k = np.unique(on_piece[sel], return_counts=True)
        top = names[np.argmax(k)]
        share = k.max() / sel.sum()
        one += share >= 0.9
        print(f"component {c}: {sel.sum()} vertices, {share:.0%} on piece {top} ({big.get(int(top), 'small')} points)")
    print(f"pieces {len(big)}, components {len(comps)}, components on one piece {one}, "
          f"pieces covered {covered}")


if __name__ == "__main__":
    main()
