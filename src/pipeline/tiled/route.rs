//! Prepare's partition pass and the per-block clean-up after it.
//!
//! [`route`] streams the input once more and appends every finite point (with its global id and
//! unit normal) to the spill file of each block whose core, inflated by a margin, contains it:
//! buffered, append-only writes, at most [`SPILL_BUFFER_BYTES`] buffered in all. [`finish_block`]
//! then turns one spill file into the block's stored point set: it merges duplicates with the
//! in-memory cleaning's rule (a point is dropped when a point of lower id lies within the
//! tolerance), which needs only the points within the tolerance of it — all in the file, since
//! the margin covers the block's reach plus the tolerance — so every block that holds a point
//! makes the same keep/drop decision for it.

use super::store::PointSet;
use super::survey::{TiledInput, finite, unit_normal};
use crate::error::{ReconError, StoreError};
use crate::geometry::{Aabb, Normalization, Point3};
use crate::spatial::{IndexKind, build_index};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Bytes of spill buffers held at once over all blocks (64 MiB), bounded per block to
/// 16 KiB – 1 MiB.
pub(crate) const SPILL_BUFFER_BYTES: usize = 64 << 20;

/// Cells per axis of the lookup grid from a point to the blocks that may hold it.
const LOOKUP_CELLS: usize = 32;

/// One spilled point: global id, position (normalised units), unit normal or zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Record {
    pub id: u32,
    pub p: Point3,
    pub n: Point3,
}

/// Bytes of one record on disk: u32 id, 3 f64, and 3 f64 more with normals.
fn record_bytes(normals: bool) -> usize {
    if normals { 52 } else { 28 }
}

fn io_err(path: &Path, source: std::io::Error) -> ReconError {
    ReconError::Store(StoreError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Part `part` of provisional block `b`'s spill in `dir`: the points of one input range (one
/// part when the input is read whole), read back in part order.
pub(crate) fn spill_path(dir: &Path, b: usize, part: usize) -> PathBuf {
    dir.join(format!("spill-{b}-{part}"))
}

/// From a point to the indices of the boxes that may contain it: a uniform grid over the boxes'
/// union, each cell listing the boxes that meet it.
struct Lookup {
    min: Point3,
    cell: f64,
    cells: Vec<Vec<u32>>,
}

impl Lookup {
    fn new(boxes: &[Aabb]) -> Lookup {
        let mut all = Aabb::empty();
        for b in boxes {
            all.grow(&b.min);
            all.grow(&b.max);
        }
        let edge = all
            .extent()
            .iter()
            .fold(0.0f64, |a, &e| a.max(e))
            .max(1e-12);
        let cell = edge / LOOKUP_CELLS as f64;
        let mut cells = vec![Vec::new(); LOOKUP_CELLS.pow(3)];
        let index = |v: f64, k: usize| {
            (((v - all.min[k]) / cell).floor().max(0.0) as usize).min(LOOKUP_CELLS - 1)
        };
        for (b, bx) in boxes.iter().enumerate() {
            let lo = [0, 1, 2].map(|k| index(bx.min[k], k));
            let hi = [0, 1, 2].map(|k| index(bx.max[k], k));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        cells[(z * LOOKUP_CELLS + y) * LOOKUP_CELLS + x].push(b as u32);
                    }
                }
            }
        }
        Lookup {
            min: all.min,
            cell,
            cells,
        }
    }

    /// The boxes whose cell holds `p` (a superset of those containing it; empty outside).
    fn candidates(&self, p: &Point3) -> &[u32] {
        let mut at = [0usize; 3];
        for k in 0..3 {
            let u = ((p[k] - self.min[k]) / self.cell).floor();
            // Below the box or NaN.
            if u.is_nan() || u < 0.0 {
                return &[];
            }
            at[k] = (u as usize).min(LOOKUP_CELLS - 1);
        }
        &self.cells[(at[2] * LOOKUP_CELLS + at[1]) * LOOKUP_CELLS + at[0]]
    }
}

/// What the partition pass wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Routed {
    /// Points whose first containing core (lowest block index) is each block's, before merging.
    pub core_points: Vec<usize>,
    /// Records written per block.
    pub spilled: Vec<usize>,
}

