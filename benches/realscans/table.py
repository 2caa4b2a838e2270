"""Markdown report of benches/realscans/run.sh.

Usage: table.py MANIFEST.tsv ROWS.tsv OUT.md LABEL PEER_KIND POISSON_DEPTH [LOAD_TEXT]

ROWS columns: name, tool, status, seconds, extra, components, watertight, genus, boundary_loops,
non_manifold_vertices, non_manifold_edges, triangles, mesh_to_scan_rel, chamfer_truth_rel, cpu_seconds.
The "meets" column is checked automatically where the expectation is mechanical:
closed objects: 1 component, watertight, the expected genus (two-spheres: 2 components, genus 0; a
truth that passes through itself has no genus to expect: "yes (genus G, unchecked)", counted apart);
everything else (open scans, scenes, separate pieces): no non-manifold vertex/edge (one sheet per
scanned piece and no blobs are for a human to check: comps/loops, and look at the mesh), and where the
expectation names it, mesh->scan <= 1e-3 (distance from mesh samples to the plane of the 8 nearest
input points, i.e. to the scan's surface).
"""
import os
import platform
import re
import sys

manifest_p, rows_p, out_p, label, peer, depth = sys.argv[1:7]
load = sys.argv[7] if len(sys.argv) > 7 else ''
manifest = [l.rstrip('\n').split('\t') for l in open(manifest_p) if l.strip()]
rows = [l.rstrip('\n').split('\t') for l in open(rows_p) if l.strip()]
floors_p = os.path.join(os.path.dirname(manifest_p), 'floors.tsv')
floors = dict(l.rstrip('\n').split('\t')[:2] for l in open(floors_p) if l.strip()) if os.path.exists(floors_p) else {}


def f(x):
    try:
        v = float(x)
    except ValueError:
        return x
    if v == 0:
        return '0'
    return f'{v:.2e}' if abs(v) < 0.01 else f'{v:.3g}'


# Marks the expectation of a closed object whose truth passes through itself (prepare.py).
UNCHECKED = 'genus unchecked'


def meets(expected, r):
    st, comps, wt, genus, loops, nmv, nme, tris, m2s = r[2], r[5], r[6], r[7], r[8], r[9], r[10], r[11], r[12]
    if st != 'ok':
        return 'no (' + st + ')'
    if expected.startswith('closed: 1 watertight component, ' + UNCHECKED):
        ok = comps == '1' and wt == 'True'
        return 'yes (genus %s, unchecked)' % genus if ok else 'no'
    m = re.match(r'closed: 1 watertight component, genus (\d+)', expected)
    if m:
        ok = comps == '1' and wt == 'True' and genus == m.group(1)
        return 'yes' if ok else 'no'
    if expected.startswith('two closed objects'):
        return 'yes' if comps == '2' and wt == 'True' and genus == '0' else 'no'
    if expected.startswith('closed object'):
        return 'yes' if comps == '1' and wt == 'True' else 'no'
    if nmv != '0' or nme != '0':
        return 'no (non-manifold)'
    if 'mesh->scan <= 1e-3' in expected:
        try:
            if float(m2s) > 1e-3:
                return 'no (mesh→scan)'
        except ValueError:
            return 'no (mesh→scan)'
    return 'manifold (sheets: check)'


peer_txt = {'native': f'native PoissonRecon (mkazhdan/PoissonRecon, `--depth {depth}`, defaults otherwise)',
            'open3d': f'Open3D screened Poisson (`create_from_point_cloud_poisson(depth={depth})`)',
            'none': 'none'}[peer]
out = []
out.append('# Real-scan benchmark\n')
out.append(f'Measured: {label}, {os.cpu_count()} cores, {platform.machine()} Linux' + (f' ({load}: the machine is shared, so wall times are noisy; cpu s = user + sys of the process is steadier)' if load else '') + '. '
           f'Command: `benches/realscans/prepare.sh BIN && benches/realscans/run.sh BIN`. rbfsurf runs with '
           f'**default parameters** (`rbfsurf reconstruct IN -o OUT.glb`). Peer: {peer_txt}; inputs without '
           'normals get Open3D normals first (15-NN PCA + `orient_normals_consistent_tangent_plane(15)`, '
           'time included in "s" and shown in "note").\n')
