//! Prepare's first pass over the input: one stream of the points for their count, the bounding
//! box of the finite ones, the normals' validity and a bounded, deterministic subsample. Nothing
//! proportional to the cloud is kept.
//!
//! Points are numbered by their position among the finite points of the input (the *global id*,
//! the same in every pass and in every block that holds the point). The subsample keeps the ids
//! that are multiples of `step`, `step` a power of two doubled whenever more than
//! [`super::prepare::SAMPLE_POINTS`] would be kept: at most that many points, spread over the
//! whole file, the same for every run over the same input.

use crate::error::ReconError;
use crate::geometry::{Aabb, Point3, PointCloud, normalized};
use crate::io::{ReadLimits, StreamInput};

/// Points per chunk handed from the reader to a pass (~3 MiB with normals).
const CHUNK_POINTS: usize = 1 << 16;

/// Where prepare reads the points: a re-readable input (a file or bytes in memory), streamed
/// once per pass, or a cloud already in memory.
#[derive(Debug, Clone, Copy)]
pub enum TiledInput<'a> {
    /// A point file or a file's bytes, read with these limits (not the readers' memory budget:
    /// the points are never held).
    Stream(StreamInput<'a>, &'a ReadLimits),
    /// Points in memory.
    Cloud(&'a PointCloud),
}

/// What [`TiledInput::for_each_chunk`] calls with each chunk of points and their normals.
pub(crate) type ChunkFn<'f> =
    dyn FnMut(&[Point3], Option<&[Point3]>) -> Result<(), ReconError> + 'f;

impl TiledInput<'_> {
    /// Calls `f` with consecutive chunks of the points (and normals when the input has them),
    /// in input order; stops at the first error (a read error becomes [`ReconError::Read`]).
    pub(crate) fn for_each_chunk(&self, f: &mut ChunkFn<'_>) -> Result<(), ReconError> {
        match self {
            TiledInput::Cloud(cloud) => {
                if cloud.points.is_empty() {
                    return Err(crate::clean::InputError::Empty.into());
                }
                let normals = (cloud.normals.as_ref()).filter(|n| n.len() == cloud.points.len());
                for (k, chunk) in cloud.points.chunks(CHUNK_POINTS).enumerate() {
                    let n = normals.map(|n| &n[k * CHUNK_POINTS..k * CHUNK_POINTS + chunk.len()]);
                    f(chunk, n)?;
                }
                Ok(())
            }
            TiledInput::Stream(input, limits) => {
                crate::io::stream_points(*input, limits, CHUNK_POINTS, |chunks| {
                    for chunk in chunks {
                        let c = chunk.map_err(ReconError::Read)?;
                        f(&c.points, c.normals.as_deref())?;
                    }
                    Ok(())
                })
            }
        }
    }
}

/// What the first pass found.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Survey {
    /// Points read.
    pub total: usize,
    /// Points with finite coordinates (their ids are `0..finite`).
    pub finite: usize,
    /// Whether the input has normals and at least one is usable.
    pub has_normals: bool,
    /// Finite points whose normal is zero or not finite.
    pub invalid_normals: usize,
    /// Box of the finite points, input units.
    pub bbox: Aabb,
    /// The subsample keeps the ids that are multiples of this.
    pub step: usize,
    /// The subsample: global ids, positions (input units), unit normals (zero when unusable or
    /// absent).
    pub ids: Vec<u32>,
    pub points: Vec<Point3>,
    pub normals: Vec<Point3>,
}

impl Survey {
    /// Nothing surveyed yet.
    pub(crate) fn empty() -> Survey {
        Survey {
            total: 0,
            finite: 0,
            has_normals: false,
            invalid_normals: 0,
            bbox: Aabb::empty(),
            step: 1,
            ids: Vec::new(),
            points: Vec::new(),
            normals: Vec::new(),
        }
    }

    /// Keeps only the ids that are multiples of twice the current step.
    fn thin(&mut self) {
        self.step *= 2;
        let step = self.step as u32;
        let keep: Vec<bool> = self.ids.iter().map(|&id| id % step == 0).collect();
        for v in [&mut self.points, &mut self.normals] {
            let mut k = 0;
            v.retain(|_| {
                k += 1;
                keep[k - 1]
            });
        }
        self.ids.retain(|&id| id % step == 0);
    }
}

/// The unit normal of `n`, zero when it has none.
pub(crate) fn unit_normal(n: Point3) -> Point3 {
    normalized(n).unwrap_or([0.0; 3])
}

/// Whether all three coordinates are finite.
pub(crate) fn finite(p: &Point3) -> bool {
    p.iter().all(|v| v.is_finite())
}

/// The first pass: see the module doc. `max_sample` bounds the subsample.
pub(crate) fn survey(input: &TiledInput<'_>, max_sample: usize) -> Result<Survey, ReconError> {
    let mut s = Survey::empty();
    let mut input_normals = false;
    input.for_each_chunk(&mut |points, normals| {
        input_normals |= normals.is_some();
        s.total += points.len();
        for (i, p) in points.iter().enumerate() {
            if !finite(p) {
                continue;
            }
            let id = u32::try_from(s.finite).map_err(|_| ReconError::TooManyIds)?;
            s.finite += 1;
            s.bbox.grow(p);
            let n = normals.map_or([0.0; 3], |n| unit_normal(n[i]));
            if normals.is_some() && n == [0.0; 3] {
                s.invalid_normals += 1;
            }
            if id % s.step as u32 == 0 {
                s.ids.push(id);
                s.points.push(*p);
                s.normals.push(n);
                if s.ids.len() > max_sample.max(1) {
                    s.thin();
                }
            }
        }
        Ok(())
    })?;
    if s.total == 0 {
        return Err(crate::clean::InputError::Empty.into());
    }
    if s.finite == 0 {
        return Err(crate::clean::InputError::NoFinitePoints { total: s.total }.into());
    }
    s.has_normals = input_normals && s.invalid_normals < s.finite;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_subsample_is_every_step_th_finite_point_and_bounded() {
        let mut points: Vec<Point3> = (0..10_000).map(|i| [i as f64, 0.0, 1.0]).collect();
        points[5] = [f64::NAN, 0.0, 0.0];
        let cloud = PointCloud {
            points,
            ..Default::default()
        };
        let s = survey(&TiledInput::Cloud(&cloud), 1000).unwrap();
        assert_eq!((s.total, s.finite, s.has_normals), (10_000, 9_999, false));
        assert_eq!(s.step, 16);
        assert!(s.ids.len() <= 1000 && s.ids.len() > 500, "{}", s.ids.len());
        assert!(s.ids.iter().all(|&id| id % 16 == 0));
        // Id 16 is the 17th finite point: the input's 18th (one NaN before it).
        assert_eq!(s.points[1], [17.0, 0.0, 1.0]);
        assert_eq!(s.bbox.max, [9999.0, 0.0, 1.0]);
    }
}
