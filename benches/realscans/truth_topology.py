#!/usr/bin/env python3
"""Topology of the solid a closed (possibly self-intersecting) truth mesh encloses, per voxel size.

The suite's "right genus" for a closed object is the genus of its truth. A truth mesh that passes
through itself is an immersed, not an embedded, surface: its own Euler genus is not the genus of any
watertight surface around the same solid. This measures the solid itself, independently of rbfsurf:

  winding number on a voxel grid (signed z-crossings per column: exact integers, no ray parity),
  solid = winding >= 1, then for the solid as closed cubes (26-connected) and as open cubes
  (6-connected, via Alexander duality on the complement): components, cavities and first Betti
  number (handles) from the Euler characteristic of the cube complex.

At a voxel size where both conventions agree, the count is the solid's; where they disagree, parts
are closer than a voxel. Usage (needs numpy and scipy):

  truth_topology.py MESH.off [N ...]     N = voxels along the longest side (default 150 300 600)
"""
import sys

import numpy as np
from scipy import ndimage


def read_off(path):
    tok = open(path).read().split()
    if tok[0] != "OFF":
        sys.exit(f"{path}: not an OFF file")
    nv, nf = int(tok[1]), int(tok[2])
    v = np.array(tok[4:4 + 3 * nv], float).reshape(nv, 3)
    f = np.array(tok[4 + 3 * nv:4 + 3 * nv + 4 * nf], int).reshape(nf, 4)
    if (f[:, 0] != 3).any():
        sys.exit(f"{path}: only triangles are supported")
    return v, f[:, 1:]


def winding_grid(v, f, n):
    """Winding number at the centres of a grid with n cells along the longest side."""
    lo, hi = v.min(0), v.max(0)
    pad = 0.02 * (hi - lo).max()
    lo, hi = lo - pad, hi + pad
    h = (hi - lo).max() / n
    shape = np.ceil((hi - lo) / h).astype(int) + 1
    # off the lattice by irrational fractions, so no column passes exactly through an edge
    off = np.array([0.5 + 1e-4 * np.sqrt(2), 0.5 + 1e-4 * np.sqrt(3), 0.5])
    xs, ys = (lo[a] + (np.arange(shape[a]) + off[a]) * h for a in (0, 1))
    delta = np.zeros(shape, np.int32)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    for t in np.nonzero(area2 != 0)[0]:
        tri = np.stack([a[t], b[t], c[t]])
        i0, j0 = np.maximum(0, np.ceil((tri[:, :2].min(0) - lo[:2]) / h - off[:2]).astype(int))
        i1, j1 = np.minimum(shape[:2] - 1, np.floor((tri[:, :2].max(0) - lo[:2]) / h - off[:2]).astype(int))
        if i1 < i0 or j1 < j0:
            continue
        X, Y = np.meshgrid(xs[i0:i1 + 1], ys[j0:j1 + 1], indexing="ij")
        A, B, C = tri
        w0 = ((B[0] - X) * (C[1] - Y) - (B[1] - Y) * (C[0] - X)) / area2[t]
        w1 = ((C[0] - X) * (A[1] - Y) - (C[1] - Y) * (A[0] - X)) / area2[t]
        w2 = 1 - w0 - w1
        ii, jj = np.nonzero((w0 >= 0) & (w1 >= 0) & (w2 >= 0))
        if ii.size == 0:
            continue
        z = w0[ii, jj] * A[2] + w1[ii, jj] * B[2] + w2[ii, jj] * C[2]
        k = np.ceil((z - lo[2]) / h - off[2]).astype(int)
        ok = (k >= 0) & (k < shape[2])
        # an upward column enters the solid through a face whose outward normal points down
        np.add.at(delta, (ii[ok] + i0, jj[ok] + j0, k[ok]), -int(np.sign(area2[t])))
    return np.cumsum(delta, axis=2), h


def euler_closed_cubes(S):
    """Euler characteristic of the union of the closed unit cubes of the voxels in S."""
    s = np.pad(S, 1).astype(np.uint8)

    def cells(axes):  # lattice cells touched by a voxel: merge neighbours along each axis
        r = s
        for ax in axes:
            lo = tuple(slice(0, -1) if a == ax else slice(None) for a in range(3))
            hi = tuple(slice(1, None) if a == ax else slice(None) for a in range(3))
            r = np.maximum(r[lo], r[hi])
        return int(r.sum())

    vertices = cells((0, 1, 2))
    edges = cells((1, 2)) + cells((0, 2)) + cells((0, 1))
    faces = cells((0,)) + cells((1,)) + cells((2,))
    return vertices - edges + faces - int(S.sum())


def topology(S):
    """(components, cavities, handles) of S as closed cubes and as open cubes."""
    full = np.ones((3, 3, 3))
    comps26 = ndimage.label(S, structure=full)[1]
    comps6 = ndimage.label(S)[1]
    outside = ~np.pad(S, 1)
    cav26 = ndimage.label(outside)[1] - 1
    cav6 = ndimage.label(outside, structure=full)[1] - 1
    handles26 = comps26 + cav26 - euler_closed_cubes(S)
    # open cubes: b1(S) = b1(complement), the complement taken as closed cubes
    handles6 = (cav6 + 1) + comps6 - euler_closed_cubes(outside)
    return (comps26, cav26, handles26), (comps6, cav6, handles6)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    v, f = read_off(sys.argv[1])
    edges = {tuple(sorted(e)) for t in f for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    chi = len(v) - len(edges) + len(f)
    print(f"{sys.argv[1]}: {len(v)} vertices, {len(f)} triangles, mesh Euler characteristic {chi}")
    for n in [int(a) for a in sys.argv[2:]] or [150, 300, 600]:
        w, h = winding_grid(v, f, n)
        (c26, v26, g26), (c6, v6, g6) = topology(w >= 1)
        print(f"  voxel {h:.4g} ({n} along the longest side): winding {w.min()}..{w.max()}, "
              f"{int((w >= 2).sum())} voxels counted twice or more; solid as closed cubes: "
              f"{c26} component(s), {v26} cavities, {g26} handles; as open cubes: {c6} component(s), "
              f"{v6} cavities, {g6} handles", flush=True)


if __name__ == "__main__":
    main()
