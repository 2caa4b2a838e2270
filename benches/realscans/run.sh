#!/usr/bin/env bash
# Real-scan benchmark: rbfsurf with DEFAULT parameters vs native screened Poisson on the
# inputs that benches/realscans/prepare.sh makes (statues with thin parts with and without normals,
# noisy and sparse variants, the six shared CGAL scans, a building, a single-view range scan, the
# noisy 10^6 torus). Records topology, mesh->scan distance, Chamfer against the truth where there is
# one, triangles, wall time, and whether rbfsurf panicked or hung.
#
# Usage (from the repository root):
#   benches/realscans/run.sh [BIN] [--label TEXT] [--out FILE.md] [--only REGEX] [--no-peer]
#     BIN       the rbfsurf binary to measure (default target/release/rbfsurf; env RBFSURF_BIN too),
#               so two builds can be compared: run it once per binary with different --out
#     --label   text for the table's title (default: `git rev-parse --short HEAD` + binary path)
#     --out     Markdown output (default benches/results/realscans.md; raw rows next to it as .tsv)
#     --only    only the inputs whose name matches this (grep -E) regex
#     --no-peer rbfsurf only
# Environment:
#   POISSON_BIN  native PoissonRecon (github.com/mkazhdan/PoissonRecon, built OUTSIDE this repository;
#                default /tmp/PoissonRecon/Bin/Linux/PoissonRecon). If missing, the peer is Open3D's
#                screened Poisson (benches/poisson.py) instead; the table says which.
#   POISSON_DEPTH (default 10)   TIMEOUT per rbfsurf run in seconds (default 300; a run that takes
#                longer is recorded as TIMEOUT: a hang or a pathological slowdown)
#   PEER_TIMEOUT per peer run (default 600)
#   SCRATCH      outputs (default target/realscans/out)   VENV (default benches/.venv-open3d)
# Inputs without normals: the peer gets normals from Open3D (15-NN PCA + consistent tangent plane
# orientation, benches/realscans/normals.py); its time is reported apart and included in "peer s".
set -euo pipefail
[[ -f Cargo.toml && -d benches ]] || { echo "run from the repository root" >&2; exit 2; }
BIN=${RBFSURF_BIN:-target/release/rbfsurf}
LABEL="" OUTMD=benches/results/realscans.md ONLY="" PEER=1
while [[ $# -gt 0 ]]; do
  case "$1" in
    --label) LABEL="$2"; shift ;;
    --out) OUTMD="$2"; shift ;;
    --only) ONLY="$2"; shift ;;
    --no-peer) PEER=0 ;;
    -h|--help) sed -n '2,24p' "$0"; exit 0 ;;
    -*) echo "unknown option $1" >&2; exit 2 ;;
    *) BIN="$1" ;;
  esac
  shift
done
DATA=${DATA:-target/realscans}
MANIFEST=$DATA/manifest.tsv
[[ -f $MANIFEST ]] || { echo "no $MANIFEST: run benches/realscans/prepare.sh first" >&2; exit 2; }
[[ -x $BIN ]] || { echo "no rbfsurf binary at $BIN" >&2; exit 2; }
(cd "$DATA" && sha256sum -c --quiet SHA256SUMS) || { echo "inputs differ from $DATA/SHA256SUMS: rerun prepare.sh" >&2; exit 2; }
SCRATCH=${SCRATCH:-$DATA/out}
TIMEOUT=${TIMEOUT:-300}
PEER_TIMEOUT=${PEER_TIMEOUT:-600}
POISSON_DEPTH=${POISSON_DEPTH:-10}
POISSON_BIN=${POISSON_BIN:-/tmp/PoissonRecon/Bin/Linux/PoissonRecon}
VENV=${VENV:-benches/.venv-open3d}
mkdir -p "$SCRATCH" "$(dirname "$OUTMD")"
ROWS=${OUTMD%.md}.tsv
: > "$ROWS"
[[ -n $LABEL ]] || LABEL="$(git rev-parse --short HEAD 2> /dev/null || echo '?') ($BIN)"

