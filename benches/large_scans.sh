#!/usr/bin/env bash
# Large-scan benchmark: rbfsurf vs screened Poisson (Open3D) on synthetic scans with a
# known truth mesh and on the real data sets, with wall time, peak RSS, accuracy and topology.
#
# Usage (from the repository root):  benches/large_scans.sh [--quick] [--no-poisson] [--scratch DIR]
#   --quick       only 10^4 and 10^5 points (skip 10^6)
#   --no-poisson  rbfsurf only
#   --scratch DIR keep inputs and outputs there (default: a fresh temporary directory)
# Output: a Markdown table on stdout and in benches/results/large_scans.md (quick runs:
# benches/results/large_scans_quick.md).
set -euo pipefail

# ---------------------------------------------------------------------------------------------
# The cases. Edit here to extend.
SHAPES=(torus knot bumpy-sphere)           # clean inputs at every size
SIZES=(10000 100000 1000000)               # --quick drops 1000000
VARIANT_SHAPES=(knot)                      # shapes that get the defect variants below
VARIANT_POINTS=100000
# name | `rbfsurf generate` flags | extra `rbfsurf reconstruct` flag sets, ';'-separated (each set
# is one more rbfsurf run besides the default one) | output extension
VARIANTS=(
  "noise0.1%|--noise 0.001|--smoothing 1;--neighbours 100 --smoothing 3|glb"
  "noise0.5%|--noise 0.005|--neighbours 100 --smoothing 3;--neighbours 100 --smoothing 3 --min-component 0.01|glb"
  "outliers5%|--outliers 0.05|--outlier-std-ratio 3;--outlier-std-ratio 3 --min-component 0.01|glb"
  "holes5|--holes 5|--boundary closed|glb"
  "no-normals|--no-normals||glb"
  "offset1e6|--offset 1e6||obj"       # GLB/PLY store f32: 1e6 + x would lose the shape
)
# Real data: name | input | reference for `rbfsurf compare`
REAL=(
  "kitten|data/kitten.ply|data/kitten.ply"
  "bunny|data/bunny_cgal.ply|data/bunny00.off"
)
POISSON_DEPTH=10
COMPARE_SAMPLES=100000
# ---------------------------------------------------------------------------------------------

QUICK=0
POISSON=1
SCRATCH=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --quick) QUICK=1 ;;
    --no-poisson) POISSON=0 ;;
    --scratch) SCRATCH="$2"; shift ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    *) echo "unknown option $1 (use --quick, --no-poisson, --scratch DIR)" >&2; exit 2 ;;
  esac
  shift
done
[[ -f Cargo.toml && -d benches ]] || { echo "run from the repository root" >&2; exit 2; }
if [[ $QUICK == 1 ]]; then SIZES=(10000 100000); fi
if [[ -z "$SCRATCH" ]]; then SCRATCH=$(mktemp -d /tmp/rbfsurf-large.XXXXXX); fi
mkdir -p "$SCRATCH" benches/results
RESULTS="$SCRATCH/results.tsv"
: > "$RESULTS"

echo "building release ..." >&2
cargo build --release --locked --quiet
BIN=target/release/rbfsurf

# Timing: GNU time if present (installed with apt-get when running as root), else the report.
TIME_BIN=/usr/bin/time
if [[ ! -x $TIME_BIN && $(id -u) == 0 ]] && command -v apt-get > /dev/null; then
  apt-get install -y -qq time > /dev/null 2>&1 || true
fi
[[ -x $TIME_BIN ]] || { TIME_BIN=""; echo "no /usr/bin/time: using the report's memory.peak_rss_mib" >&2; }

# Peer: Open3D in its own venv.
VENV=benches/.venv-open3d
if [[ $POISSON == 1 ]]; then
  if [[ ! -x $VENV/bin/python ]] || ! $VENV/bin/python -c 'import open3d' 2> /dev/null; then
    echo "installing Open3D into $VENV ..." >&2
    if ! { python3 -m venv "$VENV" && "$VENV/bin/pip" install -q open3d; } >&2; then
      echo "skipping Poisson: could not install open3d into $VENV (pip failed)" >&2
      POISSON=0
    fi
  fi
  if [[ $POISSON == 1 ]] && ! $VENV/bin/python -c 'import open3d' 2> /dev/null; then
    echo "skipping Poisson: open3d does not import in $VENV" >&2
    POISSON=0
  fi
fi

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

