"""Make the real-scan suite's inputs deterministically (pure Python 3, no third-party modules).

Usage: prepare.py CGAL_DATA SHARED_DATA STANFORD_BUNNY_DATA OUT_DIR

  CGAL_DATA            the `data/` folder of CGAL's data.tar.gz (Debian libcgal-demo 5.5.1-2, CC0-1.0)
  SHARED_DATA          ../shared/data of the project (CGAL scans, CC0-1.0)
  STANFORD_BUNNY_DATA  a folder holding Stanford's bunny range image bun000.ply, or '-' to skip
  OUT_DIR              where inputs go (target/realscans); truth meshes go to OUT_DIR/truth/

Writes OUT_DIR/manifest.tsv: name, input, reference for accuracy ('-' none; a path: Chamfer against
that closed truth mesh; 'onesided:PATH': only the mesh->truth mean, for open scans), expected result,
normals ('yes'/'no'), what it is. benches/realscans/run.sh reads it. Every random choice uses
random.Random(seed) (Mersenne Twister; `random()` and `gauss()` give the same numbers on every
CPython 3), so the files are byte-identical from run to run; run.sh checks them against SHA256SUMS.
"""
import math
import os
import random
import shutil
import struct
import sys


# ----------------------------------------------------------------------------------------------
# I/O
def read_off(path):
    toks = []
    with open(path) as f:
        for line in f:
            line = line.split('#', 1)[0]
            toks.extend(line.split())
    head = toks[0]
    assert head.endswith('OFF'), path
    i = 1
    nv, nf = int(toks[i]), int(toks[i + 1])
    i += 3
    per_v = 3 + (4 if head.startswith('C') else 0)
    verts = []
    for _ in range(nv):
        verts.append(tuple(float(t) for t in toks[i:i + 3]))
        i += per_v
    faces = []
    for _ in range(nf):
        k = int(toks[i])
        idx = [int(t) for t in toks[i + 1:i + 1 + k]]
        i += 1 + k
        # colour fields after the indices: skip until the next line's count; OFF files here have
        # none on faces except COFF vertex colours, handled above. Fan-triangulate polygons.
        for j in range(1, k - 1):
            faces.append((idx[0], idx[j], idx[j + 1]))
    return verts, faces


def read_ply_vertices(path):
    """x y z (and nx ny nz if present) of a PLY's vertex element, ascii or binary little endian."""
    with open(path, 'rb') as f:
        data = f.read()
    end = data.index(b'end_header') + len(b'end_header')
    while data[end:end + 1] in (b'\r', b'\n'):
        end += 1
        if data[end - 1:end] == b'\n':
            break
    header = data[:end].decode('ascii', 'replace').splitlines()
    fmt = next(l.split()[1] for l in header if l.startswith('format'))
    elements, cur = [], None
    for l in header:
        p = l.split()
        if not p:
            continue
        if p[0] == 'element':
            cur = [p[1], int(p[2]), []]
            elements.append(cur)
        elif p[0] == 'property' and cur is not None:
            cur[2].append((p[-1], p[1:-1]))
    assert elements[0][0] == 'vertex', path
    name, n, props = elements[0]
    names = [p[0] for p in props]
    want = ['x', 'y', 'z'] + (['nx', 'ny', 'nz'] if 'nx' in names else [])
    cols = [names.index(w) for w in want]
    out = []
    if fmt == 'ascii':
        lines = data[end:].decode('ascii').split('\n')
        for l in lines[:n]:
            v = l.split()
            out.append(tuple(float(v[c]) for c in cols))
    else:
        assert fmt == 'binary_little_endian', path
        codes = {'float': 'f', 'float32': 'f', 'double': 'd', 'float64': 'd', 'uchar': 'B', 'uint8': 'B',
                 'char': 'b', 'int8': 'b', 'short': 'h', 'int16': 'h', 'ushort': 'H', 'uint16': 'H',
                 'int': 'i', 'int32': 'i', 'uint': 'I', 'uint32': 'I'}
        for pname, ptype in props:
            assert ptype[0] != 'list', (path, pname)
        st = struct.Struct('<' + ''.join(codes[p[1][0]] for p in props))
        off = end
        for _ in range(n):
            v = st.unpack_from(data, off)
            off += st.size
            out.append(tuple(float(v[c]) for c in cols))
    return out


