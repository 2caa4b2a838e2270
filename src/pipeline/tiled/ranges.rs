//! Prepare's passes over the input as tasks per byte range ([`crate::io::split`]), so that no
//! task reads the whole input: the survey and the partition of a file of `n` bytes run as
//! `n / range_bytes` tasks each, on any thread or worker, and give exactly what the single passes
//! give.
//!
//! 1. **Count** (one task per range): points, finite points, their box, invalid normals.
//! 2. **Number** (cheap, over the counts): each range's first global id (the finite points of
//!    the ranges before it) and the subsample's `step`, the one the single survey ends with (the
//!    smallest power of two that keeps at most [`super::prepare::SAMPLE_POINTS`] ids).
//! 3. **Sample** (one task per range): the points whose global id is a multiple of `step`.
//! 4. **Route** (one task per range, once the blocks are planned from the subsample): the
//!    range's points to part `r` of every block's spill ([`super::route::route_part`]); a block
//!    reads its parts in range order, so its records, ids and duplicate decisions are the single
//!    pass's.
//!
//! Formats that cannot be split (ASCII PLY, PLY with list properties, LAZ, E57, OBJ) and clouds
//! in memory are read by single passes ([`InputSplit`] has no effect on them).

use super::route::{self, Pass, Routed, Routing};
use super::survey::{self, Survey, TiledInput, finite, unit_normal};
use crate::error::ReconError;
use crate::geometry::{Aabb, Point3};
use crate::io::split::{Split, split_input};
use crate::io::{ReadLimits, StreamInput};
use crate::report::TaskReport;
use rayon::prelude::*;
use std::sync::Mutex;

/// Points per chunk handed from a range's reader to a pass.
const CHUNK_POINTS: usize = 1 << 16;

/// Default bytes per range of the input (64 MiB: about 2.8 million binary PLY records of six
/// floats, 1.9 million of `double x y z` with `float` normals).
pub const DEFAULT_RANGE_BYTES: u64 = 64 << 20;

/// How prepare's survey and partition passes read the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputSplit {
    /// One task streams the whole input per pass.
    Whole,
    /// One task per byte range of about this many bytes, for the formats that can be split
    /// (binary PLY without list properties, uncompressed LAS, XYZ / PTS / CSV); the others are
    /// read whole.
    Bytes(u64),
}

impl Default for InputSplit {
    fn default() -> Self {
        InputSplit::Bytes(DEFAULT_RANGE_BYTES)
    }
}

/// What one range's count found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RangeCount {
    /// Points read.
    pub total: u64,
    /// Points with finite coordinates.
    pub finite: u64,
    /// Finite points whose normal is zero or not finite (with normals).
    pub invalid_normals: u64,
    /// Box of the finite points, input units.
    pub bbox: Aabb,
}

/// Step 1 over one range's points (`pass`); `normals` whether the input has them.
pub(crate) fn count_range(pass: &Pass<'_>, normals: bool) -> Result<RangeCount, ReconError> {
    let mut c = RangeCount {
        total: 0,
        finite: 0,
        invalid_normals: 0,
        bbox: Aabb::empty(),
    };
    pass(&mut |points, ns| {
        c.total += points.len() as u64;
        for (i, p) in points.iter().enumerate() {
            if !finite(p) {
                continue;
            }
            c.finite += 1;
            c.bbox.grow(p);
            let n = ns.map_or([0.0; 3], |n| unit_normal(n[i]));
            if normals && n == [0.0; 3] {
                c.invalid_normals += 1;
            }
        }
        Ok(())
    })?;
    Ok(c)
}

