//! Ray parity of unoriented splats: which side of a closed sampled surface a normal points to,
//! without trusting any other normal's sign.
//!
//! Every point is a disc (centre the point, plane its estimated normal line, radius the distance to
//! its [`RADIUS_NEIGHBOUR`]-th neighbour), so the discs cover the sampled surface. A ray leaving a
//! point of a closed surface outward crosses the surface an even number of times; inward, an odd
//! number. Hits along a ray are merged into crossings where they follow each other closer than the
//! discs' radii (overlapping discs of one sheet), and the point's own sheet is not counted. Seven
//! rays in a 25° cone around `+n` and seven around `−n` vote: the score is +1 when all fourteen say
//! the normal points outward, −1 when all say inward. The two axes and one cone ray per side go
//! first; when those four agree on outward the point scores +1 without the other ten (most points:
//! a third of the cost).
//!
//! This does not depend on the orientation of the other points, which is what the winding number
//! ([`super::dipole`]) does: on a plate thinner than the neighbourhood a wrongly oriented cluster
//! keeps its own winding number near zero, while its rays still see the plate's other face.
//! Measured (CGAL elk, 10k samples, seed 5): of the 143 normals the other steps leave flipped, 118
//! score below 0 (a prototype); of 1,500 correctly oriented points 7 do. Open sheets and holes make
//! the vote split (a ray leaves through a hole): points there score near 0, which is why the caller
//! acts only where almost every point gets a clear vote. Noise would split it too (a noisy
//! neighbour's disc, off the plane and tilted, adds a crossing next to the origin), so on a noisy
//! cloud the own sheet reaches [`NOISY_SHEET`] times the noise level.
//!
//! Rays are traced through a uniform grid of the discs (3D DDA), each disc tested once per ray.
//! Cost `O(targets · rays · (cells crossed + discs in them))`, parallel over targets: 0.13 s for
//! the 10k elk, 0.30 s for the 37,706-point bunny, 0.14 s for a noisy 26k statue on 2 cores; 0.05 s
//! on open scans, where only the gate sample is traced.

use rayon::prelude::*;

use crate::geometry::{Aabb, Point3, cross, dist2, dot, normalized, sub};
use crate::rbf::noise::median_quadric_residual;

/// The disc of a point reaches its this-th nearest neighbour.
const RADIUS_NEIGHBOUR: usize = 8;
/// Most discs in the grid; larger clouds keep an even stride of their points (radii grown to cover).
const SPLAT_BUDGET: usize = 250_000;
/// Most grid cells.
const MAX_CELLS: usize = 1 << 22;
/// Rays per side: the normal line and this many more on a cone around it.
const CONE_RAYS: usize = 6;
/// Half-angle of the cone, radians (25°).
const CONE_ANGLE: f64 = 0.436_332_312_998_582_4;
/// Hits closer to the ray's origin than this share of its disc radius belong to its own sheet
/// (neighbours' discs tilted by the normals' estimation error) and are not counted. Flips left
/// against true normals, summed over 11 CGAL samples (six of the elk, homer, bull, man, camel,
/// armadillo; 1,438 without this step): 0.35 → 1,302; 0.5 → 925; 0.6 → 882; 0.7 → 919;
/// 1.0 → 1,031.
const OWN_SHEET: f64 = 0.6;
/// On a noisy cloud the own sheet also reaches this many times the noise level σ
/// ([`noise_level`]): a noisy neighbour's disc lies off the origin's plane by about `σ√2` and is
/// tilted besides, so with only [`OWN_SHEET`] a ray out of a noisy sheet counts its own sheet and
/// the vote splits. Clean clouds (σ ≤ 0.06 of the disc radius: kitten, bunny, CGAL samples,
/// shared scans) keep [`OWN_SHEET`] almost everywhere; statues and knots with noise of 0.25–0.5 %
/// of the diagonal (σ ≈ 0.1–0.16 of the radius) get about one radius. Flips against true normals
/// summed over six noisy statues (armadillo 26k, bull, bunny, camel, elk, homer; 701 with
/// [`OWN_SHEET`] alone): 6σ → 622, 8σ → 536, **10σ → 516**, 12σ → 580; the torus and knot with
/// 0.5 % noise 18 → 32 / 14 / 9 / 4; every clean set the same but the armadillo 10k, 51 → 50.
const NOISY_SHEET: f64 = 10.0;
/// Points sampled for σ.
const NOISE_SAMPLES: usize = 1000;
/// Neighbours farther off a point's plane than this slope (30°) are on another sheet, not noise.
const TANGENT_SLOPE: f64 = 0.5;
/// Rays within this cosine of a disc's plane do not hit it (grazing: where they cross is unclear).
const MIN_COSINE: f32 = 0.1;

