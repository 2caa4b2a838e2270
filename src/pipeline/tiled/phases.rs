//! Prepare as separate tasks, for the distributed executor: each pass over the input runs as
//! one task per byte range on whichever worker takes it, holding only a window of the input
//! around its range ([`crate::io::split::Window`]); each block's clean-up is a task; the steps
//! between the passes (numbering the ranges, planning the blocks, the estimates on patches)
//! read only small values. Every value crosses workers through the job's [`Store`] under
//! `prep/…`, and the result is [`super::prepare::prepare`]'s, bit for bit.
//!
//! | phase    | task                  | writes                                   | then (once)             |
//! |----------|-----------------------|------------------------------------------|-------------------------|
//! | survey   | [`count`] per range   | `prep/count/<r>`                         | [`gather_counts`]       |
//! | sample   | [`sample`] per range  | `prep/sample/<r>`                        | [`plan_partition`]      |
//! | route    | [`route`] per range   | `prep/spill/<g>/<b>/<r>`, `prep/routed/<g>/<r>` | [`after_routes`] |
//! | clean-up | [`clean_up`] per block| `points/<k>`, `prep/block/<k>`           | [`complete`]            |
//!
//! `g` is the partition's generation: when the estimates need a wider margin than the first
//! partition's, it is routed again as generation `g + 1`.

use super::TiledOptions;
use super::patches;
use super::prepare::{
    self, BlockBox, BlockOutput, CleanSpec, Plan, SAMPLE_POINTS, alive_blocks, plan_routes,
};
use super::ranges::{RangeCount, count_range, number, sample_range};
use super::route::{self, Dropped, Routed, Routing};
use super::store::{PointSet, Store};
use super::survey::Survey;
use crate::error::{ReconError, StoreError};
use crate::geometry::{Aabb, Normalization, Point3};
use crate::io::ReadLimits;
use crate::io::split::{Split, Window};
use crate::params::ReconParams;
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use std::path::Path;

/// Points per chunk handed from a range's reader to a pass.
const CHUNK_POINTS: usize = 1 << 16;

/// One range of the input as a task reads it: the split (planned from the input's first
/// segment), the range and a window that holds it.
pub(crate) struct RangeInput<'a> {
    pub split: &'a Split,
    pub r: usize,
    pub window: Window<'a>,
}

impl RangeInput<'_> {
    fn pass(&self) -> impl Fn(&mut super::survey::ChunkFn<'_>) -> Result<(), ReconError> + '_ {
        move |f| (self.split).read_window(self.window, self.r, CHUNK_POINTS, f)
    }
}

fn put_json<T: Serialize>(store: &Store, key: &str, v: &T) -> Result<(), ReconError> {
    let bytes = serde_json::to_vec(v).map_err(|e| corrupt_err(key, e))?;
    Ok(store.put(key, bytes)?)
}

fn get_json<T: DeserializeOwned>(store: &Store, key: &str) -> Result<T, ReconError> {
    let bytes = store.get(key)?;
    serde_json::from_slice(&bytes).map_err(|e| corrupt_err(key, e))
}

fn corrupt_err(key: &str, e: serde_json::Error) -> ReconError {
    tracing::warn!(key, error = %e, "prepare value unreadable");
    ReconError::Store(StoreError::Corrupt {
        key: key.to_string(),
        what: "prepare value unreadable",
    })
}

/// A range's count as stored (the box is absent without finite points).
#[derive(Serialize, Deserialize)]
struct CountRecord {
    total: u64,
    finite: u64,
    invalid_normals: u64,
    bbox: Option<[Point3; 2]>,
}

/// Every range's count, and whether the input has normals: what numbers the ranges.
#[derive(Serialize, Deserialize)]
struct Counts {
    normals: bool,
    ranges: Vec<CountRecord>,
}

fn to_count(c: &CountRecord) -> RangeCount {
    RangeCount {
        total: c.total,
        finite: c.finite,
        invalid_normals: c.invalid_normals,
        bbox: c.bbox.map_or(Aabb::empty(), |[min, max]| Aabb { min, max }),
    }
}

/// Survey task: counts range `input.r` into `prep/count/<r>`. Returns the keys written.
pub(crate) fn count(input: &RangeInput<'_>, store: &Store) -> Result<Vec<String>, ReconError> {
    let c = count_range(&input.pass(), input.split.has_normals())?;
    let rec = CountRecord {
        total: c.total,
        finite: c.finite,
        invalid_normals: c.invalid_normals,
        bbox: (c.finite > 0).then_some([c.bbox.min, c.bbox.max]),
    };
    let key = format!("prep/count/{}", input.r);
    put_json(store, &key, &rec)?;
    Ok(vec![key])
}