PEER_KIND=none
if [[ $PEER == 1 ]]; then
  if ! "$VENV/bin/python" -c 'import open3d' 2> /dev/null; then
    [[ -x $VENV/bin/python ]] || python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q open3d >&2 || true
    # Open3D's wheel needs libusb at import time on Debian
    if ! "$VENV/bin/python" -c 'import open3d' 2> /dev/null && [[ $(id -u) == 0 ]]; then
      apt-get install -y -qq libusb-1.0-0 > /dev/null 2>&1 || true
    fi
  fi
  if "$VENV/bin/python" -c 'import open3d' 2> /dev/null; then
    if [[ -x $POISSON_BIN ]]; then PEER_KIND=native; else PEER_KIND=open3d; fi
  else
    echo "no Open3D in $VENV: running without the peer" >&2
  fi
fi
echo "rbfsurf: $BIN; peer: $PEER_KIND" >&2
LOAD0=$(cut -d' ' -f1-3 /proc/loadavg)

json() {  # json FILE KEY.PATH -> value or '-'
  python3 - "$1" "$2" << 'EOF'
import json, sys
try:
    v = json.load(open(sys.argv[1]))
    for k in sys.argv[2].split('.'):
        v = v[k]
    print('-' if v is None else v)
except Exception:
    print('-')
EOF
}
now() { date +%s.%N; }
# timed TIMEFILE CMD... : runs CMD under GNU time (wall, user, sys seconds into TIMEFILE) when present
TIME_BIN=/usr/bin/time
[[ -x $TIME_BIN ]] || { [[ $(id -u) == 0 ]] && apt-get install -y -qq time > /dev/null 2>&1; } || true
timed() {
  local tf=$1; shift
  if [[ -x $TIME_BIN ]]; then "$TIME_BIN" -f '%e %U %S' -o "$tf" "$@"; else : > "$tf"; "$@"; fi
}
cpu_of() {  # cpu_of TIMEFILE... -> summed user+sys seconds, or '-'
  python3 -c '
import sys
tot, ok = 0.0, False
for p in sys.argv[1:]:
    try:
        w, u, s = open(p).read().strip().split("\n")[-1].split()[:3]
        tot += float(u) + float(s); ok = True
    except Exception:
        pass
print(round(tot, 2) if ok else "-")' "$@"
}
elapsed() { python3 -c "print(round($(now) - $1, 2))"; }