def fmt(x):
    return repr(float(x)) if x != 0 else '0'


def write_ply(path, pts):
    """ASCII PLY, float x y z [nx ny nz] (values written with full double precision)."""
    normals = len(pts[0]) == 6
    with open(path, 'w') as f:
        f.write('ply\nformat ascii 1.0\nelement vertex %d\n' % len(pts))
        f.write('property float x\nproperty float y\nproperty float z\n')
        if normals:
            f.write('property float nx\nproperty float ny\nproperty float nz\n')
        f.write('end_header\n')
        for p in pts:
            f.write(' '.join('%.9g' % c for c in p) + '\n')


def write_xyz(path, pts):
    with open(path, 'w') as f:
        for p in pts:
            f.write('%.9g %.9g %.9g\n' % (p[0], p[1], p[2]))


def write_off(path, verts, faces):
    with open(path, 'w') as f:
        f.write('OFF\n%d %d 0\n' % (len(verts), len(faces)))
        for v in verts:
            f.write('%.9g %.9g %.9g\n' % v)
        for t in faces:
            f.write('3 %d %d %d\n' % t)


# ----------------------------------------------------------------------------------------------
# geometry
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def diagonal(pts):
    lo = [min(p[i] for p in pts) for i in range(3)]
    hi = [max(p[i] for p in pts) for i in range(3)]
    return math.sqrt(sum((hi[i] - lo[i]) ** 2 for i in range(3)))


def sample_mesh(verts, faces, n, seed):
    """n points, area-uniform on the triangles, with the face normal (made outward: the mesh's
    signed volume decides the sign)."""
    rng = random.Random(seed)
    cum, total, vol = [], 0.0, 0.0
    fn = []
    for a, b, c in faces:
        pa, pb, pc = verts[a], verts[b], verts[c]
        cr = cross(sub(pb, pa), sub(pc, pa))
        area = 0.5 * math.sqrt(cr[0] ** 2 + cr[1] ** 2 + cr[2] ** 2)
        vol += (pa[0] * (pb[1] * pc[2] - pb[2] * pc[1]) - pa[1] * (pb[0] * pc[2] - pb[2] * pc[0])
                + pa[2] * (pb[0] * pc[1] - pb[1] * pc[0])) / 6.0
        total += area
        cum.append(total)
        ln = 2.0 * area if area > 0 else 1.0
        fn.append((cr[0] / ln, cr[1] / ln, cr[2] / ln))
    sign = 1.0 if vol >= 0 else -1.0
    import bisect
    out = []
    for _ in range(n):
        k = bisect.bisect_left(cum, rng.random() * total)
        k = min(k, len(faces) - 1)
        a, b, c = faces[k]
        u, v = rng.random(), rng.random()
        if u + v > 1.0:
            u, v = 1.0 - u, 1.0 - v
        pa, pb, pc = verts[a], verts[b], verts[c]
        p = tuple(pa[i] + u * (pb[i] - pa[i]) + v * (pc[i] - pa[i]) for i in range(3))
        nrm = tuple(sign * x for x in fn[k])
        out.append(p + nrm)
    return out