/// Step 2: the survey without its subsample (`ids` empty), each range's first global id, from
/// the ranges' counts in file order; `max_sample` bounds the subsample. The same errors as the
/// single survey for an input without (finite) points or with more ids than fit `u32`.
pub(crate) fn number(
    counts: &[RangeCount],
    max_sample: usize,
    normals: bool,
) -> Result<(Survey, Vec<u32>), ReconError> {
    let mut s = Survey::empty();
    let mut first_ids = Vec::with_capacity(counts.len());
    let (mut total, mut finite) = (0u64, 0u64);
    for c in counts {
        first_ids.push(u32::try_from(finite).unwrap_or(u32::MAX));
        total += c.total;
        finite += c.finite;
        s.invalid_normals += c.invalid_normals as usize;
        if c.finite > 0 {
            s.bbox.grow(&c.bbox.min);
            s.bbox.grow(&c.bbox.max);
        }
    }
    s.total = usize::try_from(total).map_err(|_| ReconError::TooManyIds)?;
    s.finite = usize::try_from(finite).map_err(|_| ReconError::TooManyIds)?;
    if s.total == 0 {
        return Err(crate::clean::InputError::Empty.into());
    }
    if s.finite == 0 {
        return Err(crate::clean::InputError::NoFinitePoints { total: s.total }.into());
    }
    if finite > u64::from(u32::MAX) + 1 {
        return Err(ReconError::TooManyIds);
    }
    let max = max_sample.max(1);
    while s.finite.div_ceil(s.step) > max {
        s.step *= 2;
    }
    s.has_normals = normals && s.invalid_normals < s.finite;
    Ok((s, first_ids))
}

/// The points of a range kept by the subsample: global ids, positions, unit normals.
pub(crate) type SamplePart = (Vec<u32>, Vec<Point3>, Vec<Point3>);

/// Step 3 over one range's points (`pass`), whose first finite point has global id `first_id`:
/// the points whose id is a multiple of `step`.
pub(crate) fn sample_range(
    pass: &Pass<'_>,
    first_id: u32,
    step: usize,
) -> Result<SamplePart, ReconError> {
    let mut out: SamplePart = (Vec::new(), Vec::new(), Vec::new());
    let mut id = first_id;
    let step = step as u32;
    pass(&mut |points, ns| {
        for (i, p) in points.iter().enumerate() {
            if !finite(p) {
                continue;
            }
            if id.is_multiple_of(step) {
                out.0.push(id);
                out.1.push(*p);
                out.2.push(ns.map_or([0.0; 3], |n| unit_normal(n[i])));
            }
            id = id.wrapping_add(1);
        }
        Ok(())
    })?;
    Ok(out)
}

/// The input as prepare's passes read it: whole, or by ranges (with the ranges' first ids once
/// the survey has numbered them). Records each pass's tasks for the report's timeline.
pub(crate) struct Scan<'a> {
    input: &'a TiledInput<'a>,
    ranges: Option<(StreamInput<'a>, Split, &'a ReadLimits)>,
    first_ids: Vec<u32>,
    worker: String,
    tasks: Mutex<Vec<TaskReport>>,
}

