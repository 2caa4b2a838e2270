#!/usr/bin/env bash
# Fetch and prepare the real-scan suite's inputs into target/realscans/ (gitignored), deterministically.
#
# Usage (from the repository root): benches/realscans/prepare.sh [BIN]
#   BIN  the rbfsurf binary used for the synthetic torus (default target/release/rbfsurf)
# Environment (all optional):
#   SHARED_DATA  the project's shared data folder (default ../shared/data, else /work/shared/data)
#   CGAL_DEB     a local libcgal-demo_5.5.1-2_all.deb (default: `apt-get download libcgal-demo=5.5.1-2`)
#   BUNNY_GIT    git dir of a snapshot of github.com/dengnantianjie/3dcoursework (holds Stanford's
#                bunny/data/ range images unchanged); default /work/.mirror/dengnantianjie+3dcoursework/repo
#                (the search tool's `fetch github:dengnantianjie/3dcoursework` puts it there). Without
#                it the Stanford inputs (bun000, the ten merged views) are skipped.
#   OUT          output folder (default target/realscans)
#
# Provenance and licences (nothing third-party is committed; see benches/realscans/README.md):
#   - CGAL data (Debian package libcgal-demo 5.5.1-2, usr/share/doc/libcgal-dev/data.tar.gz):
#     Debian's copyright file for CGAL: files without an explicit copyright notice are CC0-1.0.
#   - ../shared/data: copies of the same CGAL data (CC0-1.0), see shared/data/README.md.
#   - bun000.ply … top3.ply, bun.conf: Stanford 3D Scanning Repository, bunny range data (Cyberware 3030MS, 1996);
#     Stanford's terms: free use and redistribution for research, acknowledge the source, no
#     commercial use without permission. Checked by SHA-256 below.
#   - torus: `rbfsurf generate` (our own).
set -euo pipefail
[[ -f Cargo.toml && -d benches ]] || { echo "run from the repository root" >&2; exit 2; }
BIN=${1:-target/release/rbfsurf}
OUT=${OUT:-target/realscans}
SHARED_DATA=${SHARED_DATA:-}
if [[ -z $SHARED_DATA ]]; then
  for d in ../shared/data /work/shared/data; do [[ -f $d/kitten.ply ]] && { SHARED_DATA=$d; break; }; done
fi
[[ -n $SHARED_DATA && -f $SHARED_DATA/kitten.ply ]] || { echo "no shared data (set SHARED_DATA)" >&2; exit 2; }
BUNNY_GIT=${BUNNY_GIT:-/work/.mirror/dengnantianjie+3dcoursework/repo}
CGAL_SHA=78b09b23d4d6d1bf15552a1060b419ab3fc09918486462faed197e5fc6ac3735
BUN000_SHA=688d6b5ef4f8aebaeed9af9ed1605b6f4985a8e845ff5c015924f9b1d13f4b05
BUNNY_COMMIT=6630ded3bcb3b4006d8fb5887b96bc1aec2a6a6c

mkdir -p "$OUT/cache"
OUT=$(cd "$OUT" && pwd)
cache=$OUT/cache

# 1. CGAL data
deb=${CGAL_DEB:-$cache/libcgal-demo_5.5.1-2_all.deb}
if [[ ! -f $deb ]]; then
  echo "downloading libcgal-demo 5.5.1-2 (24 MB) ..." >&2
  (cd "$cache" && apt-get download libcgal-demo=5.5.1-2 > /dev/null 2>&1) \
    || { echo "apt-get download libcgal-demo=5.5.1-2 failed (run apt-get update? or set CGAL_DEB)" >&2; exit 1; }
fi
echo "$CGAL_SHA  $deb" | sha256sum -c --quiet - || { echo "checksum mismatch: $deb" >&2; exit 1; }
if [[ ! -d $cache/cgal/data/meshes ]]; then
  rm -rf "$cache/deb" "$cache/cgal" && mkdir -p "$cache/deb" "$cache/cgal"
  dpkg-deb -x "$deb" "$cache/deb"
  tar xzf "$cache/deb/usr/share/doc/libcgal-dev/data.tar.gz" -C "$cache/cgal"
  rm -rf "$cache/deb"
fi

# 2. Stanford bunny range images: bun000 alone, and all ten views with their registration
stanford=-
if git --git-dir="$BUNNY_GIT" cat-file -e "$BUNNY_COMMIT:bunny/data/bun000.ply" 2> /dev/null; then
  mkdir -p "$cache/stanford"
  while read -r sha file; do
    git --git-dir="$BUNNY_GIT" show "$BUNNY_COMMIT:bunny/data/$file" > "$cache/stanford/$file"
    echo "$sha  $cache/stanford/$file" | sha256sum -c --quiet - \
      || { echo "checksum mismatch: $file" >&2; exit 1; }
  done <<SUMS
