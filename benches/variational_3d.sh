#!/usr/bin/env bash
# 3D comparison of the dense variational method (Turk–O'Brien r³) with Shen MLS and the CSRBF
# default, and a size sweep on random subsets of the bunny.
#
# For each run: wall time of the fit + polygonization (from the --report JSON: total of the stage
# timings), peak resident memory (/usr/bin/time -v), output size, and accuracy of the mesh against
# the input point set (`rbfsurf compare MESH POINTS --json`: Chamfer / Hausdorff relative to the
# bbox diagonal). Usage: benches/variational_3d.sh [OUTDIR]   (default: a temporary directory).
# Needs python3 and GNU time. Tables are printed as Markdown.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-$(mktemp -d)}"
mkdir -p "$OUT"
cargo build --release --quiet --bin rbfsurf
BIN="$OUT/rbfsurf"
cp target/release/rbfsurf "$BIN" # private copy: the shared target dir may be rebuilt meanwhile

# run NAME INPUT METHOD: prints one table row
run() {
    local name=$1 input=$2 method=$3
    local mesh="$OUT/$name-$method.ply" rep="$OUT/$name-$method.json" tlog="$OUT/$name-$method.time"
    if /usr/bin/time -v -o "$tlog" "$BIN" reconstruct "$input" -o "$mesh" --report "$rep" \
        --method "$method" -q >"$OUT/$name-$method.log" 2>&1; then
        "$BIN" compare "$mesh" "$input" --json >"$OUT/$name-$method.cmp.json" 2>/dev/null || true
        python3 - "$name" "$method" "$rep" "$tlog" "$OUT/$name-$method.cmp.json" <<'PY'
import json, re, sys
name, method, rep, tlog, cmp = sys.argv[1:]
r = json.load(open(rep))
t = open(tlog).read()
rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
wall = re.search(r"Elapsed \(wall clock\) time.*: (.*)", t).group(1).strip()
def find(d, keys):
    # first numeric value under any of `keys`, searched depth-first
    if isinstance(d, dict):
        for k, v in d.items():
            if k in keys and isinstance(v, (int, float)):
                return v
        for v in d.values():
            x = find(v, keys)
            if x is not None:
                return x
    return None
def sec(d):
    s = d.get("timings_s") or d.get("timings") or {}
    if isinstance(s, dict) and s:
        tot = s.get("total")
        return tot if isinstance(tot, (int, float)) else sum(v for v in s.values() if isinstance(v, (int, float)))
    return find(d, {"total_s", "seconds", "time_s"})
try:
    c = json.load(open(cmp))
except Exception:
    c = {}
ch = find(c, {"chamfer_rel", "chamfer", "chamfer_relative"})
hd = find(c, {"hausdorff_rel", "hausdorff", "hausdorff_relative"})
tri = r.get("mesh", {}).get("triangles")
unk = r.get("matrix", {}).get("n")
closed = "yes" if r.get("mesh", {}).get("watertight") else "no"
comps = r.get("mesh", {}).get("components")
fmt = lambda v, f: (f % v) if isinstance(v, (int, float)) else "–"
print(f"| {name} | {method} | {fmt(unk,'%d')} | {fmt(sec(r),'%.2f')} | {wall} | {rss:.0f} | {fmt(tri,'%d')} | {fmt(comps,'%d')} / {closed} | {fmt(ch,'%.2e')} | {fmt(hd,'%.2e')} |")
PY
    else
        echo "| $name | $method | – | failed: $(tail -c 160 "$OUT/$name-$method.log" | tr '\n|' '  ') | | | | | | |"
    fi
}

header() {
    echo "| input | method | unknowns | time (s, report) | wall | peak RSS (MiB) | triangles | components / watertight | Chamfer / diag | Hausdorff / diag |"
    echo "|---|---|---|---|---|---|---|---|---|---|"
}

echo "## kitten (5,210 points)"
header
for m in csrbf variational mls; do run kitten data/kitten.ply "$m"; done

echo
echo "## size sweep: random subsets of data/bunny_cgal.ply (seeded)"
for n in 1000 2000 4000 6000; do
    python3 - "$n" "$OUT/bunny$n.xyz" <<'PY'
import random, sys
n, path = int(sys.argv[1]), sys.argv[2]
lines = open("data/bunny_cgal.ply").read().split("end_header\n", 1)[1].split("\n")
pts = [l for l in lines if l.strip()]
random.Random(5).shuffle(pts)
open(path, "w").write("\n".join(pts[:n]) + "\n")
PY
done
header
for n in 1000 2000 4000 6000; do
    for m in csrbf variational mls; do run "bunny$n" "$OUT/bunny$n.xyz" "$m"; done
done
echo
echo "outputs in $OUT"