def read_range_image(path):
    """A Stanford range-image PLY (ascii): its vertices, and the normal of each vertex from its
    range-grid neighbours (the cross product of the row and column differences, turned towards
    the scanner at +z); None for a vertex without a neighbour both along its row and its column."""
    with open(path, 'rb') as f:
        data = f.read()
    end = data.index(b'end_header') + len(b'end_header')
    head = data[:end].decode('ascii', 'replace').splitlines()
    body = data[end:].decode('ascii').split()
    nv = int(next(l.split()[2] for l in head if l.startswith('element vertex')))
    ng = int(next(l.split()[2] for l in head if l.startswith('element range_grid')))
    cols = int(next(l.split()[2] for l in head if 'num_cols' in l))
    rows = int(next(l.split()[2] for l in head if 'num_rows' in l))
    verts = [tuple(float(t) for t in body[3 * i:3 * i + 3]) for i in range(nv)]
    grid, i = [], 3 * nv
    for _ in range(ng):
        k = int(body[i])
        grid.append(int(body[i + 1]) if k > 0 else -1)
        i += 1 + k
    assert ng == rows * cols, path
    normals = [None] * nv

    def at(r, c):
        if 0 <= r < rows and 0 <= c < cols and grid[r * cols + c] >= 0:
            return verts[grid[r * cols + c]]
        return None

    for r in range(rows):
        for c in range(cols):
            v = grid[r * cols + c]
            if v < 0:
                continue
            x = verts[v]
            left, right, up, down = at(r, c - 1), at(r, c + 1), at(r - 1, c), at(r + 1, c)
            if not ((left or right) and (up or down)):
                continue
            du = [a - b for a, b in zip(right or x, left or x)]
            dv = [a - b for a, b in zip(down or x, up or x)]
            n = (du[1] * dv[2] - du[2] * dv[1], du[2] * dv[0] - du[0] * dv[2], du[0] * dv[1] - du[1] * dv[0])
            ln = math.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
            if ln > 0:
                s = 1.0 if n[2] >= 0 else -1.0
                normals[v] = tuple(s * c_ / ln for c_ in n)
    return verts, normals


def merge_range_images(folder):
    """The views listed in folder/bun.conf (`bmesh FILE tx ty tz qx qy qz qw`), registered into one
    frame: x' = R(q)^T x + t (the convention under which the ten bunny views agree). Returns the
    merged x y z of every vertex and, separately, x y z nx ny nz of the vertices that have a
    range-grid normal."""
    xyz, with_n = [], []
    for line in open(os.path.join(folder, 'bun.conf')):
        p = line.split()
        if not p or p[0] != 'bmesh':
            continue
        t = [float(v) for v in p[2:5]]
        qx, qy, qz, qw = (float(v) for v in p[5:9])
        ln = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        qx, qy, qz, qw = qx / ln, qy / ln, qz / ln, qw / ln
        r = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
             [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
             [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]]
        rot = lambda v: tuple(sum(r[c][k] * v[c] for c in range(3)) for k in range(3))
        verts, normals = read_range_image(os.path.join(folder, p[1]))
        for v, n in zip(verts, normals):
            w = tuple(a + b for a, b in zip(rot(v), t))
            xyz.append(w)
            if n is not None:
                with_n.append(w + rot(n))
    return xyz, with_n


def add_noise(pts, frac, seed):
    """Each point moves by sigma*g along a random direction, sigma = frac x bbox diagonal (the same
    model as `rbfsurf generate --noise`); normals are kept as they were."""
    rng = random.Random(seed)
    s = frac * diagonal(pts)
    out = []
    for p in pts:
        while True:
            d = (rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1))
            ln = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
            if ln > 1e-12:
                break
        g = rng.gauss(0, 1) * s / ln
        out.append((p[0] + g * d[0], p[1] + g * d[1], p[2] + g * d[2]) + tuple(p[3:]))
    return out


def subsample(pts, n, seed):
    rng = random.Random(seed)
    idx = sorted(rng.sample(range(len(pts)), n))
    return [pts[i] for i in idx]


def strip(pts):
    return [p[:3] for p in pts]