impl Routed {
    /// Adds the counts of another part.
    pub(crate) fn add(&mut self, other: &Routed) {
        for (a, b) in self.core_points.iter_mut().zip(&other.core_points) {
            *a += b;
        }
        for (a, b) in self.spilled.iter_mut().zip(&other.spilled) {
            *a += b;
        }
    }
}

/// Where and how the partition routes points: the cores, their boxes inflated by the margin, the
/// lookup over those, the normalisation and the spill folder. Shared by the parts of a pass.
pub(crate) struct Routing<'a> {
    cores: &'a [Aabb],
    reach: Vec<Aabb>,
    lookup: Lookup,
    normalization: &'a Normalization,
    normals: bool,
    dir: &'a Path,
}

impl<'a> Routing<'a> {
    /// Routing into spill files in `dir` for `cores` inflated by `margin` (normalised units).
    pub(crate) fn new(
        cores: &'a [Aabb],
        margin: f64,
        normalization: &'a Normalization,
        normals: bool,
        dir: &'a Path,
    ) -> Self {
        let reach: Vec<Aabb> = cores.iter().map(|c| c.inflated(margin)).collect();
        let lookup = Lookup::new(&reach);
        Routing {
            cores,
            reach,
            lookup,
            normalization,
            normals,
            dir,
        }
    }
}

/// A pass over some points in input order: calls its argument with consecutive chunks.
pub(crate) type Pass<'p> = dyn Fn(&mut super::survey::ChunkFn<'_>) -> Result<(), ReconError> + 'p;

/// The partition pass over `input` whole: see [`route_part`].
pub(crate) fn route(input: &TiledInput<'_>, routing: &Routing<'_>) -> Result<Routed, ReconError> {
    route_part(routing, 0, 0, SPILL_BUFFER_BYTES, &|f| {
        input.for_each_chunk(f)
    })
}

/// One part of the partition pass: stream `pass`, normalise each finite point (its id is
/// `first_id` plus the finite points before it in the pass) and append it to part `part` of the
/// spill of every block whose core inflated by the margin contains it; at most `buffer_bytes`
/// buffered over all blocks.
pub(crate) fn route_part(
    routing: &Routing<'_>,
    part: usize,
    first_id: u32,
    buffer_bytes: usize,
    pass: &Pass<'_>,
) -> Result<Routed, ReconError> {
    let Routing {
        cores,
        reach,
        lookup,
        normalization,
        normals,
        dir,
    } = routing;
    let nb = cores.len();
    let cap = (buffer_bytes / nb.max(1)).clamp(16 << 10, 1 << 20);
    let mut buffers: Vec<Vec<u8>> = vec![Vec::new(); nb];
    let mut routed = Routed {
        core_points: vec![0; nb],
        spilled: vec![0; nb],
    };
    let flush = |b: usize, buf: &mut Vec<u8>| -> Result<(), ReconError> {
        let path = spill_path(dir, b, part);
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| io_err(&path, e))?;
        f.write_all(buf).map_err(|e| io_err(&path, e))?;
        buf.clear();
        Ok(())
    };
    let mut id = first_id;
    pass(&mut |points, chunk_normals| {
        for (i, p) in points.iter().enumerate() {
            if !finite(p) {
                continue;
            }
            let q = normalization.forward(p);
            let n = chunk_normals.map_or([0.0; 3], |n| unit_normal(n[i]));
            let mut owner = true;
            for &b in lookup.candidates(&q) {
                let b = b as usize;
                if !reach[b].contains(&q) {
                    continue;
                }
                if owner && cores[b].contains(&q) {
                    routed.core_points[b] += 1;
                    owner = false;
                }
                let buf = &mut buffers[b];
                buf.extend_from_slice(&id.to_le_bytes());
                let values = if *normals { 6 } else { 3 };
                for v in q.iter().chain(n.iter()).take(values) {
                    buf.extend_from_slice(&v.to_le_bytes());
                }
                routed.spilled[b] += 1;
                if buf.len() >= cap {
                    flush(b, buf)?;
                }
            }
            id = id.wrapping_add(1);
        }
        Ok(())
    })?;
    for (b, buf) in buffers.iter_mut().enumerate() {
        if !buf.is_empty() {
            flush(b, buf)?;
        }
    }
    Ok(routed)
}