/// After the survey tasks: checks the total as the whole-file reader would (`limits`), numbers
/// the ranges (the refusals of an empty input included) and stores every count in
/// `prep/counts`.
pub(crate) fn gather_counts(
    split: &Split,
    limits: &ReadLimits,
    store: &Store,
) -> Result<(), ReconError> {
    let n = split.ranges().len();
    let ranges = (0..n)
        .map(|r| get_json::<CountRecord>(store, &format!("prep/count/{r}")))
        .collect::<Result<Vec<_>, _>>()?;
    let counts = Counts {
        normals: split.has_normals(),
        ranges,
    };
    let total: u64 = counts.ranges.iter().map(|c| c.total).sum();
    split.check_total(total, limits)?;
    numbering(&counts)?;
    put_json(store, "prep/counts", &counts)
}

/// The survey without its subsample, and each range's first global id.
fn numbering(counts: &Counts) -> Result<(Survey, Vec<u32>), ReconError> {
    let c: Vec<RangeCount> = counts.ranges.iter().map(to_count).collect();
    number(&c, SAMPLE_POINTS, counts.normals)
}

/// Sample task: the subsample's points of range `input.r` into `prep/sample/<r>`. Returns the
/// keys written.
pub(crate) fn sample(input: &RangeInput<'_>, store: &Store) -> Result<Vec<String>, ReconError> {
    let (s, first_ids) = numbering(&get_json(store, "prep/counts")?)?;
    let (ids, points, normals) = sample_range(&input.pass(), first_ids[input.r], s.step)?;
    let set = PointSet {
        ids,
        points,
        normals: Some(normals),
    };
    let key = format!("prep/sample/{}", input.r);
    store.put(&key, set.encode())?;
    Ok(vec![key])
}

/// The whole survey, subsample included, from the stored counts and samples.
fn survey(store: &Store) -> Result<Survey, ReconError> {
    let counts: Counts = get_json(store, "prep/counts")?;
    let (mut s, _) = numbering(&counts)?;
    for r in 0..counts.ranges.len() {
        let key = format!("prep/sample/{r}");
        let part = PointSet::decode(&store.get(&key)?, &key)?;
        s.ids.extend(part.ids);
        s.points.extend(part.points);
        s.normals.extend(part.normals.unwrap_or_default());
    }
    Ok(s)
}

/// What a route task needs: the cores, the margin, the normalisation, the generation.
#[derive(Serialize, Deserialize)]
struct RoutingRecord {
    generation: u32,
    margin: f64,
    offset: Point3,
    scale: f64,
    normals: bool,
    cores: Vec<[Point3; 2]>,
}

/// After the sample tasks: plans the blocks and the partition's margin from the subsample into
/// `prep/routing` (generation 0). `block_points` bounds the core points per block.
pub(crate) fn plan_partition(
    params: &ReconParams,
    options: &TiledOptions,
    block_points: usize,
    store: &Store,
) -> Result<(), ReconError> {
    let s = survey(store)?;
    let routes = plan_routes(&s, params, options, block_points)?;
    let rec = RoutingRecord {
        generation: 0,
        margin: routes.margin,
        offset: routes.normalization.offset,
        scale: routes.normalization.scale,
        normals: s.has_normals,
        cores: routes.cores.iter().map(|c| [c.min, c.max]).collect(),
    };
    put_json(store, "prep/routing", &rec)
}

impl RoutingRecord {
    /// The block cores.
    fn boxes(&self) -> Vec<Aabb> {
        (self.cores.iter())
            .map(|&[min, max]| Aabb { min, max })
            .collect()
    }
}

fn spill_key(generation: u32, b: usize, r: usize) -> String {
    format!("prep/spill/{generation}/{b}/{r}")
}