$BUN000_SHA bun000.ply
ac61fef9a82c1a963fb33167209dbee5507cccddefed7b6c516c6c4cbd64eb2f bun045.ply
1eaabf4c24aac4f02d42fcc64ba1dc0b817b0575aca6bf61aa50a96ac464facd bun090.ply
e84e4a17666cc07ca2c353920b40336374763151c99a6dffb8e402c6190a5df1 bun180.ply
a97009be31db07947c28658ba208207f1edde7556f3892536c54bb514420bf16 bun270.ply
1a119403e3d2e654197c74419778e5599f96b4df309b2a0a6ed050104215a4db bun315.ply
047401ae93d9b3c52c762364cc2ad1938ff40ffcc133a8acb54c81bd7a38c6c7 chin.ply
e8b78473ec43b6cefe210fb4638c3666b2cf74d81ae552d832a6a600af63ca24 ear_back.ply
622c9e33f5e046aced4a3f7f66a0b04804ff6aa6e1113faabe24726dd05bb6e5 top2.ply
ccded0886e91bd3d2653f671c3bd45fad0228d2be54b9aa98f0ee6de60cbcbb2 top3.ply
4e205d6675e6284e5b185ed87cb8390884e103fd1bb9f9b54e340be7708aebeb bun.conf
SUMS
  stanford=$cache/stanford
else
  echo "no Stanford bunny range data at BUNNY_GIT=$BUNNY_GIT: bun000 inputs skipped" >&2
fi

# 3. inputs
echo "preparing inputs in $OUT ..." >&2
python3 "$(dirname "$0")/prepare.py" "$cache/cgal/data" "$SHARED_DATA" "$stanford" "$OUT"

# 4. the noisy 10^6 torus with its truth (sigma = 0.05% of the diagonal)
if [[ -x $BIN ]]; then
  "$BIN" generate torus --points 1000000 --seed 1 --noise 0.0005 \
    -o "$OUT/torus-1M-noise0.05.ply" --truth "$OUT/truth/torus.ply" > /dev/null
  printf 'torus-1M-noise0.05\t%s\t%s\t%s\tyes\t%s\n' "$OUT/torus-1M-noise0.05.ply" "$OUT/truth/torus.ply" \
    'closed: 1 watertight component, genus 1; mesh->truth Chamfer <= 1.5e-4' \
    '`rbfsurf generate torus --points 1000000 --seed 1 --noise 0.0005` (with normals)' >> "$OUT/manifest.tsv"
  "$BIN" generate two-spheres --points 20000 --seed 1 --no-normals -o "$OUT/two-spheres-xyz.ply" \
    --truth "$OUT/truth/two-spheres.ply" > /dev/null
  printf 'two-spheres-xyz\t%s\t%s\t%s\tno\t%s\n' "$OUT/two-spheres-xyz.ply" "$OUT/truth/two-spheres.ply" \
    'two closed objects: 2 watertight components, genus 0 each' \
    '`rbfsurf generate two-spheres --points 20000 --no-normals` (floater rule: two objects stay two)' >> "$OUT/manifest.tsv"
else
  echo "no rbfsurf binary at $BIN: synthetic inputs skipped" >&2
fi
# 5. the floor of the mesh->scan measure: the truth mesh's own distance to the plane of the points' neighbours
#    (noise and sampling), for the inputs that have a truth mesh
if [[ -x $BIN ]]; then
  : > "$OUT/floors.tsv"
  while IFS=$'\t' read -r name in ref _; do
    [[ $ref == - || $ref == onesided:* ]] && continue
    "$BIN" compare "$ref" "$in" --json 2> /dev/null \
      | python3 -c 'import json,sys; print(sys.argv[1] + "\t" + str(json.load(sys.stdin).get("mesh_to_ref_plane_mean_rel")))' "$name" \
      >> "$OUT/floors.tsv" || true
  done < "$OUT/manifest.tsv"
fi
(cd "$OUT" && find . -maxdepth 2 -type f \( -name '*.ply' -o -name '*.xyz' -o -name '*.off' \) \
  -not -path './cache/*' -not -path './out/*' | sort | xargs sha256sum > SHA256SUMS)
echo "$(wc -l < "$OUT/manifest.tsv") inputs in $OUT/manifest.tsv" >&2
