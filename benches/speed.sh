#!/usr/bin/env bash
# Whole-process wall time side by side: rbfsurf with default parameters against native
# screened Poisson (PoissonRecon --depth 10, its default parallelism), runs interleaved so both see
# the same machine load; prints a Markdown table of the ranges and the ratio of the medians.
#
# Usage (from the repository root):
#   benches/speed.sh [--rounds N] [--bin BIN] [--base BASE_BIN] INPUT...
#     INPUT      point files with normals (PoissonRecon needs them), e.g. the real-scan suite's
#                target/realscans/armadillo-10k-n.ply (benches/realscans/prepare.sh makes them)
#     --rounds   runs of each program per input (default 5)
#     --bin      the rbfsurf binary (default target/release/rbfsurf)
#     --base     a second rbfsurf binary (e.g. main before a change), interleaved too; its column
#                and the ratio new / base are added
# Environment: POISSON_BIN (default /tmp/PoissonRecon/Bin/Linux/PoissonRecon: built OUTSIDE this
# repository from github.com/mkazhdan/PoissonRecon), POISSON_DEPTH (default 10),
# SCRATCH (default target/speed).
set -euo pipefail
[[ -f Cargo.toml && -d benches ]] || { echo "run from the repository root" >&2; exit 2; }
ROUNDS=5 BIN=target/release/rbfsurf BASE="" INPUTS=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --rounds) ROUNDS="$2"; shift ;;
    --bin) BIN="$2"; shift ;;
    --base) BASE="$2"; shift ;;
    -h|--help) sed -n '2,17p' "$0"; exit 0 ;;
    -*) echo "unknown option $1" >&2; exit 2 ;;
    *) INPUTS+=("$1") ;;
  esac
  shift
done
[[ ${#INPUTS[@]} -gt 0 ]] || { echo "no inputs (see --help)" >&2; exit 2; }
POISSON=${POISSON_BIN:-/tmp/PoissonRecon/Bin/Linux/PoissonRecon}
[[ -x $POISSON ]] || { echo "no PoissonRecon at $POISSON (set POISSON_BIN)" >&2; exit 2; }
DEPTH=${POISSON_DEPTH:-10}
SCRATCH=${SCRATCH:-target/speed}
mkdir -p "$SCRATCH"
rows=$SCRATCH/times.tsv
: >"$rows"

# One timed run: appends "input program seconds triangles" to $rows.
timed() {
  local name=$1 prog=$2; shift 2
  local t0 t1
  t0=$(date +%s.%N)
  "$@" >"$SCRATCH/last.log" 2>&1 || { echo "$prog failed on $name" >&2; cat "$SCRATCH/last.log" >&2; exit 1; }
  t1=$(date +%s.%N)
  local tris
  tris=$(grep -oE '[0-9]+ triangles' "$SCRATCH/last.log" | head -1 | cut -d' ' -f1 || true)
  printf '%s\t%s\t%s\t%s\n' "$name" "$prog" "$(python3 -c "print($t1 - $t0)")" "${tris:--}" >>"$rows"
}

for r in $(seq "$ROUNDS"); do
  for f in "${INPUTS[@]}"; do
    name=$(basename "${f%.*}")
    timed "$name" rbfsurf "$BIN" reconstruct "$f" -o "$SCRATCH/$name.glb"
    # PoissonRecon spins idle OpenMP threads by default; PASSIVE lets them sleep (its own speed
    # is unchanged, measured).
    timed "$name" poisson env OMP_WAIT_POLICY=PASSIVE "$POISSON" --in "$f" --out "$SCRATCH/$name.poisson.ply" --depth "$DEPTH"
    if [[ -n $BASE ]]; then
      timed "$name" base "$BASE" reconstruct "$f" -o "$SCRATCH/$name.base.glb"
    fi
  done
  echo "round $r of $ROUNDS done" >&2
done

python3 - "$rows" <<'PY'
import sys, statistics, collections
t = collections.defaultdict(lambda: collections.defaultdict(list))
order = []
for line in open(sys.argv[1]):
    name, prog, s, _ = line.rstrip('\n').split('\t')
    if name not in order:
        order.append(name)
    t[name][prog].append(float(s))
base = any('base' in t[n] for n in order)
head = '| input | rbfsurf s | PoissonRecon s | ratio |' + (' base s | new / base |' if base else '')
print(head)
print('|' + '---|' * (head.count('|') - 1))
for n in order:
    r, p = t[n]['rbfsurf'], t[n]['poisson']
    row = f'| {n} | {min(r):.2f}–{max(r):.2f} | {min(p):.2f}–{max(p):.2f} | {statistics.median(r) / statistics.median(p):.2f} |'
    if base:
        b = t[n]['base']
        row += f' {min(b):.2f}–{max(b):.2f} | {statistics.median(r) / statistics.median(b):.2f} |'
    print(row)
print(f'\n{len(t[order[0]]["rbfsurf"])} runs each, interleaved; ratio = median / median.')
PY