/// Route task: the points of range `input.r` to every block's part `r` of the partition's
/// current generation; `dir` is a scratch folder. Returns the keys written.
pub(crate) fn route(
    input: &RangeInput<'_>,
    store: &Store,
    dir: &Path,
) -> Result<Vec<String>, ReconError> {
    let (_, first_ids) = numbering(&get_json(store, "prep/counts")?)?;
    let rec: RoutingRecord = get_json(store, "prep/routing")?;
    let cores = rec.boxes();
    let normalization = Normalization {
        offset: rec.offset,
        scale: rec.scale,
    };
    let routing = Routing::new(&cores, rec.margin, &normalization, rec.normals, dir);
    let r = input.r;
    let routed = route::route_part(
        &routing,
        r,
        first_ids[r],
        route::SPILL_BUFFER_BYTES,
        &input.pass(),
    )?;
    let mut written = Vec::new();
    for b in (0..cores.len()).filter(|&b| routed.spilled[b] > 0) {
        let path = route::spill_path(dir, b, r);
        let bytes = std::fs::read(&path).map_err(|source| {
            ReconError::Store(StoreError::Io {
                path: path.clone(),
                source,
            })
        })?;
        let key = spill_key(rec.generation, b, r);
        store.put(&key, bytes)?;
        written.push(key);
        let _ = std::fs::remove_file(&path);
    }
    let key = format!("prep/routed/{}/{r}", rec.generation);
    put_json(store, &key, &(routed.core_points, routed.spilled))?;
    written.push(key);
    Ok(written)
}

/// The spill keys of generation `generation` that its route tasks stored (those whose counts
/// were stored), for removal.
pub(crate) fn spill_keys(store: &Store, generation: u32, ranges: usize) -> Vec<String> {
    let mut keys = Vec::new();
    for r in 0..ranges {
        let key = format!("prep/routed/{generation}/{r}");
        if let Ok((_, spilled)) = get_json::<(Vec<usize>, Vec<usize>)>(store, &key) {
            keys.extend(
                (0..spilled.len())
                    .filter(|&b| spilled[b] > 0)
                    .map(|b| spill_key(generation, b, r)),
            );
        }
        keys.push(key);
    }
    keys
}

/// How the clean-up tasks make the blocks: provisional block `alive[k]` becomes block `k`,
/// from its parts in `ranges[k]`.
#[derive(Serialize, Deserialize)]
struct CleanRecord {
    generation: u32,
    spec: CleanSpec,
    parts: usize,
    alive: Vec<usize>,
    ranges: Vec<Vec<usize>>,
}

/// What came of the route tasks.
pub(crate) enum AfterRoutes {
    /// The estimates need a wider margin: route again (this generation).
    Reroute(u32),
    /// The plan is made (`prep/plan`): clean up this many blocks.
    CleanUp(usize),
}

/// After the route tasks of the current generation: the estimates on patches (their spills
/// fetched into `dir`), then either a wider margin (the next generation in `prep/routing`) or
/// the plan without its blocks in `prep/plan` and the clean-up's instructions.
pub(crate) fn after_routes(
    params: &ReconParams,
    options: &TiledOptions,
    block_points: usize,
    store: &Store,
    dir: &Path,
) -> Result<AfterRoutes, ReconError> {
    let s = survey(store)?;
    let mut routes = plan_routes(&s, params, options, block_points)?;
    let mut rec: RoutingRecord = get_json(store, "prep/routing")?;
    routes.margin = rec.margin;
    let parts = get_json::<Counts>(store, "prep/counts")?.ranges.len();
    let nb = routes.cores.len();
    let mut sum = Routed {
        core_points: vec![0; nb],
        spilled: vec![0; nb],
    };
    let mut per_range = Vec::with_capacity(parts);
    for r in 0..parts {
        let (core_points, spilled): (Vec<usize>, Vec<usize>) =
            get_json(store, &format!("prep/routed/{}/{r}", rec.generation))?;
        let part = Routed {
            core_points,
            spilled,
        };
        sum.add(&part);
        per_range.push(part.spilled);
    }
    let alive = alive_blocks(&sum);
    let picks = patches::pick_patches(&alive, &sum.spilled);
    for &b in &picks {
        fetch_spill(store, dir, rec.generation, b, &per_range)?;
    }
    let (support, noise) = patches::estimate_on_patches(
        (dir, parts),
        &picks,
        &routes.cores,
        s.has_normals,
        routes.tol,
        s.finite,
        params,
    )?;
    for &b in &picks {
        route::remove_block_spill(dir, b, parts);
    }
    if let Some(wider) = routes.wider_margin(params, options, &support)? {
        rec.generation += 1;
        rec.margin = wider;
        put_json(store, "prep/routing", &rec)?;
        return Ok(AfterRoutes::Reroute(rec.generation));
    }
    let (plan, spec) = prepare::plan_after_partition(&s, routes, support, noise, params, options)?;
    store.put("prep/plan", plan.encode())?;
    let clean = CleanRecord {
        generation: rec.generation,
        spec,
        parts,
        ranges: (alive.iter())
            .map(|&b| (0..parts).filter(|&r| per_range[r][b] > 0).collect())
            .collect(),
        alive,
    };
    put_json(store, "prep/clean", &clean)?;
    Ok(AfterRoutes::CleanUp(clean.alive.len()))
}