out.append('Columns: s = wall seconds of the whole process (Poisson: + Open3D normal estimation when the input has none); cpu s = user + sys seconds (GNU time); comps = connected components; wt = watertight; '
           'loops = boundary loops; nm v/e = non-manifold vertices/edges; tris = triangles; '
           'mesh→scan = mean distance from the mesh (100k area samples) to the scan\'s surface (the PCA plane of '
           'the 8 nearest input points), relative to the input bbox diagonal (`rbfsurf compare MESH INPUT --json`, '
           '`mesh_to_ref_plane_mean_rel`); '
           'Chamfer = `chamfer_rel` against the truth mesh (`rbfsurf compare MESH TRUTH`). Topology of both '
           'tools from `rbfsurf compare` on the written mesh. "meets" = the expected result below, checked '
           'mechanically (closed: 1 component, watertight, right genus, unchecked where the truth passes '
           'through itself; open/scene/pieces: manifold only — one sheet per piece and no blobs need a '
           'look at comps/loops and at the mesh; mesh→scan ≤ 1e-3 is checked '
           'where the expectation names it).\n')
out.append('| input | tool | status | s | cpu s | comps | wt | genus | loops | nm v/e | tris | mesh→scan | Chamfer | meets | note |')
out.append('|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|')
exp = {m[0]: m[3] for m in manifest}
for r in rows:
    r = r + ['-'] * (15 - len(r))
    out.append('| ' + ' | '.join([r[0], r[1], r[2], r[3], r[14], r[5], r[6], r[7], r[8], f'{r[9]}/{r[10]}', r[11],
                                   f(r[12]), f(r[13]), meets(exp.get(r[0], ''), r), r[4]]) + ' |')

tools = sorted({r[1] for r in rows})
out.append('\n## Summary\n')
out.append('| tool | runs | ok | meets (closed / open) | panics | timeouts | total s | total cpu s |')
out.append('|---|---|---|---|---|---|---|---|')
for t in tools:
    rs = [r for r in rows if r[1] == t]
    closed = [r for r in rs if exp.get(r[0], '').startswith(('closed', 'two closed'))]
    other = [r for r in rs if r not in closed]
    loose = [r for r in closed if UNCHECKED in exp.get(r[0], '')]
    strict = [r for r in closed if r not in loose]
    mc = sum(meets(exp.get(r[0], ''), r) == 'yes' for r in strict)
    mu = sum(meets(exp.get(r[0], ''), r).startswith('yes') for r in loose)
    mo = sum(meets(exp.get(r[0], ''), r).startswith('manifold') for r in other)
    tot = sum(float(r[3]) for r in rs if r[3] not in ('-', ''))
    cpu = sum(float(r[14]) for r in rs if len(r) > 14 and r[14] not in ('-', ''))
    unchecked = f' + {mu}/{len(loose)} with the genus unchecked' if loose else ''
    out.append(f'| {t} | {len(rs)} | {sum(r[2] == "ok" for r in rs)} | {mc}/{len(strict)} closed{unchecked}, '
               f'{mo}/{len(other)} open manifold | {sum(r[2] == "PANIC" for r in rs)} | '
               f'{sum(r[2].startswith("TIMEOUT") for r in rs)} | {tot:.0f} | {cpu:.0f} |')

out.append('\n## Inputs and the expected result\n')
out.append('Made by `benches/realscans/prepare.sh` into `target/realscans/` (provenance and licences: '
           '`benches/realscans/README.md`).\n')
out.append('"floor" = mesh→scan of the truth mesh itself (the measure\'s value for a perfect surface), '
           'where a truth mesh exists.\n')
out.append('| input | normals | what | expected | floor |')
out.append('|---|---|---|---|---|')
for m in manifest:
    out.append(f'| {m[0]} | {m[4]} | {m[5]} | {m[3]} | {f(floors.get(m[0], "-"))} |')
text = '\n'.join(out) + '\n'
open(out_p, 'w').write(text)
print(text)
