#!/usr/bin/env python3
"""Chamfer distance to the truth on fresh samples of closed statues, rbfsurf against PoissonRecon.

    python3 benches/realscans/heldout.py [--bin BIN] [--poisson POISSON_BIN] [--seeds 41,42]
                                         [--statues armadillo,camel,...] [--points 10000]

New area-uniform samples (seeds no default was chosen on) of the CGAL statues that
benches/realscans/prepare.sh unpacks into target/realscans/cache/cgal, with their true face
normals, are written to target/realscans-heldout. Both programs get the same normals and run with
their defaults (PoissonRecon `--depth 10`); rbfsurf also runs on the same points without normals
(`x y z`). Prints a Markdown table of `chamfer_rel` against the statue's mesh (`rbfsurf compare`),
relative to the bounding-box diagonal. POISSON_BIN defaults to /tmp/PoissonRecon/Bin/Linux/
PoissonRecon (built outside this repository from github.com/mkazhdan/PoissonRecon).
"""
import argparse
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from prepare import read_off, sample_mesh, write_off, write_ply, write_xyz  # noqa: E402

CGAL = 'target/realscans/cache/cgal/data/meshes'


def chamfer(bin_, mesh, truth):
    out = subprocess.run([bin_, 'compare', mesh, truth, '--json'], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out)['chamfer_rel']


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--bin', default='target/release/rbfsurf')
    ap.add_argument('--poisson', default=os.environ.get(
        'POISSON_BIN', '/tmp/PoissonRecon/Bin/Linux/PoissonRecon'))
    ap.add_argument('--seeds', default='41,42')
    ap.add_argument('--statues', default='armadillo,camel,bull,elephant,homer')
    ap.add_argument('--points', type=int, default=10000)
    ap.add_argument('--out', default='target/realscans-heldout')
    a = ap.parse_args()
    if not os.path.isdir(CGAL):
        sys.exit('no %s: run benches/realscans/prepare.sh first' % CGAL)
    os.makedirs(a.out, exist_ok=True)
    print('| sample | rbfsurf, true normals | PoissonRecon d10, true normals | rbfsurf, `x y z` |')
    print('|---|---|---|---|')
    wins = rows = 0
    for statue in a.statues.split(','):
        verts, faces = read_off(os.path.join(CGAL, statue + '.off'))
        truth = os.path.join(a.out, statue + '.off')
        write_off(truth, verts, faces)
        for seed in (int(s) for s in a.seeds.split(',')):
            name = os.path.join(a.out, '%s-%d-s%d' % (statue, a.points, seed))
            pts = sample_mesh(verts, faces, a.points, seed)
            write_ply(name + '.ply', pts)
            write_xyz(name + '.xyz', [p[:3] for p in pts])
            subprocess.run([a.bin, 'reconstruct', name + '.ply', '-o', name + '-r.obj'],
                           check=True, capture_output=True)
            subprocess.run([a.bin, 'reconstruct', name + '.xyz', '-o', name + '-x.obj'],
                           check=True, capture_output=True)
            subprocess.run([a.poisson, '--in', name + '.ply', '--out', name + '-p.ply',
                            '--depth', '10'], check=True, capture_output=True,
                           env=dict(os.environ, OMP_WAIT_POLICY='PASSIVE'))
            r, p, x = (chamfer(a.bin, name + s, truth) for s in ('-r.obj', '-p.ply', '-x.obj'))
            rows += 1
            wins += r < p
            print('| %s %d seed %d | %.3e | %.3e | %.3e |' % (statue, a.points, seed, r, p, x))
    print('\nrbfsurf lower than PoissonRecon with the same normals: %d of %d' % (wins, rows))


if __name__ == '__main__':
    main()
