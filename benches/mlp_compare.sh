#!/usr/bin/env bash
# Jiang & Turk's MLP approximator and its baselines against the thin-plate RBF curve
# (Turk–O'Brien) on Koch K2, Shen's 27 points and the five-point example.
# Runs the release binary, keeps the JSON reports and one side-by-side SVG per data set in
# benches/results/mlp/, and prints a markdown table (also written to benches/results/mlp/table.md).
# Usage: benches/mlp_compare.sh            (from the repository root; builds the release binary)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet --bin rbfsurf
BIN=${BIN:-target/release/rbfsurf}
OUT=benches/results/mlp
GRID=${GRID:-150}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$OUT"
# label|method|extra arguments
VARIANTS=(
  "turk-obrien|turk-obrien|"
  "mlp|mlp|"
  "mlp-noreg|mlp-noreg|"
  "mlp-constraint-curvature|mlp-constraint-curvature|"
  "mlp-dropout|mlp-dropout|"
  "mlp λ=5e-4|mlp|--lambda 0.0005"
)
for d in koch2 shen27 five-point; do
  i=0
  for v in "${VARIANTS[@]}"; do
    IFS='|' read -r label method extra <<<"$v"
    # shellcheck disable=SC2086
    "$BIN" curve --dataset "$d" --method "$method" --grid "$GRID" --quiet $extra \
      -o "$TMP/$d-$i.svg" --report "$OUT/$d-$i.json"
    printf '%s\n' "$label" >"$TMP/$d-$i.label"
    i=$((i + 1))
  done
done
python3 - "$OUT" "$TMP" "${#VARIANTS[@]}" <<'PY'
import json, re, sys
out, tmp, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
rows = ["| data set | method | components (closed, extra) | missed points | max deviation at data | curvature min / max | mean thin-plate energy | epochs | fit time (s) |",
        "|---|---|---|---|---|---|---|---|---|"]
num = re.compile(r'(\d+)\.\d+')
seg = re.compile(r'<line x1="([-\d]+)" y1="([-\d]+)" x2="([-\d]+)" y2="([-\d]+)" stroke="#([0-9a-f]{6})" stroke-width="([\d]+)"/>\n?')


def merge_lines(body):
    """Chain consecutive segments of (nearly) the same colour into polylines (colours rounded
    to multiples of 16 per channel) to keep the composite small."""
    out, run = [], None

    def flush():
        if run:
            pts = " ".join(f"{x},{y}" for x, y in run[2])
            out.append(f'<polyline points="{pts}" fill="none" stroke="#{run[0]}" stroke-width="{run[1]}"/>')

    pos = 0
    for m in seg.finditer(body):
        if m.start() != pos:
            flush(); run = None
            out.append(body[pos:m.start()])
        pos = m.end()
        x1, y1, x2, y2, col, w = m.groups()
        col = "".join(f"{min(255, round(int(col[i:i + 2], 16) / 16) * 16):02x}" for i in (0, 2, 4))
        if run and run[0] == col and run[1] == w and run[2][-1] == (x1, y1):
            if run[2][-1] != (x2, y2):
                run[2].append((x2, y2))
        else:
            flush()
            run = [col, w, [(x1, y1), (x2, y2)]]
    flush()
    out.append(body[pos:])
    return "".join(out)
for d in ["koch2", "shen27", "five-point"]:
    panels = []
    for i in range(n):
        r = json.load(open(f"{out}/{d}-{i}.json"))
        label = open(f"{tmp}/{d}-{i}.label").read().strip()
        q, t = r["quality"], r.get("training")
        f = lambda x, p=3: "∞" if x is None else f"{x:.{p}g}"
        rows.append(f"| {d} | {label} | {q['components']} ({q['closed_loops']}, {q['extra_loops']}) | "
                    f"{len(q['interpolation_failures'])} | {f(q['max_deviation_at_data'])} | "
                    f"{f(q['curvature_min'])} / {f(q['curvature_max'])} | "
                    f"{f(t['mean_energy_aux']) if t else '–'} | {t['epochs'] if t else '–'} | "
                    f"{r['timings_s']['fit']:.2f} |")
        svg = open(f"{tmp}/{d}-{i}.svg").read()
        head, body = svg.split(">", 1)
        vb = re.search(r'viewBox="([^"]+)"', head).group(1)
        body = body.rsplit("</svg>", 1)[0]
        body = re.sub(r'font-size="14">[^<]*<', f'font-size="22">{label}<', body, count=1)
        panels.append((vb, merge_lines(num.sub(r'\1', body))))
    w, h = 400, 312
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w * 3}" height="{h * 2}">']
    for k, (vb, body) in enumerate(panels):
        x, y = (k % 3) * w, (k // 3) * h
        parts.append(f'<svg x="{x}" y="{y}" width="{w}" height="{h}" viewBox="{vb}">{body}</svg>')
    parts.append("</svg>\n")
    open(f"{out}/{d}.svg", "w").write("\n".join(parts))
table = "\n".join(rows) + "\n"
open(f"{out}/table.md", "w").write(table)
print(table)
PY
ls -l "$OUT"/*.svg