# measure NAME TOOL MESH INPUT REF SECONDS STATUS EXTRA -> one TSV row
# columns: name tool status seconds extra comps watertight genus boundary_loops nm_vertices
#          nm_edges triangles mesh_to_scan chamfer_truth cpu_seconds
measure() {
  local name=$1 tool=$2 mesh=$3 in=$4 ref=$5 secs=$6 status=$7 extra=$8 cpu=${9:--}
  local c="$SCRATCH/$name-$tool.cmp.json" t="$SCRATCH/$name-$tool.truth.json"
  local topo="- - - - - - -" m2s=- cham=-
  if [[ $status == ok ]] && timeout "$TIMEOUT" "$BIN" compare "$mesh" "$in" --json > "$c" 2> "$c.err"; then
    topo="$(json "$c" mesh.components) $(json "$c" mesh.watertight) $(json "$c" mesh.genus) $(json "$c" mesh.boundary_loops) $(json "$c" mesh.non_manifold_vertices) $(json "$c" mesh.non_manifold_edges) $(json "$c" mesh.triangles)"
    m2s=$(json "$c" mesh_to_ref_plane_mean_rel)
    if [[ $ref == onesided:* ]]; then
      timeout "$TIMEOUT" "$BIN" compare "$mesh" "${ref#onesided:}" --json > "$t" 2> "$t.err" && cham="$(json "$t" mesh_to_ref_mean_rel)(1-sided)"
    elif [[ $ref != - ]]; then
      timeout "$TIMEOUT" "$BIN" compare "$mesh" "$ref" --json > "$t" 2> "$t.err" && cham=$(json "$t" chamfer_rel)
    fi
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$tool" "$status" "$secs" "$extra" "${topo// /$'\t'}" "$m2s" "$cham" "$cpu" >> "$ROWS"
  echo "  $tool: $status ${secs}s (cpu ${cpu}s) [comps watertight genus loops nmv nme tris] = $topo, mesh->scan $m2s, truth $cham" >&2
}

status_of() {  # status_of RC ERRFILE [LIMIT_S]
  local rc=$1 err=$2 limit=${3:-$TIMEOUT}
  if [[ $rc == 0 ]]; then echo ok
  elif [[ $rc == 124 ]]; then echo "TIMEOUT(>${limit}s)"
  elif grep -q "panicked" "$err" 2> /dev/null; then echo "PANIC"
  elif [[ $rc -ge 128 ]]; then echo "CRASH(signal $((rc - 128)))"
  else echo "error(rc $rc)"; fi
}

while IFS=$'\t' read -r name in ref expected normals what; do
  [[ -z $ONLY || $name =~ $ONLY ]] || continue
  npts=$(python3 - "$in" << 'EOF'
import sys
p = sys.argv[1]
if p.endswith('.ply'):
    h = open(p, 'rb').read(4096).split(b'end_header')[0]
    print([l.split()[2] for l in h.split(b'\n') if l.startswith(b'element vertex')][0].decode())
else:
    print(sum(1 for l in open(p) if l.strip()))
EOF
)
  echo "$name ($npts points, normals: $normals) ..." >&2
  # rbfsurf, default parameters
  out="$SCRATCH/$name-rbfsurf.glb" rep="$SCRATCH/$name-rbfsurf.json" err="$SCRATCH/$name-rbfsurf.err"
  rm -f "$out" "$rep"
  t0=$(now); rc=0
  timed "$SCRATCH/$name-rbfsurf.time" timeout "$TIMEOUT" "$BIN" reconstruct "$in" -o "$out" --report "$rep" --quiet 2> "$err" || rc=$?
  secs=$(elapsed "$t0"); st=$(status_of $rc "$err")
  [[ $st == ok ]] || echo "  rbfsurf $st: $(tail -n 2 "$err" | tr '\n' ' ')" >&2
  measure "$name" rbfsurf "$out" "$in" "$ref" "$secs" "$st" "-" "$(cpu_of "$SCRATCH/$name-rbfsurf.time")"
  # peer
  if [[ $PEER_KIND != none ]]; then
    pout="$SCRATCH/$name-poisson.ply" perr="$SCRATCH/$name-poisson.err" rc=0
    rm -f "$pout"
    if [[ $PEER_KIND == native ]]; then
      oriented="$SCRATCH/$name-oriented.ply"
      nsecs=-
      t0=$(now)
      if timed "$SCRATCH/$name-normals.time" "$VENV/bin/python" benches/realscans/normals.py "$in" "$oriented" > "$SCRATCH/$name-normals.json" 2> "$perr"; then
        nsecs=$(elapsed "$t0")
        t0=$(now)
        # OMP_WAIT_POLICY=PASSIVE: no spinning OpenMP threads on a shared, loaded machine
        OMP_WAIT_POLICY=PASSIVE timed "$SCRATCH/$name-poisson.time" timeout "$PEER_TIMEOUT" "$POISSON_BIN" --in "$oriented" --out "$pout" --depth "$POISSON_DEPTH" > "$SCRATCH/$name-poisson.log" 2>> "$perr" || rc=$?
        psecs=$(elapsed "$t0")
        if [[ $normals == yes ]]; then
          secs=$psecs pcpu=$(cpu_of "$SCRATCH/$name-poisson.time")
        else
          secs=$(python3 -c "print(round($psecs + $nsecs, 2))")
          pcpu=$(cpu_of "$SCRATCH/$name-poisson.time" "$SCRATCH/$name-normals.time")
        fi
      else
        rc=1 secs=- pcpu=-
      fi
      extra="Open3D normals ${nsecs}s"
      [[ $normals == yes ]] && extra="given normals"
    else
      t0=$(now)
      timed "$SCRATCH/$name-poisson.time" timeout "$PEER_TIMEOUT" "$VENV/bin/python" benches/poisson.py "$in" "$pout" --depth "$POISSON_DEPTH" > "$SCRATCH/$name-poisson.json" 2> "$perr" || rc=$?
      secs=$(elapsed "$t0") pcpu=$(cpu_of "$SCRATCH/$name-poisson.time")
      extra="$( [[ $normals == yes ]] && echo 'given normals' || echo 'Open3D normals')"
    fi
    st=$(status_of $rc "$perr" "$PEER_TIMEOUT")
    measure "$name" "poisson-d$POISSON_DEPTH" "$pout" "$in" "$ref" "$secs" "$st" "$extra" "${pcpu:--}"
  fi
done < "$MANIFEST"

LOAD="load average (1/5/15 min) at start $LOAD0, at end $(cut -d' ' -f1-3 /proc/loadavg)"
python3 benches/realscans/table.py "$MANIFEST" "$ROWS" "$OUTMD" "$LABEL" "$PEER_KIND" "$POISSON_DEPTH" "$LOAD"
echo "written $OUTMD (rows: $ROWS, meshes in $SCRATCH)" >&2