/// The records of block `b`'s spill in `dir`, its `parts` parts in order (ascending id).
pub(crate) fn read_block_spill(
    dir: &Path,
    b: usize,
    parts: usize,
    normals: bool,
) -> Result<Vec<Record>, ReconError> {
    let mut out = Vec::new();
    for part in 0..parts {
        out.extend(read_spill(&spill_path(dir, b, part), normals)?);
    }
    Ok(out)
}

/// Removes the parts of block `b`'s spill.
pub(crate) fn remove_block_spill(dir: &Path, b: usize, parts: usize) {
    for part in 0..parts {
        let _ = std::fs::remove_file(spill_path(dir, b, part));
    }
}

/// The records of a spill file (ascending id: the pass appends in input order); an absent
/// file holds none.
pub(crate) fn read_spill(path: &Path, normals: bool) -> Result<Vec<Record>, ReconError> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(io_err(path, e)),
    };
    let size = record_bytes(normals);
    if bytes.len() % size != 0 {
        return Err(ReconError::Store(StoreError::Corrupt {
            key: path.display().to_string(),
            what: "spill file of partial records",
        }));
    }
    let f = |c: &[u8], k: usize| {
        f64::from_le_bytes(c[4 + 8 * k..12 + 8 * k].try_into().unwrap_or([0; 8]))
    };
    Ok(bytes
        .chunks_exact(size)
        .map(|c| Record {
            id: u32::from_le_bytes(c[..4].try_into().unwrap_or([0; 4])),
            p: [f(c, 0), f(c, 1), f(c, 2)],
            n: if normals {
                [f(c, 3), f(c, 4), f(c, 5)]
            } else {
                [0.0; 3]
            },
        })
        .collect())
}

/// For each record, whether it survives the duplicate merge: no record of lower id within `tol`.
/// Exact for every record whose `tol`-neighbourhood lies inside the records' region.
pub(crate) fn keep_flags(records: &[Record], tol: f64) -> Result<Vec<bool>, ReconError> {
    if tol <= 0.0 || records.is_empty() {
        return Ok(vec![true; records.len()]);
    }
    let pts: Vec<Point3> = records.iter().map(|r| r.p).collect();
    let index = build_index(&pts, IndexKind::KdTree, 16)?;
    use rayon::prelude::*;
    Ok((0..records.len())
        .into_par_iter()
        .map_init(Vec::new, |hits, i| {
            index.within(&pts[i], tol, hits);
            !hits.iter().any(|&h| records[h as usize].id < records[i].id)
        })
        .collect())
}

/// What [`finish_block`] dropped that the block owns (its first containing core is the block's).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Dropped {
    /// Duplicates merged into a point of lower id.
    pub merged: usize,
    /// Strays of a noisy cloud ([`crate::clean::strays`]).
    pub strays: usize,
}

/// A block's stored point set from its spill records: the kept points within `reach`, in id
/// order, normals negated when `flip`. With `stray_sigma` (the noise level σ of a cloud the noise
/// estimate calls noisy, normalised units) the strays are dropped too, tested against all the
/// kept records of the file, so a point whose neighbours lie in the file (every point of the
/// reach but where the data are sparser than the margin beyond it) gets the in-memory decision
/// in every block that holds it. Returns it with what was dropped of what `owns`.
pub(crate) fn finish_block(
    records: &[Record],
    reach: &Aabb,
    tol: f64,
    normals: bool,
    flip: bool,
    stray_sigma: Option<f64>,
    owns: impl Fn(&Point3) -> bool,
) -> Result<(PointSet, Dropped), ReconError> {
    // Strays need every neighbour the file holds; duplicates only those within `tol` of the reach.
    let within: Vec<Record>;
    let near: &[Record] = match stray_sigma {
        Some(_) => records,
        None => {
            within = (records.iter())
                .filter(|r| reach.inflated(tol).contains(&r.p))
                .copied()
                .collect();
            &within
        }
    };
    let keep = keep_flags(near, tol)?;
    let strays = match stray_sigma {
        Some(sigma) => stray_flags(near, &keep, sigma)?,
        None => vec![false; near.len()],
    };
    let mut set = PointSet {
        normals: normals.then(Vec::new),
        ..Default::default()
    };
    let mut dropped = Dropped::default();
    for (i, r) in near.iter().enumerate() {
        if !reach.contains(&r.p) {
            continue;
        }
        if !keep[i] || strays[i] {
            let owned = usize::from(owns(&r.p));
            if keep[i] {
                dropped.strays += owned;
            } else {
                dropped.merged += owned;
            }
            continue;
        }
        set.ids.push(r.id);
        set.points.push(r.p);
        if let Some(n) = set.normals.as_mut() {
            n.push(if flip { r.n.map(|v| -v) } else { r.n });
        }
    }
    Ok((set, dropped))
}

