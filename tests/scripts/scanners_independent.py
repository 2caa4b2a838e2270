#!/usr/bin/env python3
"""Cross-check rbfsurf's LAS/LAZ/E57 readers and the test writers against independent libraries.

Needs (once): pip install laspy==2.7.0 lazrs==0.8.2 pye57==0.4.19 numpy
Run from the repository root:  python3 tests/scripts/scanners_independent.py

1. laspy (with the lazrs backend) writes LAS 1.2 point format 3, LAS 1.4 format 7 and a LAZ 1.4
   format 8 file at UTM coordinates with 16-bit colour, and pye57 (libE57Format) writes a
   two-scan E57 with poses and 8-bit colour; each gets a CSV of the values it holds.
2. `cargo test --test library scanners_independent::independent_files -- --ignored` reads those files with
   rbfsurf and compares against the CSVs (coordinates bit-exact, colours and intensity to 1e-6),
   then writes rbfsurf's own test files (las and e57 crates) with their CSVs.
3. laspy and pye57 read rbfsurf's files and compare against those CSVs.
Exit code 0 and a final "N passed, 0 failed" line when everything agrees.
"""
import csv
import os
import subprocess
import sys
import tempfile

import laspy
import numpy as np
import pye57

UTM = np.array([512345.0, 4102345.0, 250.0])
RESULTS = {"passed": 0, "failed": 0}


def check(name, ok, detail=""):
    RESULTS["passed" if ok else "failed"] += 1
    print(("ok   " if ok else "FAIL ") + name + (": " + detail if detail else ""))


def cloud(n, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    xyz = UTM + 10.0 * d
    rgb16 = np.round((0.5 + 0.4 * d) * 65535).astype(np.uint16)
    intensity = rng.integers(100, 60000, size=n).astype(np.uint16)
    return xyz, rgb16, intensity


def write_csv(path, xyz, rgb, intensity):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["x", "y", "z", "r", "g", "b", "i"])
        for p, c, i in zip(xyz, rgb, intensity):
            w.writerow([repr(float(p[0])), repr(float(p[1])), repr(float(p[2])),
                        int(c[0]), int(c[1]), int(c[2]), repr(float(i))])


def laspy_file(path, version, point_format, xyz, rgb, intensity):
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.offsets = UTM - 20.0
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.red, las.green, las.blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    las.intensity = intensity
    las.write(path)
    back = laspy.read(path)  # the values as stored (on the 1e-4 grid)
    stored = np.stack([back.x, back.y, back.z], axis=1)
    write_csv(path + ".csv", stored, rgb, intensity)


def pye57_file(path, xyz, rgb16, intensity):
    rgb8 = (rgb16 >> 8).astype(np.uint8)
    e57 = pye57.E57(path, mode="w")
    half = len(xyz) // 2
    # Scan 0 at identity pose; scan 1 stored in its own frame: rotated 90° about z, translated.
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    quat = np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])
    t = UTM + np.array([3.0, -2.0, 1.0])
    for k, (sl, q, tr) in enumerate([(slice(0, half), np.array([1.0, 0, 0, 0]), np.zeros(3)),
                                      (slice(half, None), quat, t)]):
        pts = xyz[sl]
        local = pts if k == 0 else (pts - tr) @ rot  # Rᵀ (p − t)
        data = {
            "cartesianX": local[:, 0].copy(), "cartesianY": local[:, 1].copy(),
            "cartesianZ": local[:, 2].copy(),
            "colorRed": rgb8[sl, 0].copy(), "colorGreen": rgb8[sl, 1].copy(),
            "colorBlue": rgb8[sl, 2].copy(), "intensity": intensity[sl].astype(np.float64),
        }
        e57.write_scan_raw(data, name="scan%d" % k, rotation=q, translation=tr)
    e57.close()
    # The CSV holds the world coordinates as pye57 reads them back (pose applied by libE57Format).
    back = pye57.E57(path)
    rows = []
    for k in range(back.scan_count):
        s = back.read_scan(k, intensity=True, colors=True, transform=True, ignore_missing_fields=True)
        rows.append((np.stack([s["cartesianX"], s["cartesianY"], s["cartesianZ"]], axis=1),
                     np.stack([s["colorRed"], s["colorGreen"], s["colorBlue"]], axis=1),
                     s["intensity"]))
    write_csv(path + ".csv", *[np.concatenate([r[i] for r in rows]) for i in range(3)])


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    xyz = np.array([[float(r["x"]), float(r["y"]), float(r["z"])] for r in rows])
    rgb = np.array([[int(r["r"]), int(r["g"]), int(r["b"])] for r in rows])
    return xyz, rgb, np.array([float(r["i"]) for r in rows])


def verify_ours(d):
    for name in sorted(os.listdir(d)):
        if not name.startswith("ours") or name.endswith(".csv"):
            continue
        path = os.path.join(d, name)
        xyz, rgb, intensity = read_csv(path + ".csv")
        if name.endswith(".e57"):
            f = pye57.E57(path)
            parts = [f.read_scan(k, intensity=True, colors=True, transform=True, ignore_missing_fields=True)
                     for k in range(f.scan_count)]
            got = np.concatenate([np.stack([s["cartesianX"], s["cartesianY"], s["cartesianZ"]], 1)
                                  for s in parts])
            col = np.concatenate([np.stack([s["colorRed"], s["colorGreen"], s["colorBlue"]], 1)
                                  for s in parts])
            check(name + " coordinates (pye57)", np.abs(got - xyz).max() < 1e-6,
                  "max error %.2e m" % np.abs(got - xyz).max())
            check(name + " colours (pye57)", np.array_equal(col.astype(int), rgb))
        else:
            las = laspy.read(path)
            got = np.stack([las.x, las.y, las.z], axis=1)
            check(name + " coordinates (laspy)", np.array_equal(got, xyz),
                  "max error %.2e m" % np.abs(got - xyz).max())
            if "red" in las.point_format.dimension_names:
                col = np.stack([las.red, las.green, las.blue], axis=1).astype(int)
                check(name + " colours (laspy)", np.array_equal(col, rgb))
            check(name + " intensity (laspy)", np.array_equal(np.asarray(las.intensity), intensity))
            check(name + " point count (laspy)", las.header.point_count == len(xyz))


def main():
    keep = sys.argv[1] if len(sys.argv) > 1 else None
    d = keep or tempfile.mkdtemp(prefix="rbfsurf-independent-")
    os.makedirs(d, exist_ok=True)
    xyz, rgb, intensity = cloud(5000, 1)
    laspy_file(os.path.join(d, "theirs_12_f3.las"), "1.2", 3, xyz, rgb, intensity)
    laspy_file(os.path.join(d, "theirs_14_f7.las"), "1.4", 7, xyz, rgb, intensity)
    laspy_file(os.path.join(d, "theirs_14_f8.laz"), "1.4", 8, xyz, rgb, intensity)
    pye57_file(os.path.join(d, "theirs.e57"), xyz, rgb, intensity)
    env = dict(os.environ, RBFSURF_INDEPENDENT_DIR=d)
    r = subprocess.run(["cargo", "test", "--locked", "--test", "library",
                        "scanners_independent::independent_files", "--", "--ignored", "--nocapture"], env=env)
    check("rbfsurf reads the laspy and pye57 files", r.returncode == 0)
    verify_ours(d)
    print("files in", d)
    print("%d passed, %d failed" % (RESULTS["passed"], RESULTS["failed"]))
    sys.exit(1 if RESULTS["failed"] else 0)


if __name__ == "__main__":
    main()