/// One disc, in coordinates relative to the grid's corner (single precision: the cells' lists are
/// copies, scanned in order).
#[derive(Clone, Copy)]
struct Disc {
    centre: [f32; 3],
    line: [f32; 3],
    radius: f32,
    id: u32,
}

/// Where rays start: a point, and how far from it hits belong to its own sheet.
struct Origin {
    at: Point3,
    own_sheet: f64,
}

/// Discs in a uniform grid; each cell holds copies of the discs its bounding boxes touch.
struct SplatGrid {
    count: usize,
    lo: Point3,
    cell: f64,
    dims: [usize; 3],
    /// Discs of cell `c`: `discs[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    discs: Vec<Disc>,
    /// The own sheet reaches at least this far on this cloud ([`NOISY_SHEET`] σ).
    noisy_sheet: f64,
}

/// The disc radius of point `i`: the distance to its [`RADIUS_NEIGHBOUR`]-th nearest neighbour
/// (the farthest listed when it has fewer).
fn disc_radius(points: &[Point3], neighbours: &[Vec<u32>], i: usize) -> f64 {
    let list = &neighbours[i];
    list.get(RADIUS_NEIGHBOUR - 1)
        .or(list.last())
        .map_or(0.0, |&j| dist2(points[i], points[j as usize]).sqrt())
}

/// The noise level σ of the cloud: the median quadric-fit residual of [`NOISE_SAMPLES`] evenly
/// spread points with those of their neighbours that lie within [`TANGENT_SLOPE`] of their
/// plane (about 0 for clean samples, curvature the quadric follows adding nothing; the other face
/// of a plate thinner than the neighbourhood is left out, or it would count as noise).
fn noise_level(points: &[Point3], normals: &[Point3], neighbours: &[Vec<u32>]) -> f64 {
    let n = points.len();
    median_quadric_residual((0..n).step_by(n.div_ceil(NOISE_SAMPLES).max(1)).map(|i| {
        let line = normalized(normals[i]).unwrap_or([0.0; 3]);
        let mut nb: Vec<Point3> = neighbours[i]
            .iter()
            .map(|&j| points[j as usize])
            .filter(|&q| {
                let d = sub(q, points[i]);
                dot(d, line).abs() <= TANGENT_SLOPE * dot(d, d).sqrt()
            })
            .collect();
        nb.push(points[i]);
        nb
    }))
}

