#!/usr/bin/env python3
"""Displayed vertex colours of rbfsurf's GLB against the sRGB field of the scanned points,
with independent writers (laspy, pye57/libE57Format) and an independent GLB reader (trimesh).

Needs (once): pip install numpy==2.* trimesh==4.5.3 laspy==2.7.0 pye57==0.4.19
Run from the repository root:  python3 tests/scripts/colour_transfer.py [BIN]
  BIN  the rbfsurf binary (default target/release/rbfsurf)
  THREE_DIR (environment, optional): node_modules/three of an `npm install three@0.170.0`; then the
       default (meshopt-compressed) GLB is also read by three.js's GLTFLoader
       (tests/scripts/glb_colours_three.mjs) and checked the same way.

A sphere of radius 10 m at UTM coordinates carries a colour field linear in the position, as
sRGB-encoded values in [0.1, 0.9] (what a viewer shows): LAS 1.2 format 3 with 16-bit colour,
the same with 8-bit values in the 16-bit fields (many writers do this), and an E57 with 8-bit
colour (pye57's limits 0..255). Each is reconstructed with default parameters into a plain GLB;
trimesh reads the vertices (node transform applied) and COLOR_0 as stored. glTF 2.0 defines
COLOR_0 as linear; a conforming viewer (three.js, the Khronos sample viewer) shows it
sRGB-encoded, so the displayed colour is srgb_encode(COLOR_0), compared per channel with the
field at the vertex. The error a viewer that shows COLOR_0 without encoding would see is printed
beside it (not a check). Exit code 0 and a final "N passed, 0 failed" line when the displayed
mean error is at most 0.01 and the 99th percentile at most 0.03.
"""
import os
import subprocess
import sys
import tempfile

import laspy
import numpy as np
import pye57
import trimesh

UTM = np.array([512345.0, 4102345.0, 250.0])
RADIUS = 10.0
RESULTS = {"passed": 0, "failed": 0}


def check(name, ok, detail=""):
    RESULTS["passed" if ok else "failed"] += 1
    print(("ok   " if ok else "FAIL ") + name + (": " + detail if detail else ""))


def field(xyz):
    """The sRGB-encoded colour field: linear in each coordinate, in [0.1, 0.9]."""
    return 0.5 + 0.4 * np.clip((xyz - UTM) / RADIUS, -1.0, 1.0)


def srgb_encode(c):
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def sphere(n, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return UTM + RADIUS * d


def write_las(path, xyz, full_scale):
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.offsets = UTM - 20.0
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    rgb = np.round(field(xyz) * full_scale).astype(np.uint16)
    las.red, las.green, las.blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    las.write(path)


def write_e57(path, xyz):
    rgb = np.round(field(xyz) * 255).astype(np.uint8)
    e57 = pye57.E57(path, mode="w")
    data = {
        "cartesianX": xyz[:, 0].copy(), "cartesianY": xyz[:, 1].copy(),
        "cartesianZ": xyz[:, 2].copy(),
        "colorRed": rgb[:, 0].copy(), "colorGreen": rgb[:, 1].copy(), "colorBlue": rgb[:, 2].copy(),
    }
    e57.write_scan_raw(data, name="scan0")
    e57.close()


def displayed_error(glb):
    """Per-channel absolute errors: (conforming viewer, viewer ignoring the transfer function)."""
    mesh = trimesh.load(glb, force="mesh", process=False)
    # trimesh keeps float COLOR_0 as stored, scaled to 0..255 (its `to_rgba` rounding).
    stored = np.asarray(mesh.visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
    want = field(np.asarray(mesh.vertices, dtype=np.float64))
    return np.abs(srgb_encode(stored) - want), np.abs(stored - want), len(mesh.vertices)


def main():
    binary = sys.argv[1] if len(sys.argv) > 1 else "target/release/rbfsurf"
    d = tempfile.mkdtemp(prefix="rbfsurf-colour-")
    xyz = sphere(20000, 7)
    inputs = {
        "las-16bit.las": lambda p: write_las(p, xyz, 65535),
        "las-8bit-in-16.las": lambda p: write_las(p, xyz, 255),
        "e57-8bit.e57": lambda p: write_e57(p, xyz),
    }
    for name, make in inputs.items():
        src = os.path.join(d, name)
        make(src)
        out = os.path.join(d, name + ".glb")
        subprocess.run([binary, "reconstruct", src, "-o", out, "--glb-compression", "none"],
                       check=True, stdout=subprocess.DEVNULL)
        shown, raw, n = displayed_error(out)
        mean, p99 = shown.mean(), np.percentile(shown, 99)
        check(name + " trimesh, plain GLB, displayed (sRGB-encoded COLOR_0)",
              mean <= 0.01 and p99 <= 0.03,
              "%d vertices, mean %.4f, p99 %.4f, max %.4f per channel; COLOR_0 shown as stored: "
              "mean %.4f" % (n, mean, p99, shown.max(), raw.mean()))
        three = os.environ.get("THREE_DIR")
        if three:
            out = os.path.join(d, name + ".meshopt.glb")
            subprocess.run([binary, "reconstruct", src, "-o", out], check=True,
                           stdout=subprocess.DEVNULL)
            here = os.path.dirname(os.path.abspath(__file__))
            text = subprocess.run(["node", os.path.join(here, "glb_colours_three.mjs"), three, out],
                                  check=True, capture_output=True, text=True).stdout
            rows = np.array([[float(v) for v in line.split()] for line in text.splitlines()])
            err = np.abs(rows[:, 3:] - field(rows[:, :3]))
            mean, p99 = err.mean(), np.percentile(err, 99)
            check(name + " three.js, default GLB, displayed", mean <= 0.01 and p99 <= 0.03,
                  "%d vertices, mean %.4f, p99 %.4f, max %.4f" % (len(rows), mean, p99, err.max()))
    print("%d passed, %d failed" % (RESULTS["passed"], RESULTS["failed"]))
    sys.exit(1 if RESULTS["failed"] else 0)


if __name__ == "__main__":
    main()