impl<'a> Scan<'a> {
    /// How `input` is read under `split`: by ranges when it is a stream of a format that splits
    /// into more than one range. `worker` names this process in the timeline.
    pub(crate) fn new(
        input: &'a TiledInput<'a>,
        split: InputSplit,
        worker: &str,
    ) -> Result<Scan<'a>, ReconError> {
        let ranges = match (input, split) {
            (TiledInput::Stream(s, limits), InputSplit::Bytes(bytes)) => {
                split_input(*s, limits, bytes)?
                    .filter(|sp| sp.ranges().len() > 1)
                    .map(|sp| (*s, sp, *limits))
            }
            _ => None,
        };
        Ok(Scan {
            input,
            ranges,
            first_ids: Vec::new(),
            worker: worker.to_string(),
            tasks: Mutex::new(Vec::new()),
        })
    }

    /// The spill parts per block: one per range (one when read whole).
    pub(crate) fn parts(&self) -> usize {
        self.ranges.as_ref().map_or(1, |(_, s, _)| s.ranges().len())
    }

    /// The timeline of the passes' tasks so far.
    pub(crate) fn take_tasks(&self) -> Vec<TaskReport> {
        std::mem::take(&mut *self.tasks.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Runs `f` as task `name`, recording its wall-clock interval.
    pub(crate) fn timed<T>(&self, name: String, f: impl FnOnce() -> T) -> T {
        let start_ms = crate::report::unix_now_ms();
        let out = f();
        let end_ms = crate::report::unix_now_ms().max(start_ms);
        let t = TaskReport {
            task: name,
            worker: self.worker.clone(),
            start_ms,
            end_ms,
            seconds: (end_ms - start_ms) as f64 / 1000.0,
        };
        self.tasks.lock().unwrap_or_else(|e| e.into_inner()).push(t);
        out
    }

    /// Range `r` as a pass.
    fn range_pass<'s>(
        &'s self,
        r: usize,
    ) -> impl Fn(&mut survey::ChunkFn<'_>) -> Result<(), ReconError> + 's {
        move |f| match &self.ranges {
            Some((input, split, _)) => split.read_range(*input, r, CHUNK_POINTS, f),
            None => self.input.for_each_chunk(f),
        }
    }

    /// The survey (count, numbering, subsample): the single pass's result either way.
    pub(crate) fn survey(&mut self, max_sample: usize) -> Result<Survey, ReconError> {
        let Some((_, split, limits)) = &self.ranges else {
            return self.timed("survey".into(), || survey::survey(self.input, max_sample));
        };
        let (normals, nr) = (split.has_normals(), split.ranges().len());
        let counts = (0..nr)
            .into_par_iter()
            .map(|r| {
                self.timed(format!("survey range {r}"), || {
                    count_range(&self.range_pass(r), normals)
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let total: u64 = counts.iter().map(|c| c.total).sum();
        split.check_total(total, limits)?;
        let (mut s, first_ids) = number(&counts, max_sample, normals)?;
        let parts = (0..nr)
            .into_par_iter()
            .map(|r| {
                self.timed(format!("sample range {r}"), || {
                    sample_range(&self.range_pass(r), first_ids[r], s.step)
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        for (ids, points, normals) in parts {
            s.ids.extend(ids);
            s.points.extend(points);
            s.normals.extend(normals);
        }
        self.first_ids = first_ids;
        Ok(s)
    }

    /// The partition pass with `routing`: one part per range, the counts summed. Needs
    /// [`Scan::survey`] first.
    pub(crate) fn route(&self, routing: &Routing<'_>, blocks: usize) -> Result<Routed, ReconError> {
        if self.ranges.is_none() {
            return self.timed("route".into(), || route::route(self.input, routing));
        }
        let threads = rayon::current_num_threads().max(1);
        let buffer = route::SPILL_BUFFER_BYTES / threads;
        let parts = (0..self.parts())
            .into_par_iter()
            .map(|r| {
                self.timed(format!("route range {r}"), || {
                    route::route_part(routing, r, self.first_ids[r], buffer, &self.range_pass(r))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut sum = Routed {
            core_points: vec![0; blocks],
            spilled: vec![0; blocks],
        };
        for p in &parts {
            sum.add(p);
        }
        Ok(sum)
    }
}

#[cfg(test)]
mod tests {
    use super::super::prepare::{SAMPLE_POINTS, prepare};
    use super::super::store::{Store, StoreKind};
    use super::super::tasks::block_key;
    use super::super::{TiledOptions, survey};
    use super::*;
    use crate::geometry::PointCloud;
    use crate::io::PointFormat;
    use crate::params::ReconParams;
    use crate::progress::NoProgress;

    /// A torus with non-finite points and near duplicates spread over it.
    fn cloud() -> PointCloud {
        let shape = crate::geometry::synthetic::Shape::by_name("torus").unwrap();
        let mut cloud = shape.sample(5000, 3);
        let normals = cloud.normals.as_mut().unwrap();
        for i in [0, 17, 2500, 4999] {
            cloud.points[i][1] = f64::NAN;
        }
        normals[40] = [0.0; 3];
        for i in (0..5000).step_by(41) {
            let p = cloud.points[i];
            cloud.points.push([p[0] + 1e-9, p[1], p[2]]);
            normals.push(normals[i]);
        }
        cloud
    }

    /// The cloud as XYZ text (six columns, comments, CRLF) and as binary PLY.
    fn files(cloud: &PointCloud) -> Vec<(Vec<u8>, PointFormat)> {
        let mut text = String::from("# torus\r\n");
        for (p, n) in cloud.points.iter().zip(cloud.normals.as_ref().unwrap()) {
            let row: Vec<String> = p.iter().chain(n).map(|v| v.to_string()).collect();
            text.push_str(&row.join(" "));
            text.push_str("\r\n");
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.ply");
        crate::io::write_points_ply(&path, cloud).unwrap();
        let ply = std::fs::read(&path).unwrap();
        vec![
            (text.into_bytes(), PointFormat::Xyz),
            (ply, PointFormat::Ply),
        ]
    }

    #[test]
    fn the_range_survey_is_the_single_survey() {
        let cloud = cloud();
        let limits = ReadLimits::default();
        for (data, format) in files(&cloud) {
            let input = TiledInput::Stream(
                StreamInput::Bytes {
                    data: &data,
                    format,
                },
                &limits,
            );
            let whole = survey::survey(&input, 1000).unwrap();
            for bytes in [3000, 40_000, 1 << 30] {
                let mut scan = Scan::new(&input, InputSplit::Bytes(bytes), "t").unwrap();
                let split = scan.survey(1000).unwrap();
                assert_eq!(split, whole, "{format:?}, {bytes}-byte ranges");
                let tasks = scan.take_tasks();
                let ranges = tasks.iter().filter(|t| t.task.starts_with("survey range"));
                if bytes < 1 << 30 {
                    assert!(scan.parts() > 1, "{format:?}, {bytes}-byte ranges");
                    assert_eq!(ranges.count(), scan.parts(), "{format:?}");
                } else {
                    assert_eq!((scan.parts(), tasks[0].task.as_str()), (1, "survey"));
                }
            }
            assert!(whole.step > 1 && whole.invalid_normals == 1);
        }
        // A subsample that holds every point (step 1) and one that thins to one point.
        let data = &files(&cloud)[1].0;
        let input = TiledInput::Stream(
            StreamInput::Bytes {
                data,
                format: PointFormat::Ply,
            },
            &limits,
        );
        for max in [1, SAMPLE_POINTS] {
            let whole = survey::survey(&input, max).unwrap();
            let mut scan = Scan::new(&input, InputSplit::Bytes(5000), "t").unwrap();
            assert_eq!(scan.survey(max).unwrap(), whole, "at most {max}");
        }
    }

    #[test]
    fn prepare_by_ranges_writes_the_single_passes_blocks() {
        let cloud = cloud();
        let limits = ReadLimits::default();
        let params = ReconParams::default();
        for (data, format) in files(&cloud) {
            let input = TiledInput::Stream(
                StreamInput::Bytes {
                    data: &data,
                    format,
                },
                &limits,
            );
            let run = |split: InputSplit| {
                let options = TiledOptions {
                    store: StoreKind::Memory,
                    split,
                    ..Default::default()
                };
                let store = Store::open(&options.store).unwrap();
                let (plan, tasks) =
                    prepare(&input, &params, &options, 600, &store, &NoProgress).unwrap();
                let sets: Vec<Vec<u8>> = (0..plan.blocks.len())
                    .map(|b| store.get(&block_key(b)).unwrap())
                    .collect();
                (plan, tasks, sets)
            };
            let (whole, whole_tasks, whole_sets) = run(InputSplit::Whole);
            let (split, tasks, sets) = run(InputSplit::Bytes(7000));
            assert!(whole.blocks.len() >= 6, "{} blocks", whole.blocks.len());
            assert_eq!(split.blocks, whole.blocks, "{format:?}");
            assert_eq!(split.clean, whole.clean, "{format:?}");
            // Four NaN points and the copy of one of them.
            let c = whole.clean;
            assert!(
                c.merged_duplicates > 100 && c.dropped_non_finite == 5,
                "{c:?}"
            );
            assert_eq!(split.sample, whole.sample);
            assert_eq!(split.support, whole.support);
            assert_eq!(
                sets, whole_sets,
                "{format:?}: the blocks' stored point sets"
            );
            let routes = tasks
                .iter()
                .filter(|t| t.task.starts_with("route range"))
                .count();
            assert!(routes >= 20, "{routes} route tasks");
            assert!(whole_tasks.iter().any(|t| t.task == "route"));
        }
    }
}
