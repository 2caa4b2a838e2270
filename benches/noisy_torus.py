#!/usr/bin/env python3
"""Noisy torus: mean distance of rbfsurf's mesh to the analytic torus.

Usage (from the repository root; needs numpy and trimesh):
  python3 benches/noisy_torus.py [--bin BIN] [--points N] [--sigma F] [--no-normals] [--seed S]
                                 [--keep DIR] [-- EXTRA RBFSURF ARGS]
The torus of `rbfsurf generate torus` (centre 0.5, radii 0.3 and 0.12, axis z) is sampled
clean with its normals by `rbfsurf generate`, then every coordinate gets independent Gaussian
noise of standard deviation F × the bounding-box diagonal (default F = 0.0005), so the
displacement along the normal has that σ. rbfsurf reconstructs it with default parameters
(plus EXTRA); the mesh is sampled uniformly by area (200,000 points, trimesh) and the mean and
90th percentile of the distance to the analytic torus, |√((√(x²+y²) − R)² + z²) − r| about the
centre, are printed relative to the diagonal, with the points' own mean distance (the noise)
and the run's wall time and peak RSS (GNU time).
"""
import argparse
import os
import subprocess
import tempfile

import numpy as np
import trimesh

CENTRE, MAJOR, MINOR = np.array([0.5, 0.5, 0.5]), 0.3, 0.12
DIAGONAL = float(np.linalg.norm([2 * (MAJOR + MINOR), 2 * (MAJOR + MINOR), 2 * MINOR]))


def torus_distance(p):
    q = p - CENTRE
    ring = np.hypot(q[:, 0], q[:, 1]) - MAJOR
    return np.abs(np.hypot(ring, q[:, 2]) - MINOR)


def write_ply(path, xyz, normals):
    cols = [xyz] + ([normals] if normals is not None else [])
    data = np.hstack(cols).astype("<f4")
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    head = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(xyz)
    head += "".join("property float %s\n" % p for p in props) + "end_header\n"
    with open(path, "wb") as f:
        f.write(head.encode())
        f.write(data.tobytes())


def read_ply_points(path):
    m = trimesh.load(path, process=False)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.vertex_normals, dtype=np.float64)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="target/release/rbfsurf")
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--sigma", type=float, default=0.0005)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-normals", action="store_true")
    ap.add_argument("--keep")
    ap.add_argument("extra", nargs="*")
    a = ap.parse_args()
    d = a.keep or tempfile.mkdtemp(prefix="rbfsurf-torus-")
    os.makedirs(d, exist_ok=True)
    tag = "torus-%d-axis%g-s%d%s" % (a.points, a.sigma, a.seed, "-xyz" if a.no_normals else "")
    src = os.path.join(d, tag + ".ply")
    if not os.path.exists(src):
        clean = os.path.join(d, "clean-%d-s%d.ply" % (a.points, a.seed))
        subprocess.run([a.bin, "generate", "torus", "--points", str(a.points), "--seed",
                        str(a.seed), "-o", clean], check=True, stdout=subprocess.DEVNULL)
        m = trimesh.load(clean, process=False)
        xyz = np.asarray(m.vertices, dtype=np.float64)
        normals = np.asarray(m.metadata["_ply_raw"]["vertex"]["data"][["nx", "ny", "nz"]].tolist())
        rng = np.random.default_rng(a.seed)
        xyz = xyz + rng.normal(scale=a.sigma * DIAGONAL, size=xyz.shape)
        write_ply(src, xyz, None if a.no_normals else normals)
    pts = trimesh.load(src, process=False).vertices
    out = os.path.join(d, tag + ".out.ply")
    timed = subprocess.run(["/usr/bin/time", "-f", "%e %M", a.bin, "reconstruct", src, "-o", out,
                            "--report", out + ".json"] + a.extra,
                           check=True, capture_output=True, text=True)
    wall, rss_kib = timed.stderr.strip().splitlines()[-1].split()
    mesh = trimesh.load(out, process=False)
    samples, _ = trimesh.sample.sample_surface(mesh, 200_000, seed=a.seed)
    dist = torus_distance(np.asarray(samples)) / DIAGONAL
    noise = torus_distance(np.asarray(pts, dtype=np.float64)).mean() / DIAGONAL
    print("%s %s: mesh->torus mean %.3e p90 %.3e (points %.3e), %d triangles, %s s, %.0f MiB"
          % (tag, " ".join(a.extra) or "default", dist.mean(), np.percentile(dist, 90), noise,
             len(mesh.faces), wall, int(rss_kib) / 1024))


if __name__ == "__main__":
    main()