# ----------------------------------------------------------------------------------------------
def main():
    cgal, shared, stanford, out = sys.argv[1:5]
    os.makedirs(os.path.join(out, 'truth'), exist_ok=True)
    rows = []

    def add(name, pts, ref, expected, what, normals=None):
        has_n = len(pts[0]) == 6 if normals is None else normals
        if has_n:
            path = os.path.join(out, name + '.ply')
            write_ply(path, pts)
        else:
            path = os.path.join(out, name + '.xyz')
            write_xyz(path, strip(pts))
        rows.append((name, path, ref, expected, 'yes' if has_n else 'no', what))
        print('  %-28s %7d points  %s' % (name, len(pts), what), file=sys.stderr)

    def add_file(name, src, ref, expected, what, normals):
        ext = os.path.splitext(src)[1]
        path = os.path.join(out, name + ext)
        shutil.copyfile(src, path)
        rows.append((name, path, ref, expected, normals, what))
        print('  %-28s (copy)  %s' % (name, what), file=sys.stderr)

    # --- closed statues with thin parts: point samples of CGAL's closed meshes (truth known) ---
    def statue(mesh, genus, variants, embedded=True):
        verts, faces = read_off(os.path.join(cgal, 'meshes', mesh + '.off'))
        truth = os.path.join(out, 'truth', mesh + '.off')
        write_off(truth, verts, faces)
        exp = 'closed: 1 watertight component, genus %d' % genus
        if not embedded:
            # The truth passes through itself: its mesh genus is no surface's (truth_topology.py
            # counts its solid's handles: more at every finer voxel size), so only closure is checked.
            exp = ('closed: 1 watertight component, genus unchecked (the truth mesh passes through '
                   'itself: its solid has more handles the finer it is voxelized, truth_topology.py)')
        for tag, n, seed, noise, normals in variants:
            pts = sample_mesh(verts, faces, n, seed)
            what = '%s (CGAL meshes/%s.off, genus %d%s): %d area-uniform samples, seed %d' % (
                mesh, mesh, genus, '' if embedded else ' as a mesh, self-intersecting', n, seed)
            if noise:
                pts = add_noise(pts, noise, seed + 1000)
                what += ', noise %.2g%% of the diagonal' % (noise * 100)
            if not normals:
                pts = strip(pts)
                what += ', x y z only'
            else:
                what += ', true face normals'
            add('%s-%s' % (mesh, tag), pts, truth, exp, what)

    statue('armadillo', 0, [('10k-n', 10000, 1, 0, True), ('10k-xyz', 10000, 1, 0, False),
                            ('3k-xyz', 3000, 2, 0, False), ('26k-noise0.25-xyz', 26000, 3, 0.0025, False)])
    statue('camel', 0, [('10k-n', 10000, 1, 0, True), ('10k-xyz', 10000, 1, 0, False)], embedded=False)
    statue('man', 0, [('26k-xyz', 26000, 1, 0, False)], embedded=False)
    statue('elephant', 3, [('10k-xyz', 10000, 1, 0, False)])
    # Statues not used to tune the defaults (their solids' genus checked with truth_topology.py:
    # it converges to the listed one).
    for mesh, genus in [('bear', 0), ('bull', 0), ('fandisk', 0), ('homer', 0), ('diplodocus', 0),
                        ('ChineseDragon-10kv', 0), ('knot', 1), ('eight', 2), ('elk', 1)]:
        statue(mesh, genus, [('10k-xyz', 10000, 1, 0, False)])
    # The elk's other samples whose thin plates flip regions of the estimated normals when the
    # orientation does not vote per region (docs/robustness.md).
    statue('elk', 1, [('10k-s%d-xyz' % seed, 10000, seed, 0, False) for seed in (4, 5, 6)])

    # --- the shared CGAL scans ---
    bunny_ref = os.path.join(shared, 'bunny00.off')
    kit = read_ply_vertices(os.path.join(shared, 'kitten.ply'))
    add_file('kitten-n', os.path.join(shared, 'kitten.ply'), '-',
             'closed: 1 watertight component, genus 1', 'kitten statue, shared/data/kitten.ply, 5,210 oriented points', 'yes')
    add('kitten-xyz', strip(kit), '-', 'closed: 1 watertight component, genus 1',
        'kitten, normals stripped (as shared/tools/acceptance.sh does)')
    bun = read_ply_vertices(os.path.join(shared, 'bunny_cgal_10k.ply'))
    add_file('bunny10k-n', os.path.join(shared, 'bunny_cgal_10k.ply'), bunny_ref,
             'closed: 1 watertight component, genus 0', 'shared/data/bunny_cgal_10k.ply (oriented)', 'yes')
    add('bunny10k-xyz', strip(bun), bunny_ref, 'closed: 1 watertight component, genus 0',
        'bunny_cgal_10k, normals stripped')
    add('bunny10k-noise0.5-xyz', strip(add_noise(bun, 0.005, 11)), bunny_ref,
        'closed: 1 watertight component, genus 0', 'bunny_cgal_10k + noise 0.5% of the diagonal (seed 11), x y z only')
    add('bunny2k-xyz', strip(subsample(bun, 2000, 12)), bunny_ref, 'closed: 1 watertight component, genus 0',
        'random 2,000 of bunny_cgal_10k (seed 12), x y z only: sparse')
    for name, what, exp, normals in [
        ('hippo1.ply', 'two incomplete scans of a hippo figurine (missing parts, separate pieces), with normals',
         'partial scan: each scanned piece one manifold surface (closed where data surround it, else an open sheet), no floaters', 'yes'),
        ('hippo2.ply', 'second hippo scan (missing parts), with normals',
         'partial scan: each scanned piece one manifold surface, no floaters', 'yes'),
        ('oni.ply', 'very sparse scan of an oni head (1,435 points), with normals',
         'closed object: 1 watertight component, no floaters', 'yes'),
        ('radar.xyz', 'closed, roughly spherical object with surface detail, x y z only',
         'closed: 1 watertight component, genus 0', 'no'),
        ('poste_france.xyz', 'a few small dense clusters far apart, x y z only',
         'separate pieces: one surface per cluster, no floaters', 'no'),
        ('b9_training.ply', 'outdoor LiDAR scene (ground, buildings, vegetation), no normals',
         'open scene: open surface(s) on the data, manifold, mesh->scan <= 1e-3', 'no')]:
        add_file(os.path.splitext(name)[0], os.path.join(shared, name), '-', exp, what, normals)

    # --- architecture: CGAL points_3/point_set_3.xyz: a building standing on a ground patch ---
    bld = [tuple(map(float, l.split())) for l in open(os.path.join(cgal, 'points_3', 'point_set_3.xyz')) if l.strip()]
    exp = 'scene (building on a ground patch): one open surface, manifold, no blobs, mesh->scan <= 1e-3'
    add('building-8k-n', bld, '-', exp, 'CGAL points_3/point_set_3.xyz: building with planar walls and sharp edges on a ground patch, 8,075 points with normals')
    add('building-8k-xyz', strip(bld), '-', exp, 'the same building, x y z only')

    # --- a single-view range scan: Stanford bunny bun000.ply (Cyberware, 40,256 points) ---
    if stanford != '-' and os.path.exists(os.path.join(stanford, 'bun000.ply')):
        rs = read_ply_vertices(os.path.join(stanford, 'bun000.ply'))
        exp = 'open range scan: one manifold sheet (plus the real holes), mesh->scan <= 1e-3'
        add('bun000-range', rs, '-', exp,
            'Stanford bunny range image bun000.ply (one view, 40,256 points, x y z only, noisy borders)')
        add('bun000-range-10k', subsample(rs, 10000, 21), '-', exp, 'random 10,000 of bun000 (seed 21)')
    else:
        print('  (skipping bun000: no Stanford bunny range data given)', file=sys.stderr)

    # --- the ten bunny views merged (Stanford's registration): a real multi-view scan ---
    if stanford != '-' and os.path.exists(os.path.join(stanford, 'bun.conf')):
        xyz, with_n = merge_range_images(stanford)
        exp = 'closed: 1 watertight component, genus 0'
        add('bunny-range-merged', xyz, '-', exp,
            'the ten Stanford bunny range images merged with bun.conf (362,272 points, x y z only: '
            'overlapping views, registration error, silhouette mixed pixels, no data under the base)')
        add('bunny-range-merged-n', with_n, '-', exp,
            'the same views with range-grid normals towards each scanner position (361,766 points: '
            'vertices without a row and a column neighbour dropped)')

    with open(os.path.join(out, 'manifest.tsv'), 'w') as f:
        for r in rows:
            f.write('\t'.join(r) + '\n')


if __name__ == '__main__':
    main()
