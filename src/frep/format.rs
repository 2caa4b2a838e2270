//! The `.field` file: a fitted CSRBF implicit function, versioned, little-endian, loads in one read.
//!
//! Layout of version 1 (every number little-endian; `f64` IEEE 754 binary64, written bit for bit):
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `RBFFIELD` |
//! | 4 | `u32` format version (1) |
//! | 4 | `u32` flags: bit 0 set = `f < 0` inside (always set by this version); bit 1 set = the local carrier's winding far field is off (the surface was trimmed open) |
//! | 32 | normalisation: offset `f64×3` (input units), scale `f64` (normalised units per input unit) |
//! | 1+1+2+4 | kernel `u8` (0 C⁰, 1 C², 2 C⁴), index `u8` (0 octree, 1 k-d tree), 2 zero bytes, leaf size `u32` |
//! | 16 | carrier radius `f64`, finest support `f64` (normalised units) |
//! | 8 + 24n | `u64` n, the n data points `f64×3` (normalised units) |
//! | … | carrier: `u8` tag 0 sphere (centre `f64×3`, radius `f64`), 1 ellipsoid (centre `f64×3`, axes `f64×9` row by row, semi-axes `f64×3`), 2 local with tangent planes, 3 local with quadrics, 4 local with wide quadrics (all three: radius `f64`, n normals `f64×3`, on the data points; the quadrics are fitted again on load, bit for bit) |
//! | … | correction: `u8` tag 0 global (one spline), 1 blocks (`u64` count, then per block: core min/max `f64×6`, outer min/max `f64×6`, spline) |
//! | 8 | FNV-1a 64 of every byte before it |
//!
//! A spline is `u8` 1 + polynomial `f64×4` (`v₀, v_x, v_y, v_z`) or `u8` 0, `u32` level count, then per
//! level: support `f64`, `u64` m, m centres `f64×3`, m weights `f64`.
//!
//! Every spatial index is rebuilt on load with the saved index kind and leaf size over the same
//! points, so neighbour lists come back in the same order and evaluation is bit for bit equal.

use super::{FieldModel, FrepError};
use crate::geometry::{Aabb, Normalization, Point3};
use crate::rbf::carrier::{LocalCarrier, LocalFit};
use crate::rbf::{Carrier, Correction, Kernel, PouBlock, RbfField, Spline, SplineLevel};
use crate::spatial::{IndexKind, SpatialIndex, build_index};
use std::path::Path;
use std::sync::Arc;

/// The file's first 8 bytes.
pub const MAGIC: &[u8; 8] = b"RBFFIELD";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;
const FLAG_NEGATIVE_INSIDE: u32 = 1;
const FLAG_NO_FAR_FIELD: u32 = 2;

/// 64-bit FNV-1a of `bytes` (the file's checksum).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

struct Writer(Vec<u8>);

