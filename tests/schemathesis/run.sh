#!/usr/bin/env bash
# Schemathesis (from PyPI, pinned) against the OpenAPI document the server serves, with all checks.
# Starts `rbfsurf serve` on a loopback port with small limits, runs `schemathesis run --checks all`
# and exits non-zero on any failure. Accepted by the configuration beside this script: a
# schema-valid body that is not a parseable point file answers 422 (`invalid_input`,
# `unreconstructable`) or 415 (sniffed as no point format).
# Usage: bash tests/schemathesis/run.sh [extra schemathesis options, e.g. --max-examples 50]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
cd "$root"
cargo build --locked --quiet
bin="${CARGO_TARGET_DIR:-$root/target}/debug/rbfsurf"
venv="${CARGO_TARGET_DIR:-$root/target}/schemathesis-venv"
if [ ! -x "$venv/bin/schemathesis" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet "schemathesis==4.32.5"
fi
data="$(mktemp -d)"
log="$data/serve.log"
NO_COLOR=1 RUST_LOG=info "$bin" serve --addr 127.0.0.1:0 --data-dir "$data/jobs" --workers 1 \
  --max-queue 64 --max-upload-mib 4 --max-points 20000 --max-memory-mib 512 \
  --max-resolution 64 --job-timeout-s 10 >"$log" 2>&1 &
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
cd "$here"
"$venv/bin/schemathesis" run "http://$addr/openapi.json" --checks all --workers 2 \
  --max-examples "${SCHEMATHESIS_EXAMPLES:-30}" "$@"
