#!/usr/bin/env python3
"""Resampling sweep of the real-scan suite's closed statues: new random samples nobody tuned for.

The suite (prepare.py) holds one or two samples per statue; a default that only works on those
seeds is tuned to them. This writes, for every closed CGAL statue whose solid has a known genus,
fresh `x y z` samples with other seeds, sizes and noise into OUT with a manifest run.sh reads:

    python3 benches/realscans/sweep.py target/realscans/cache/cgal/data target/realscans-sweep
    DATA=target/realscans-sweep benches/realscans/run.sh BIN --no-peer --out /tmp/sweep.md

(prepare.sh must have run first: it unpacks the CGAL data into target/realscans/cache/cgal.)
Variants per statue: 3,000 points (seed 7), 5,000 (seeds 8 and 9), 10,000 with Gaussian noise
0.25 % of the diagonal (seed 10). Deterministic; writes SHA256SUMS like prepare.sh.
"""
import hashlib
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from prepare import add_noise, read_off, sample_mesh, strip, write_off, write_xyz  # noqa: E402

# The embedded closed statues of the suite with their solids' genus (truth_topology.py).
STATUES = [('armadillo', 0), ('elephant', 3), ('bear', 0), ('bull', 0), ('fandisk', 0),
           ('homer', 0), ('diplodocus', 0), ('ChineseDragon-10kv', 0), ('knot', 1),
           ('eight', 2), ('elk', 1)]
VARIANTS = [('3k-s7', 3000, 7, 0.0), ('5k-s8', 5000, 8, 0.0), ('5k-s9', 5000, 9, 0.0),
            ('10k-noise0.25-s10', 10000, 10, 0.0025)]


def main():
    cgal, out = sys.argv[1:3]
    os.makedirs(os.path.join(out, 'truth'), exist_ok=True)
    rows = []
    for mesh, genus in STATUES:
        verts, faces = read_off(os.path.join(cgal, 'meshes', mesh + '.off'))
        truth = os.path.join(out, 'truth', mesh + '.off')
        write_off(truth, verts, faces)
        for tag, n, seed, noise in VARIANTS:
            pts = sample_mesh(verts, faces, n, seed)
            what = '%s (CGAL meshes/%s.off, genus %d): %d area-uniform samples, seed %d' % (
                mesh, mesh, genus, n, seed)
            if noise:
                pts = add_noise(pts, noise, seed + 1000)
                what += ', noise %.2g%% of the diagonal' % (noise * 100)
            name = '%s-%s-xyz' % (mesh, tag)
            path = os.path.join(out, name + '.xyz')
            write_xyz(path, strip(pts))
            rows.append((name, path, truth, 'closed: 1 watertight component, genus %d' % genus,
                         'no', what + ', x y z only'))
            print('  %-34s %6d points' % (name, n), file=sys.stderr)
    with open(os.path.join(out, 'manifest.tsv'), 'w') as f:
        for r in rows:
            f.write('\t'.join(r) + '\n')
    with open(os.path.join(out, 'SHA256SUMS'), 'w') as f:
        for r in rows:
            digest = hashlib.sha256(open(r[1], 'rb').read()).hexdigest()
            f.write('%s  ./%s\n' % (digest, os.path.relpath(r[1], out)))
    print('%d inputs in %s/manifest.tsv' % (len(rows), out), file=sys.stderr)


if __name__ == '__main__':
    main()