impl Writer {
    fn f(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn p(&mut self, p: &Point3) {
        p.iter().for_each(|&c| self.f(c));
    }
    fn u64(&mut self, v: usize) {
        self.0.extend_from_slice(&(v as u64).to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn spline(&mut self, s: &Spline) {
        match s.polynomial {
            Some(v) => {
                self.u8(1);
                v.iter().for_each(|&c| self.f(c));
            }
            None => self.u8(0),
        }
        self.u32(s.levels.len() as u32);
        for l in &s.levels {
            self.f(l.support);
            self.u64(l.centres.len());
            l.centres.iter().for_each(|c| self.p(c));
            l.weights.iter().for_each(|&w| self.f(w));
        }
    }
    fn aabb(&mut self, b: &Aabb) {
        self.p(&b.min);
        self.p(&b.max);
    }
}

/// The `.field` bytes of `model` (version [`VERSION`]).
pub fn encode(model: &FieldModel) -> Vec<u8> {
    let f = &model.rbf;
    let mut w = Writer(Vec::with_capacity(64 + model.points.len() * 80));
    w.0.extend_from_slice(MAGIC);
    w.u32(VERSION);
    let far_off = matches!(&f.carrier, Carrier::Local(l) if !l.far_field_enabled());
    w.u32(FLAG_NEGATIVE_INSIDE | if far_off { FLAG_NO_FAR_FIELD } else { 0 });
    w.p(&model.normalization.offset);
    w.f(model.normalization.scale);
    w.u8(match f.kernel {
        Kernel::WendlandC0 => 0,
        Kernel::WendlandC2 => 1,
        Kernel::WendlandC4 => 2,
    });
    w.u8(match model.index {
        IndexKind::Octree => 0,
        IndexKind::KdTree => 1,
    });
    w.0.extend_from_slice(&[0, 0]);
    w.u32(model.leaf_size as u32);
    w.f(f.carrier_radius);
    w.f(f.finest_support);
    w.u64(model.points.len());
    model.points.iter().for_each(|p| w.p(p));
    match &f.carrier {
        Carrier::Sphere { center, radius } => {
            w.u8(0);
            w.p(center);
            w.f(*radius);
        }
        Carrier::Ellipsoid {
            center,
            axes,
            semi_axes,
        } => {
            w.u8(1);
            w.p(center);
            axes.iter().for_each(|a| w.p(a));
            w.p(semi_axes);
        }
        Carrier::Local(l) => {
            w.u8(match l.fit() {
                LocalFit::Plane => 2,
                LocalFit::WideQuadric => 4,
                _ => 3,
            });
            w.f(l.radius());
            l.normals().iter().for_each(|n| w.p(n));
        }
    }
    match &f.correction {
        Correction::Global(s) => {
            w.u8(0);
            w.spline(s);
        }
        Correction::Blocks(blocks) => {
            w.u8(1);
            w.u64(blocks.len());
            for b in blocks {
                w.aabb(&b.core);
                w.aabb(&b.outer);
                w.spline(&b.spline);
            }
        }
    }
    let sum = fnv1a(&w.0);
    w.0.extend_from_slice(&sum.to_le_bytes());
    w.0
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let end = end.ok_or_else(|| format!("truncated at byte {}", self.at))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or([0; 4]),
        ))
    }
    fn f(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or([0; 8]),
        ))
    }
    fn finite(&mut self, what: &str) -> Result<f64, String> {
        let v = self.f()?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(format!("{what} is not finite at byte {}", self.at - 8))
        }
    }
    fn p(&mut self) -> Result<Point3, String> {
        Ok([
            self.finite("a coordinate")?,
            self.finite("a coordinate")?,
            self.finite("a coordinate")?,
        ])
    }
    /// A count of items of `item_bytes` each that must fit in the rest of the file.
    fn count(&mut self, item_bytes: usize) -> Result<usize, String> {
        let n = u64::from_le_bytes(self.take(8)?.try_into().unwrap_or([0; 8]));
        let left = (self.b.len() - self.at) as u64;
        if n.saturating_mul(item_bytes as u64) > left {
            return Err(format!(
                "count {n} at byte {} exceeds the file",
                self.at - 8
            ));
        }
        Ok(n as usize)
    }
    fn points(&mut self, n: usize) -> Result<Vec<Point3>, String> {
        (0..n).map(|_| self.p()).collect()
    }
    fn aabb(&mut self) -> Result<Aabb, String> {
        Ok(Aabb {
            min: self.p()?,
            max: self.p()?,
        })
    }
}

