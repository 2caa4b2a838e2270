"""Markdown tables of benches/large_scans.sh from its TSV rows.

Usage: large_scans_table.py RESULTS.tsv OUT.md QUICK(0/1) POISSON(0/1). Rows: input, N, tool, wall s,
core s, peak RSS MiB, chamfer_rel, hausdorff_rel, components, genus, watertight ('-' = unknown).
"""
import sys, platform, os
rows = [l.rstrip('\n').split('\t') for l in open(sys.argv[1]) if l.strip()]
quick, poisson = sys.argv[3] == '1', sys.argv[4] == '1'
out = []
cmd = 'benches/large_scans.sh' + (' --quick' if quick else '') + ('' if poisson else ' --no-poisson')
out.append(f'# Large-scan benchmark\n')
out.append(f'`{cmd}` on {os.cpu_count()} cores, {platform.machine()} Linux. '
           'time = wall seconds of the whole process (start-up, read, write included; GNU time), '
           'core = in-process reconstruction seconds (rbfsurf: report total − read − write; Poisson: '
           'normal estimation + Poisson), RSS = peak resident set. Accuracy: `rbfsurf compare OUT '
           'TRUTH --json` (relative to the reference bbox diagonal; synthetic: the truth mesh, '
           'kitten: its input points, bunny: data/bunny00.off); components/genus/watertight of the '
           'output mesh.\n')
out.append('| input | N | tool | time s | core s | peak RSS MiB | chamfer_rel | hausdorff_rel | components | genus | watertight |')
out.append('|---|---|---|---|---|---|---|---|---|---|---|')
def fmt(x):
    try:
        f = float(x)
    except ValueError:
        return x
    return f'{f:.2e}' if 0 < abs(f) < 0.01 else f'{f:.3g}'
for r in rows:
    r = r + ['-'] * (11 - len(r))
    out.append('| ' + ' | '.join([r[0], r[1], r[2], r[3], r[4], r[5], fmt(r[6]), fmt(r[7]), r[8], r[9], r[10]]) + ' |')
sizes = sorted({int(r[1]) for r in rows if r[0].startswith('torus-')})
if len(sizes) >= 2:
    lo, hi = sizes[0], sizes[-1]
    out.append(f'\n## Growth, clean torus {lo} → {hi} points ({hi // lo}×)\n')
    out.append('| tool | time s | time ratio | peak RSS MiB | RSS ratio |')
    out.append('|---|---|---|---|---|')
    for tool in sorted({r[2] for r in rows if r[0].startswith('torus-')}):
        a = [r for r in rows if r[0] == f'torus-{lo}' and r[2] == tool]
        b = [r for r in rows if r[0] == f'torus-{hi}' and r[2] == tool]
        if a and b:
            try:
                out.append(f'| {tool} | {a[0][3]} → {b[0][3]} | {float(b[0][3]) / float(a[0][3]):.1f}× | '
                           f'{a[0][5]} → {b[0][5]} | {float(b[0][5]) / float(a[0][5]):.1f}× |')
            except ValueError:
                out.append(f'| {tool} | {a[0][3]} → {b[0][3]} | - | {a[0][5]} → {b[0][5]} | - |')
text = '\n'.join(out) + '\n'
open(sys.argv[2], 'w').write(text)
print(text)