/// The unit vector `d` and [`CONE_RAYS`] unit vectors at [`CONE_ANGLE`] around it.
fn cone(d: Point3) -> [Point3; CONE_RAYS + 1] {
    let a = if d[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = normalized(cross(d, a)).unwrap_or([0.0, 0.0, 1.0]);
    let v = cross(d, u);
    let (s, c) = CONE_ANGLE.sin_cos();
    let mut out = [d; CONE_RAYS + 1];
    for (k, o) in out.iter_mut().skip(1).enumerate() {
        let phi = std::f64::consts::TAU * k as f64 / CONE_RAYS as f64;
        let (sp, cp) = phi.sin_cos();
        *o = std::array::from_fn(|a| c * d[a] + s * (cp * u[a] + sp * v[a]));
    }
    out
}

impl SplatGrid {
    /// `None` when no point has a disc.
    fn new(points: &[Point3], normals: &[Point3], neighbours: &[Vec<u32>]) -> Option<Self> {
        let n = points.len();
        let stride = n.div_ceil(SPLAT_BUDGET).max(1);
        let grow = (stride as f64).sqrt();
        let mut discs: Vec<(Point3, Point3, f64)> = Vec::new();
        for i in (0..n).step_by(stride) {
            let r = disc_radius(points, neighbours, i) * grow;
            if let Some(m) = normalized(normals[i]).filter(|_| r > 0.0) {
                discs.push((points[i], m, r));
            }
        }
        if discs.is_empty() {
            return None;
        }
        let mut radii: Vec<f64> = discs.iter().map(|d| d.2).collect();
        let mid = radii.len() / 2;
        let median = *radii.select_nth_unstable_by(mid, f64::total_cmp).1;
        let centres: Vec<Point3> = discs.iter().map(|d| d.0).collect();
        let bbox = Aabb::from_points(&centres);
        let largest = radii.iter().fold(0.0f64, |a, &b| a.max(b));
        let lo = bbox.min.map(|v| v - largest);
        let extent = sub(bbox.max, lo).map(|v| v + largest);
        let volume = extent.iter().product::<f64>();
        let cell = (2.0 * median).max((volume / MAX_CELLS as f64).cbrt());
        let dims = extent.map(|e| ((e / cell).ceil() as usize).max(1));
        let mut grid = SplatGrid {
            count: discs.len(),
            lo,
            cell,
            dims,
            start: Vec::new(),
            discs: Vec::new(),
            noisy_sheet: NOISY_SHEET * noise_level(points, normals, neighbours),
        };
        grid.fill_cells(&discs);
        Some(grid)
    }

    /// Counting sort of the discs `(centre, unit line, radius)` into every cell their bounding
    /// box touches.
    fn fill_cells(&mut self, discs: &[(Point3, Point3, f64)]) {
        let cells = self.dims.iter().product::<usize>();
        let cover = |(c, _, r): &(Point3, Point3, f64)| -> [(usize, usize); 3] {
            std::array::from_fn(|a| {
                let at = |x: f64| {
                    (((x - self.lo[a]) / self.cell).floor().max(0.0) as usize).min(self.dims[a] - 1)
                };
                (at(c[a] - r), at(c[a] + r))
            })
        };
        let each = |d: &(Point3, Point3, f64), f: &mut dyn FnMut(usize)| {
            let [x, y, z] = cover(d);
            for k in z.0..=z.1 {
                for j in y.0..=y.1 {
                    for i in x.0..=x.1 {
                        f((k * self.dims[1] + j) * self.dims[0] + i);
                    }
                }
            }
        };
        let mut start = vec![0u32; cells + 1];
        for d in discs {
            each(d, &mut |c| start[c + 1] += 1);
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        let mut next = start.clone();
        let empty = Disc {
            centre: [0.0; 3],
            line: [0.0; 3],
            radius: 0.0,
            id: 0,
        };
        let mut out = vec![empty; start[cells] as usize];
        for (id, d) in discs.iter().enumerate() {
            let disc = Disc {
                centre: std::array::from_fn(|a| (d.0[a] - self.lo[a]) as f32),
                line: d.1.map(|v| v as f32),
                radius: d.2 as f32,
                id: id as u32,
            };
            each(d, &mut |c| {
                out[next[c] as usize] = disc;
                next[c] += 1;
            });
        }
        self.start = start;
        self.discs = out;
    }

    /// Parity scores in `[−1, 1]` of the normals of `targets` (indices into `points`): +1 when
    /// every ray says the normal points out of the closed surface the discs make, −1 when every
    /// ray says it points in (see the module doc); 0 for a point without a normal or a neighbour.
    fn scores(
        &self,
        points: &[Point3],
        normals: &[Point3],
        neighbours: &[Vec<u32>],
        targets: &[u32],
    ) -> Vec<f64> {
        targets
            .par_iter()
            .map_init(
                || (vec![u32::MAX; self.count], 0u32, Vec::new()),
                |(stamp, ray, hits), &i| {
                    let i = i as usize;
                    let own = disc_radius(points, neighbours, i);
                    let Some(n) = normalized(normals[i]).filter(|_| own > 0.0) else {
                        return 0.0;
                    };
                    let rays = [cone(n), cone(n.map(|v| -v))];
                    let mut vote = |k: usize, side: usize| {
                        *ray = ray.wrapping_add(1);
                        if *ray == u32::MAX {
                            stamp.fill(u32::MAX);
                            *ray = 0;
                        }
                        let origin = Origin {
                            at: points[i],
                            own_sheet: (OWN_SHEET * own).max(self.noisy_sheet),
                        };
                        let c = self.crossings(&origin, rays[side][k], *ray, stamp, hits);
                        // Outward (+n) rays should cross an even number of times, inward odd.
                        if (c % 2 == 1) == (side == 1) { 1 } else { -1 }
                    };
                    // The two axes and one cone ray each side first: when all four say outward,
                    // the point is taken as clearly outward without the others.
                    let first = [(0, 0), (0, 1), (1, 0), (1 + CONE_RAYS / 2, 1)];
                    let mut votes: i32 = first.iter().map(|&(k, side)| vote(k, side)).sum();
                    if votes == first.len() as i32 {
                        return 1.0;
                    }
                    for side in 0..2 {
                        for k in 1..=CONE_RAYS {
                            if !first.contains(&(k, side)) {
                                votes += vote(k, side);
                            }
                        }
                    }
                    f64::from(votes) / (2 * (CONE_RAYS + 1)) as f64
                },
            )
            .collect()
    }

    /// Surface crossings of the ray `o + t d` (`t > 0`, unit `d`, `o` the origin) through the
    /// grid, not counting the origin's own sheet (hits closer than `origin.own_sheet`). `ray` and
    /// `stamp` test each disc once; `hits` is scratch.
    fn crossings(
        &self,
        origin: &Origin,
        d: Point3,
        ray: u32,
        stamp: &mut [u32],
        hits: &mut Vec<(f32, f32)>,
    ) -> usize {
        hits.clear();
        let o = origin.at;
        let of: [f32; 3] = std::array::from_fn(|a| (o[a] - self.lo[a]) as f32);
        let df = d.map(|v| v as f32);
        let near = origin.own_sheet as f32;
        self.walk(o, d, |cell| {
            let (a, b) = (self.start[cell] as usize, self.start[cell + 1] as usize);
            for disc in &self.discs[a..b] {
                let cos = df[0] * disc.line[0] + df[1] * disc.line[1] + df[2] * disc.line[2];
                if cos.abs() < MIN_COSINE || stamp[disc.id as usize] == ray {
                    continue;
                }
                stamp[disc.id as usize] = ray;
                let w: [f32; 3] = std::array::from_fn(|k| disc.centre[k] - of[k]);
                let t = (w[0] * disc.line[0] + w[1] * disc.line[1] + w[2] * disc.line[2]) / cos;
                if t <= near {
                    continue;
                }
                let q: [f32; 3] = std::array::from_fn(|k| t * df[k] - w[k]);
                if q[0] * q[0] + q[1] * q[1] + q[2] * q[2] <= disc.radius * disc.radius {
                    hits.push((t, disc.radius));
                }
            }
        });
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut count = 0;
        let mut last: Option<(f32, f32)> = None;
        for &(t, r) in hits.iter() {
            match last {
                Some((lt, lr)) if t - lt <= r.max(lr) => {}
                _ => count += 1,
            }
            last = Some((t, r));
        }
        count
    }

    /// Visit the cells the ray `o + t d` (`t ≥ 0`) passes through, in order (Amanatides–Woo).
    fn walk(&self, o: Point3, d: Point3, mut visit: impl FnMut(usize)) {
        let mut idx = [0i64; 3];
        let mut step = [0i64; 3];
        let mut next = [f64::INFINITY; 3];
        let mut delta = [f64::INFINITY; 3];
        for a in 0..3 {
            let x = (o[a] - self.lo[a]) / self.cell;
            idx[a] = (x.floor() as i64).clamp(0, self.dims[a] as i64 - 1);
            if d[a] > 0.0 {
                step[a] = 1;
                next[a] = ((idx[a] + 1) as f64 - x) * self.cell / d[a];
                delta[a] = self.cell / d[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                next[a] = (idx[a] as f64 - x) * self.cell / d[a];
                delta[a] = -self.cell / d[a];
            }
        }
        loop {
            let cell =
                (idx[2] as usize * self.dims[1] + idx[1] as usize) * self.dims[0] + idx[0] as usize;
            visit(cell);
            let a = if next[0] <= next[1] && next[0] <= next[2] {
                0
            } else if next[1] <= next[2] {
                1
            } else {
                2
            };
            idx[a] += step[a];
            if idx[a] < 0 || idx[a] >= self.dims[a] as i64 {
                return;
            }
            next[a] += delta[a];
        }
    }
}

/// Most points whose rays are traced; larger clouds use an even stride of their points.
const PARITY_BUDGET: usize = 60_000;
/// Points traced first, over the whole cloud, to judge which components the vote is reliable on.
const GATE_SAMPLE: usize = 4096;
/// A vote is clear when its score is at least this far from 0 (12 of the 14 rays agree).
const CLEAR: f64 = 0.7;
/// A connected component is judged by parity only when this share of its gate sample gets a
/// clear vote. Measured with the own sheet grown on noisy clouds ([`NOISY_SHEET`]): closed
/// surfaces 0.78–1.0 (CGAL statues and elk samples, 2k–38k points, the Chinese dragon 0.80, the
/// generated shapes; statues, torus and knot with 0.25–0.5 % noise 0.90–0.99); open or partial
/// scans 0.00–0.61 (oni 0.61, the building 0.49, the outdoor scene b9 0.23, the shared partial
/// scans and a single range image ≤ 0.03). Before the own sheet grew with the noise, noisy
/// closed clouds scored 0.58–0.73 and sat at the gate.
const RELIABLE_SHARE: f64 = 0.755;
/// Fewest gate samples in a judged component.
const MIN_JUDGED: usize = 32;
/// A point not traced takes the score of its nearest traced neighbour whose normal line agrees
/// this well (cosine): one on the same sheet, not across a thin plate.
const SAME_SHEET: f64 = 0.9;
/// A point in a judged component is flipped when its score is below this.
const FLIP_SCORE: f64 = -0.3;

/// The points whose normals ray parity says point inward (see the module doc): points scoring
/// below [`FLIP_SCORE`] in connected components (`component[i]` per point) where the vote is
/// reliable, i.e. most points get a clear vote (judged on an even sample of [`GATE_SAMPLE`]
/// points first, so that open, noisy or holed scans cost only the sample). Points not traced
/// (clouds over [`PARITY_BUDGET`]) take the score of their nearest traced neighbour on the same
/// sheet, signed by `n_i·n_j`.
pub(crate) fn parity_flips(
    points: &[Point3],
    normals: &[Point3],
    neighbours: &[Vec<u32>],
    component: &[u32],
) -> Vec<u32> {
    let n = points.len();
    let Some(grid) = SplatGrid::new(points, normals, neighbours) else {
        return Vec::new();
    };
    let mut score = vec![f64::NAN; n];
    let gate: Vec<u32> = (0..n as u32)
        .step_by(n.div_ceil(GATE_SAMPLE).max(1))
        .collect();
    for (&t, s) in gate
        .iter()
        .zip(grid.scores(points, normals, neighbours, &gate))
    {
        score[t as usize] = s;
    }
    let components = component.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let (mut clear, mut sampled) = (vec![0usize; components], vec![0usize; components]);
    for &t in &gate {
        let c = component[t as usize] as usize;
        sampled[c] += 1;
        clear[c] += usize::from(score[t as usize].abs() >= CLEAR);
    }
    let judged: Vec<bool> = (0..components)
        .map(|c| sampled[c] >= MIN_JUDGED && clear[c] as f64 >= RELIABLE_SHARE * sampled[c] as f64)
        .collect();
    let rest: Vec<u32> = (0..n as u32)
        .step_by(n.div_ceil(PARITY_BUDGET).max(1))
        .filter(|&i| judged[component[i as usize] as usize] && score[i as usize].is_nan())
        .collect();
    for (&t, s) in rest
        .iter()
        .zip(grid.scores(points, normals, neighbours, &rest))
    {
        score[t as usize] = s;
    }
    let line = |i: usize| normalized(normals[i]).unwrap_or([0.0; 3]);
    // Each point's score: its own, or (not traced) its nearest traced neighbour's on its sheet.
    let signed: Vec<f64> = (0..n)
        .map(|i| {
            if !score[i].is_nan() {
                return score[i];
            }
            neighbours[i]
                .iter()
                .map(|&j| j as usize)
                .map(|j| (j, dot(line(i), line(j))))
                .find(|&(j, c)| !score[j].is_nan() && c.abs() >= SAME_SHEET)
                .map_or(0.0, |(j, c)| c.signum() * score[j])
        })
        .collect();
    (0..n)
        .filter(|&i| judged[component[i] as usize] && signed[i] < FLIP_SCORE)
        .map(|i| i as u32)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere of `n` evenly spread points and their outward normals.
    fn sphere(n: usize, centre: Point3, r: f64) -> (Vec<Point3>, Vec<Point3>) {
        (0..n)
            .map(|i| {
                let d = crate::geometry::fibonacci_direction(i, n);
                (std::array::from_fn(|a| centre[a] + r * d[a]), d)
            })
            .unzip()
    }

    fn neighbours(points: &[Point3], k: usize) -> Vec<Vec<u32>> {
        crate::normals::estimate_normals(points, k).1
    }

    fn parity_scores(p: &[Point3], n: &[Point3], nb: &[Vec<u32>], targets: &[u32]) -> Vec<f64> {
        SplatGrid::new(p, n, nb).unwrap().scores(p, n, nb, targets)
    }

    #[test]
    fn rays_tell_outward_from_inward_on_nested_spheres() {
        // A sphere inside a sphere (a hollow ball): both surfaces' outward normals point away from
        // the solid shell, so the inner sphere's point *towards* the centre.
        let (mut p, mut nrm) = sphere(3000, [0.0; 3], 1.0);
        let (p2, n2) = sphere(1500, [0.0; 3], 0.6);
        p.extend(p2);
        nrm.extend(n2.iter().map(|v| v.map(|x| -x)));
        let nb = neighbours(&p, 12);
        let targets: Vec<u32> = (0..p.len() as u32).step_by(7).collect();
        let right = parity_scores(&p, &nrm, &nb, &targets);
        assert!(right.iter().all(|&s| s > 0.5), "{:?}", &right[..10]);
        let flipped: Vec<Point3> = nrm.iter().map(|v| v.map(|x| -x)).collect();
        let wrong = parity_scores(&p, &flipped, &nb, &targets);
        assert!(wrong.iter().all(|&s| s < -0.5), "{:?}", &wrong[..10]);
    }

    #[test]
    fn an_open_sheet_gets_no_clear_vote() {
        // A hemisphere: rays leave through the open side either way.
        let (all, normals) = sphere(4000, [0.0; 3], 1.0);
        let (p, nrm): (Vec<Point3>, Vec<Point3>) = all
            .into_iter()
            .zip(normals)
            .filter(|(p, _)| p[2] > 0.0)
            .unzip();
        let nb = neighbours(&p, 12);
        let targets: Vec<u32> = (0..p.len() as u32).step_by(5).collect();
        let s = parity_scores(&p, &nrm, &nb, &targets);
        let clear = s.iter().filter(|v| v.abs() >= 0.6).count();
        assert!(clear * 4 < s.len(), "{clear} of {}", s.len());
    }

    /// A closed slab `[0, 1]² × [0, t]` on a grid of spacing `h`, outward normals.
    fn slab(h: f64, t: f64) -> (Vec<Point3>, Vec<Point3>) {
        let m = (1.0 / h).round() as usize;
        let layers = (t / h).round().max(1.0) as usize;
        let mut out = Vec::new();
        for i in 0..=m {
            for j in 0..=m {
                let (x, y) = (i as f64 * h, j as f64 * h);
                out.push(([x, y, t], [0.0, 0.0, 1.0]));
                out.push(([x, y, 0.0], [0.0, 0.0, -1.0]));
            }
        }
        for k in 1..layers {
            let z = t * k as f64 / layers as f64;
            for i in 0..=m {
                let u = i as f64 * h;
                out.push(([u, 0.0, z], [0.0, -1.0, 0.0]));
                out.push(([u, 1.0, z], [0.0, 1.0, 0.0]));
                out.push(([0.0, u, z], [-1.0, 0.0, 0.0]));
                out.push(([1.0, u, z], [1.0, 0.0, 0.0]));
            }
        }
        out.into_iter().unzip()
    }

    /// Parity on one component with `given` normals flips at least `share` of the points `wrong`
    /// marks (more than 100 of them) and at most 0.5 % of the others.
    fn assert_wrong_found(
        p: &[Point3],
        given: &[Point3],
        nb: &[Vec<u32>],
        wrong: impl Fn(&Point3) -> bool,
        share: f64,
    ) {
        let flips = parity_flips(p, given, nb, &vec![0; p.len()]);
        let expected = p.iter().filter(|q| wrong(q)).count();
        let right = flips.iter().filter(|&&i| wrong(&p[i as usize])).count();
        assert!(
            expected > 100 && right as f64 >= share * expected as f64,
            "{right} of {expected}"
        );
        let others = flips.len() - right;
        assert!(others <= p.len() / 200, "{others} others of {}", p.len());
    }

    #[test]
    fn wrong_patches_on_a_plate_thinner_than_the_neighbourhood_are_found() {
        // A plate two spacings thick: a point's 12 neighbours reach the other face, and a wrong
        // patch of either face keeps its winding number near zero; its rays still see the other face.
        let (p, truth) = slab(0.02, 0.04);
        let wrong = |q: &Point3| {
            let top = q[2] > 0.03 && (0.3..0.5).contains(&q[0]) && (0.3..0.5).contains(&q[1]);
            let bottom = q[2] < 0.01 && (0.6..0.7).contains(&q[0]) && (0.2..0.3).contains(&q[1]);
            top || bottom
        };
        let given: Vec<Point3> = p
            .iter()
            .zip(&truth)
            .map(|(q, n)| if wrong(q) { n.map(|v| -v) } else { *n })
            .collect();
        let nb = neighbours(&p, 12);
        assert_wrong_found(&p, &given, &nb, wrong, 0.95);
        // Consistent normals: (almost) nothing to flip.
        let none = parity_flips(&p, &truth, &nb, &vec![0; p.len()]);
        assert!(none.len() <= p.len() / 200, "{} of {}", none.len(), p.len());
    }

    #[test]
    fn a_noisy_closed_surface_gets_a_clear_vote_and_its_wrong_patch_is_found() {
        // A trefoil knot tube with Gaussian noise of 0.5 % of the diagonal (about 0.15 disc radii)
        // and its estimated (noisy) lines. Counting the own sheet's noisy discs splits the vote
        // (measured: 0.58 of the points clear); the own sheet reaching NOISY_SHEET σ keeps it
        // clear (0.92), and a wrong patch is flipped back.
        use crate::geometry::synthetic::{Defects, Shape, apply_defects};
        let mut cloud = Shape::by_name("knot").unwrap().sample(10000, 11);
        let noise = Defects {
            noise_rel: 0.005,
            ..Defects::default()
        };
        apply_defects(&mut cloud, &noise, 3).unwrap();
        let p = cloud.points;
        let truth = cloud.normals.unwrap();
        let (lines, nb) = crate::normals::estimate_normals(&p, 12);
        let seed = p[0];
        let wrong = |q: &Point3| dist2(*q, seed) < 0.08 * 0.08;
        let given: Vec<Point3> = (0..p.len())
            .map(|i| {
                let outward = dot(lines[i], truth[i]) >= 0.0;
                let s = if outward != wrong(&p[i]) { 1.0 } else { -1.0 };
                lines[i].map(|v| s * v)
            })
            .collect();
        let sample: Vec<u32> = (0..p.len() as u32).step_by(3).collect();
        let clear = |grid: &SplatGrid| {
            let s = grid.scores(&p, &given, &nb, &sample);
            s.iter().filter(|v| v.abs() >= CLEAR).count() as f64 / s.len() as f64
        };
        let mut grid = SplatGrid::new(&p, &given, &nb).unwrap();
        let with_noise = clear(&grid);
        grid.noisy_sheet = 0.0;
        let without = clear(&grid);
        assert!(
            with_noise >= 0.85 && without < RELIABLE_SHARE,
            "clear votes {with_noise} with the noise reach, {without} without"
        );
        assert_wrong_found(&p, &given, &nb, wrong, 0.9);
    }

    #[test]
    fn an_open_sheet_is_not_flipped_even_when_it_points_inward() {
        // The hemisphere's votes split, so nothing is flipped, however wrong its normals are.
        let (all, normals) = sphere(4000, [0.0; 3], 1.0);
        let (p, nrm): (Vec<Point3>, Vec<Point3>) = all
            .into_iter()
            .zip(normals)
            .filter(|(p, _)| p[2] > 0.0)
            .map(|(p, n)| (p, n.map(|v| -v)))
            .unzip();
        let nb = neighbours(&p, 12);
        assert!(parity_flips(&p, &nrm, &nb, &vec![0; p.len()]).is_empty());
    }
}