/// Read the `.field` file at `path`.
pub fn read(path: &Path) -> Result<FieldModel, FrepError> {
    let bytes = std::fs::read(path).map_err(|e| FrepError::Read {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    decode(&bytes, &path.display().to_string())
}

/// Decode `.field` bytes; `name` names the source in errors.
pub fn decode(bytes: &[u8], name: &str) -> Result<FieldModel, FrepError> {
    let corrupt = |message: String| FrepError::Corrupt {
        path: name.to_string(),
        message,
    };
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err(corrupt("it does not start with RBFFIELD".into()));
    }
    let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    if version != VERSION {
        return Err(FrepError::Version {
            path: name.to_string(),
            found: version,
            supported: VERSION,
        });
    }
    let body = bytes.len().checked_sub(8).filter(|&b| b >= 16);
    let body = body.ok_or_else(|| corrupt("truncated".into()))?;
    let stored = u64::from_le_bytes(bytes[body..].try_into().unwrap_or([0; 8]));
    if fnv1a(&bytes[..body]) != stored {
        return Err(corrupt(
            "checksum mismatch (the file is truncated or was modified)".into(),
        ));
    }
    let mut r = Reader {
        b: &bytes[..body],
        at: 12,
    };
    let model = decode_body(&mut r).map_err(corrupt)?;
    if r.at != body {
        return Err(corrupt(format!(
            "{} unexpected bytes after the field",
            body - r.at
        )));
    }
    Ok(model)
}

fn positive(v: f64, what: &str) -> Result<f64, String> {
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} {v} is not positive"))
    }
}

fn decode_body(r: &mut Reader<'_>) -> Result<FieldModel, String> {
    let flags = r.u32()?;
    if flags & FLAG_NEGATIVE_INSIDE == 0 || flags & !(FLAG_NEGATIVE_INSIDE | FLAG_NO_FAR_FIELD) != 0
    {
        return Err(format!("unknown flags {flags:#x}"));
    }
    let offset = r.p()?;
    let scale = positive(r.finite("the scale")?, "the scale")?;
    let kernel = match r.u8()? {
        0 => Kernel::WendlandC0,
        1 => Kernel::WendlandC2,
        2 => Kernel::WendlandC4,
        k => return Err(format!("unknown kernel code {k}")),
    };
    let index = match r.u8()? {
        0 => IndexKind::Octree,
        1 => IndexKind::KdTree,
        k => return Err(format!("unknown index code {k}")),
    };
    r.take(2)?;
    let leaf_size = r.u32()? as usize;
    let carrier_radius = positive(r.finite("the carrier radius")?, "the carrier radius")?;
    let finest_support = positive(r.finite("the support")?, "the support")?;
    let n = r.count(24)?;
    if n == 0 {
        return Err("the field has no data points".into());
    }
    let points = r.points(n)?;
    let build = |pts: &[Point3]| -> Result<Arc<dyn SpatialIndex + Send>, String> {
        build_index(pts, index, leaf_size)
            .map(Arc::from)
            .map_err(|e| e.to_string())
    };
    let carrier_index = build(&points)?;
    let carrier = read_carrier(r, &points, &carrier_index)?;
    if let Carrier::Local(l) = &carrier {
        l.far_field_switch().store(
            flags & FLAG_NO_FAR_FIELD == 0,
            std::sync::atomic::Ordering::Relaxed,
        );
    }
    let correction = match r.u8()? {
        0 => Correction::Global(read_spline(r, &build)?),
        1 => {
            let count = r.count(96)?;
            let mut blocks = Vec::with_capacity(count);
            for _ in 0..count {
                let (core, outer) = (r.aabb()?, r.aabb()?);
                blocks.push(PouBlock {
                    core,
                    outer,
                    spline: read_spline(r, &build)?,
                });
            }
            Correction::Blocks(blocks)
        }
        t => return Err(format!("unknown correction tag {t}")),
    };
    Ok(FieldModel {
        rbf: Arc::new(RbfField {
            correction,
            kernel,
            carrier,
            carrier_index,
            carrier_radius,
            finest_support,
            unsupported_dropped: false,
        }),
        normalization: Normalization { offset, scale },
        points,
        index,
        leaf_size,
    })
}