/// Per record, whether it is a kept (`keep`) point farther than the stray limit from the plane of
/// its kept neighbours (noise level `sigma`).
fn stray_flags(records: &[Record], keep: &[bool], sigma: f64) -> Result<Vec<bool>, ReconError> {
    let kept: Vec<usize> = (0..records.len()).filter(|&i| keep[i]).collect();
    let pts: Vec<Point3> = kept.iter().map(|&i| records[i].p).collect();
    let index = build_index(&pts, IndexKind::KdTree, 16)?;
    let flags = crate::clean::strays::strays(&pts, sigma, |p, k, out| index.nearest_k(p, k, out));
    let mut out = vec![false; records.len()];
    for (&i, f) in kept.iter().zip(flags) {
        out[i] = f;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::{Defects, Shape, apply_defects};

    #[test]
    fn blocks_drop_the_strays_the_whole_cloud_drops() {
        // A noisy sphere with a streak of strays, cut into two overlapping blocks whose spill
        // files reach a margin beyond them: each block keeps exactly the whole cloud's survivors
        // within its reach, and the owned counts add up to the whole cloud's.
        let mut cloud = Shape::by_name("sphere").unwrap().sample(6000, 5);
        let noise = Defects {
            noise_rel: 0.002,
            ..Default::default()
        };
        apply_defects(&mut cloud, &noise, 6).unwrap();
        let normals = cloud.normals.clone().unwrap();
        let sigma = 0.002 * Aabb::from_points(&cloud.points).diagonal();
        for i in 0..30 {
            let (p, n) = (cloud.points[i * 101], normals[i * 101]);
            cloud
                .points
                .push([0, 1, 2].map(|k| p[k] + 12.0 * sigma * n[k]));
        }
        let records: Vec<Record> = (cloud.points.iter().enumerate())
            .map(|(i, &p)| Record {
                id: i as u32,
                p,
                n: [0.0; 3],
            })
            .collect();
        let pts: Vec<Point3> = records.iter().map(|r| r.p).collect();
        let index = build_index(&pts, IndexKind::KdTree, 16).unwrap();
        let whole =
            crate::clean::strays::strays(&pts, sigma, |p, k, out| index.nearest_k(p, k, out));
        let whole_count = whole.iter().filter(|s| **s).count();
        assert!(whole_count >= 25, "{whole_count} strays in the whole cloud");
        let bbox = Aabb::from_points(&pts);
        let mid = bbox.center()[0];
        let cores = [
            Aabb {
                max: [mid, bbox.max[1], bbox.max[2]],
                ..bbox
            },
            Aabb {
                min: [mid, bbox.min[1], bbox.min[2]],
                ..bbox
            },
        ];
        let (reach, margin) = (0.05, 0.15);
        let mut owned = 0;
        for (b, core) in cores.iter().enumerate() {
            let reach_box = core.inflated(reach);
            let spill_box = core.inflated(margin);
            let file: Vec<Record> = (records.iter())
                .filter(|r| spill_box.contains(&r.p))
                .copied()
                .collect();
            let owns = |p: &Point3| cores.iter().position(|c| c.contains(p)) == Some(b);
            let (set, dropped) =
                finish_block(&file, &reach_box, 1e-12, false, false, Some(sigma), owns).unwrap();
            let expected: Vec<u32> = (records.iter())
                .filter(|r| reach_box.contains(&r.p) && !whole[r.id as usize])
                .map(|r| r.id)
                .collect();
            assert_eq!(set.ids, expected, "block {b}");
            assert_eq!(dropped.merged, 0);
            owned += dropped.strays;
            // Without a noise level nothing but duplicates is dropped.
            let (all, none) =
                finish_block(&file, &reach_box, 1e-12, false, false, None, owns).unwrap();
            assert_eq!(none, Dropped::default());
            assert_eq!(
                all.ids.len(),
                file.iter().filter(|r| reach_box.contains(&r.p)).count()
            );
        }
        assert_eq!(owned, whole_count);
    }
}
