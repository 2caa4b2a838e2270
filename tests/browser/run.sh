#!/usr/bin/env bash
# Browser test of the viewer page: starts `rbfsurf serve`, drops data/kitten.ply on the page in
# headless Chromium, waits for "loaded N triangles", screenshots the canvas (tests/browser/out/)
# and checks that it shows the mesh. Skips (exit 0) when node or Chromium is not installed.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
chromium="${CHROMIUM:-/usr/bin/chromium}"
if ! command -v node >/dev/null 2>&1; then
  echo "browser test skipped: node is not installed"; exit 0
fi
if [ ! -x "$chromium" ]; then
  echo "browser test skipped: no Chromium at $chromium (apt-get install -y chromium, or set CHROMIUM)"; exit 0
fi
if [ ! -d "$here/node_modules/playwright-core" ]; then
  if ! command -v npm >/dev/null 2>&1; then
    echo "browser test skipped: npm is not installed to fetch playwright-core"; exit 0
  fi
  (cd "$here" && npm ci --no-audit --no-fund --silent)
fi
cd "$root"
cargo build --locked --quiet
bin="${CARGO_TARGET_DIR:-$root/target}/debug/rbfsurf"
data="$(mktemp -d)"
log="$data/serve.log"
mkdir -p "$here/out"
NO_COLOR=1 RUST_LOG=info "$bin" serve --addr 127.0.0.1:0 --data-dir "$data/jobs" >"$log" 2>&1 &
pid=$!
cleanup() { kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; rm -rf "$data"; }
trap cleanup EXIT
addr=""
for _ in $(seq 1 100); do
  addr="$(sed -n 's/.*listening addr=\([0-9.:]*\).*/\1/p' "$log" | head -n1)"
  [ -n "$addr" ] && break
  sleep 0.1
done
if [ -z "$addr" ]; then echo "server did not start:"; cat "$log"; exit 1; fi
node "$here/viewer.mjs" "http://$addr" "$root/data/kitten.ply" "$here/out/viewer.png"