# record INPUT N TOOL WALL_S CORE_S RSS_MIB OUT REF
record() {
  local input=$1 n=$2 tool=$3 wall=$4 core=$5 rss=$6 out=$7 ref=$8 cmp="$SCRATCH/cmp.json"
  local fields="- - - - -"
  if [[ -f $out ]] && $BIN compare "$out" "$ref" --json --samples $COMPARE_SAMPLES > "$cmp" 2> "$SCRATCH/cmp.err"; then
    fields="$(json "$cmp" chamfer_rel) $(json "$cmp" hausdorff_rel) $(json "$cmp" mesh.components) $(json "$cmp" mesh.genus) $(json "$cmp" mesh.watertight)"
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$input" "$n" "$tool" "$wall" "$core" "$rss" "${fields// /$'\t'}" >> "$RESULTS"
  echo "  $tool: $wall s, $rss MiB, [chamfer hausdorff comps genus watertight] = $fields" >&2
}

# run_rbfsurf NAME N IN REF EXT [FLAGS...]
run_rbfsurf() {
  local name=$1 n=$2 in=$3 ref=$4 ext=$5; shift 5
  local tag="rbfsurf${*:+ $*}" stem="$SCRATCH/${name}-rbfsurf$(echo "$*" | tr -c 'a-z0-9.\n' '_')"
  local out="$stem.$ext" rep="$stem.json" tf="$stem.time" wall=- rss=- core=-
  rm -f "$out"
  local t0; t0=$(date +%s.%N)
  local timer=(); [[ -z $TIME_BIN ]] || timer=("$TIME_BIN" -f '%e %M' -o "$tf")
  if "${timer[@]}" "$BIN" reconstruct "$in" -o "$out" --report "$rep" --quiet "$@" 2> "$stem.err"; then
    if [[ -n $TIME_BIN ]]; then
      read -r wall rss < <(tail -n 1 "$tf"); rss=$(python3 -c "print(round($rss/1024, 1))")
    else
      wall=$(python3 -c "import time; print(round(time.time() - $t0, 2))")
      rss=$(json "$rep" memory.peak_rss_mib)
    fi
    core=$(python3 -c "print(round($(json "$rep" timings_s.total) - $(json "$rep" timings_s.read) - $(json "$rep" timings_s.write), 3))")
  else
    echo "  rbfsurf failed: $(tail -n 1 "$stem.err")" >&2; tag="$tag (failed)"
  fi
  record "$name" "$n" "$tag" "$wall" "$core" "$rss" "$out" "$ref"
}

# run_poisson NAME N IN REF
run_poisson() {
  [[ $POISSON == 1 ]] || return 0
  local name=$1 n=$2 in=$3 ref=$4 stem="$SCRATCH/$1-poisson"
  local out="$stem.ply" tf="$stem.time" wall=- rss=- core=- tag="poisson d$POISSON_DEPTH"
  rm -f "$out"
  local timer=(); [[ -z $TIME_BIN ]] || timer=("$TIME_BIN" -f '%e %M' -o "$tf")
  if "${timer[@]}" "$VENV/bin/python" benches/poisson.py "$in" "$out" --depth $POISSON_DEPTH > "$stem.json" 2> "$stem.err"; then
    core=$(json "$stem.json" seconds)
    if [[ -n $TIME_BIN ]]; then
      read -r wall rss < <(tail -n 1 "$tf"); rss=$(python3 -c "print(round($rss/1024, 1))")
    else
      wall=$(python3 -c "import json; j=json.load(open('$stem.json')); print(round(j['seconds']+j['read_s']+j['write_s'], 2))")
      rss=$(json "$stem.json" peak_rss_mib)
    fi
  else
    echo "  poisson failed: $(tail -n 1 "$stem.err")" >&2; tag="$tag (failed)"
  fi
  record "$name" "$n" "$tag" "$wall" "$core" "$rss" "$out" "$ref"
}

gen() {  # gen NAME SHAPE N TRUTH_EXT [FLAGS...]
  local name=$1 shape=$2 n=$3 text=$4; shift 4
  echo "generate $name ($n points) ..." >&2
  $BIN generate "$shape" --points "$n" -o "$SCRATCH/$name.ply" --truth "$SCRATCH/$name-truth.$text" "$@"
}

for shape in "${SHAPES[@]}"; do
  for n in "${SIZES[@]}"; do
    name="$shape-$n"
    gen "$name" "$shape" "$n" ply
    run_rbfsurf "$name" "$n" "$SCRATCH/$name.ply" "$SCRATCH/$name-truth.ply" glb
    run_poisson "$name" "$n" "$SCRATCH/$name.ply" "$SCRATCH/$name-truth.ply"
  done
done

for shape in "${VARIANT_SHAPES[@]}"; do
  for v in "${VARIANTS[@]}"; do
    IFS='|' read -r vname gflags rsets ext <<< "$v"
    name="$shape-$vname"
    # shellcheck disable=SC2086
    gen "$name" "$shape" "$VARIANT_POINTS" "$ext" $gflags
    in="$SCRATCH/$name.ply" ref="$SCRATCH/$name-truth.$ext"
    run_rbfsurf "$name" "$VARIANT_POINTS" "$in" "$ref" "$ext"
    if [[ -n $rsets ]]; then
      IFS=';' read -r -a sets <<< "$rsets"
      for s in "${sets[@]}"; do
        # shellcheck disable=SC2086
        run_rbfsurf "$name" "$VARIANT_POINTS" "$in" "$ref" "$ext" $s
      done
    fi
    run_poisson "$name" "$VARIANT_POINTS" "$in" "$ref"
  done
done

for r in "${REAL[@]}"; do
  IFS='|' read -r name in ref <<< "$r"
  n=$(python3 -c "import sys; h=open('$in','rb').read(4096).split(b'end_header')[0]; print([l.split()[2] for l in h.split(b'\n') if l.startswith(b'element vertex')][0].decode())")
  echo "real data $name ($n points) ..." >&2
  run_rbfsurf "$name" "$n" "$in" "$ref" glb
  run_poisson "$name" "$n" "$in" "$ref"
done

OUT=benches/results/large_scans.md
[[ $QUICK == 1 ]] && OUT=benches/results/large_scans_quick.md
python3 benches/large_scans_table.py "$RESULTS" "$OUT" "$QUICK" "$POISSON"
echo "written $OUT (inputs and meshes in $SCRATCH)" >&2