/// Fetches provisional block `b`'s parts of `generation` into `dir` (`per_range[r][b]` records
/// in part `r`).
fn fetch_spill(
    store: &Store,
    dir: &Path,
    generation: u32,
    b: usize,
    per_range: &[Vec<usize>],
) -> Result<(), ReconError> {
    for (r, spilled) in per_range.iter().enumerate() {
        if spilled[b] > 0 {
            write_part(store, dir, generation, b, r)?;
        }
    }
    Ok(())
}

fn write_part(store: &Store, dir: &Path, g: u32, b: usize, r: usize) -> Result<(), ReconError> {
    let bytes = store.get(&spill_key(g, b, r))?;
    let path = route::spill_path(dir, b, r);
    std::fs::write(&path, bytes)
        .map_err(|source| ReconError::Store(StoreError::Io { path, source }))
}

/// A cleaned block as stored.
#[derive(Serialize, Deserialize)]
struct BlockRecord {
    core: [Point3; 2],
    outer: [Point3; 2],
    members: usize,
    merged: usize,
    strays: usize,
}

/// Clean-up task: block `k`'s point set (`points/<k>`) from its spill parts (fetched into
/// `dir`), and its box and drops in `prep/block/<k>`. Returns the spill keys it consumed and the
/// keys it wrote.
pub(crate) fn clean_up(
    store: &Store,
    k: usize,
    dir: &Path,
) -> Result<(Vec<String>, Vec<String>), ReconError> {
    let clean: CleanRecord = get_json(store, "prep/clean")?;
    let rec: RoutingRecord = get_json(store, "prep/routing")?;
    let cores = rec.boxes();
    let prov = clean.alive[k];
    for &r in &clean.ranges[k] {
        write_part(store, dir, clean.generation, prov, r)?;
    }
    let out = BlockOutput {
        dir,
        parts: clean.parts,
        cores: &cores,
        spec: clean.spec,
    };
    let (b, d) = prepare::write_block(&out, k, prov, store)?;
    let rec = BlockRecord {
        core: [b.core.min, b.core.max],
        outer: [b.outer.min, b.outer.max],
        members: b.members,
        merged: d.merged,
        strays: d.strays,
    };
    let key = format!("prep/block/{k}");
    put_json(store, &key, &rec)?;
    let consumed = (clean.ranges[k].iter())
        .map(|&r| spill_key(clean.generation, prov, r))
        .collect();
    Ok((consumed, vec![super::tasks::block_key(k), key]))
}

/// After the clean-up tasks: the plan with its blocks.
pub(crate) fn complete(store: &Store, params: &ReconParams) -> Result<Plan, ReconError> {
    let mut plan = Plan::decode(&store.get("prep/plan")?, "prep/plan", params)?;
    let clean: CleanRecord = get_json(store, "prep/clean")?;
    let mut blocks = Vec::with_capacity(clean.alive.len());
    let mut dropped = Dropped::default();
    for k in 0..clean.alive.len() {
        let b: BlockRecord = get_json(store, &format!("prep/block/{k}"))?;
        let aabb = |[min, max]: [Point3; 2]| Aabb { min, max };
        blocks.push(BlockBox {
            core: aabb(b.core),
            outer: aabb(b.outer),
            members: b.members,
        });
        dropped.merged += b.merged;
        dropped.strays += b.strays;
    }
    prepare::complete_plan(&mut plan, blocks, &dropped);
    Ok(plan)
}

/// The keys of the `prep/…` values other than the spills, for removal: `ranges` ranges,
/// generations up to `generation`, `blocks` cleaned blocks.
pub(crate) fn prep_keys(ranges: usize, generation: u32, blocks: usize) -> Vec<String> {
    let mut keys: Vec<String> = ["prep/counts", "prep/routing", "prep/plan", "prep/clean"]
        .map(String::from)
        .to_vec();
    for r in 0..ranges {
        keys.push(format!("prep/count/{r}"));
        keys.push(format!("prep/sample/{r}"));
        for g in 0..=generation {
            keys.push(format!("prep/routed/{g}/{r}"));
        }
    }
    keys.extend((0..blocks).map(|k| format!("prep/block/{k}")));
    keys
}