fn read_carrier(
    r: &mut Reader<'_>,
    points: &[Point3],
    index: &Arc<dyn SpatialIndex + Send>,
) -> Result<Carrier, String> {
    Ok(match r.u8()? {
        0 => Carrier::Sphere {
            center: r.p()?,
            radius: positive(r.finite("the sphere radius")?, "the sphere radius")?,
        },
        1 => {
            let center = r.p()?;
            let axes = [r.p()?, r.p()?, r.p()?];
            let semi_axes = r.p()?;
            Carrier::Ellipsoid {
                center,
                axes,
                semi_axes,
            }
        }
        tag @ 2..=4 => {
            let radius = positive(r.finite("the carrier radius")?, "the carrier radius")?;
            let normals = r.points(points.len())?;
            let fit = match tag {
                2 => LocalFit::Plane,
                3 => LocalFit::Quadric,
                _ => LocalFit::WideQuadric,
            };
            let local =
                LocalCarrier::from_parts(points.to_vec(), normals, radius, Arc::clone(index), fit);
            Carrier::Local(local.ok_or("the local carrier has no usable normal")?)
        }
        t => return Err(format!("unknown carrier tag {t}")),
    })
}

type BuildIndex<'a> = dyn Fn(&[Point3]) -> Result<Arc<dyn SpatialIndex + Send>, String> + 'a;

fn read_spline(r: &mut Reader<'_>, build: &BuildIndex<'_>) -> Result<Spline, String> {
    let polynomial = match r.u8()? {
        0 => None,
        1 => Some([r.f()?, r.f()?, r.f()?, r.f()?]),
        t => return Err(format!("unknown polynomial tag {t}")),
    };
    let count = r.u32()? as usize;
    if count > 64 {
        return Err(format!("{count} levels (at most 64)"));
    }
    let mut levels = Vec::with_capacity(count);
    for _ in 0..count {
        let support = positive(r.finite("a level support")?, "a level support")?;
        let m = r.count(32)?;
        let centres = r.points(m)?;
        let weights = (0..m)
            .map(|_| r.finite("a weight"))
            .collect::<Result<Vec<_>, _>>()?;
        let index = build(&centres)?;
        levels.push(SplineLevel {
            centres,
            weights,
            support,
            index,
        });
    }
    Ok(Spline { levels, polynomial })
}

/// What `rbfsurf field info` prints: the file's header and sizes as JSON.
pub fn info(model: &FieldModel, file_bytes: u64) -> serde_json::Value {
    let f = &model.rbf;
    let (kind, levels, blocks) = match &f.correction {
        Correction::Global(s) => ("global", s.levels.len(), 0),
        Correction::Blocks(b) => (
            "blocks",
            b.first().map_or(0, |b| b.spline.levels.len()),
            b.len(),
        ),
    };
    let splines: Vec<&Spline> = match &f.correction {
        Correction::Global(s) => vec![s],
        Correction::Blocks(b) => b.iter().map(|b| &b.spline).collect(),
    };
    let centres: usize = splines
        .iter()
        .flat_map(|s| s.levels.iter().map(|l| l.centres.len()))
        .sum();
    let supports: Vec<f64> = splines
        .first()
        .map(|s| s.levels.iter().map(|l| l.support).collect())
        .unwrap_or_default();
    let b = model.data_bounds();
    serde_json::json!({
        "format_version": VERSION,
        "file_bytes": file_bytes,
        "sign": "f < 0 inside (rbfsurf); operands of csg/morph/voxelize use F = -f/scale >= 0 inside",
        "kernel": f.kernel.name(),
        "carrier": f.carrier.name(),
        "correction": kind,
        "levels": levels,
        "blocks": blocks,
        "polynomial": splines.iter().any(|s| s.polynomial.is_some()),
        "points": model.points.len(),
        "centres": centres,
        "support_normalised": supports,
        "support_input_units": supports.iter().map(|s| s / model.normalization.scale).collect::<Vec<_>>(),
        "carrier_radius_normalised": f.carrier_radius,
        "index": model.index.to_string(),
        "leaf_size": model.leaf_size,
        "normalization": {"offset": model.normalization.offset, "scale": model.normalization.scale},
        "data_bounds": {"min": b.min, "max": b.max},
    })
}
