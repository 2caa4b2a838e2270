//! Stanford PLY reader (own parser): header, then the `vertex` element as points (x, y, z,
//! optional nx, ny, nz and optional red, green, blue) and, for meshes, the `face` element's index
//! lists (fan-triangulated). Colours are scaled to [0, 1] by their type's range (8-bit / 255,
//! 16-bit / 65535, floating point as stored, clamped) and kept as stored (sRGB, the scanners'
//! convention).
//!
//! Handles `ascii`, `binary_little_endian` and `binary_big_endian`, every scalar type under both
//! naming schemes, any property order, list properties and unrelated elements in any position, and
//! CRLF header lines. Before any allocation proportional to a declared count it checks the vertex
//! count against [`ReadLimits::max_points`], the minimum body size implied by the header against
//! the bytes present, and (for point clouds) the reader's memory against
//! [`ReadLimits::max_memory_mib`].
//!
//! Streaming: the body is read from any [`BufRead`] in chunks of [`CHUNK_BYTES`] and decoded
//! straight into the point arrays, so a file is never held whole; an in-memory slice goes through
//! the same path. Time O(file size), memory O(points + chunk).
//!
//! Reference: G. Turk, "The PLY Polygon File Format" (1994).

use std::io::BufRead;
use std::path::Path;

mod body;
mod header;
mod split;
mod walk;

#[cfg(test)]
mod stream_tests;
#[cfg(test)]
mod tests;

pub(crate) use split::{PlyRecords, vertex_records};
pub(crate) use walk::fan;

use body::{AsciiBody, BinBody};
use header::{Element, Encoding, Header, PropKind, read_header};

use super::budget::{CountSource, check_reader_memory};
use super::stream::{PointSink, VecSink};
use super::{IoError, ReadLimits};
use crate::geometry::{PointCloud, TriMesh};

/// Bytes read from the input at a time (64 KiB); vertex records are decoded from this buffer.
pub(crate) const CHUNK_BYTES: usize = 64 << 10;

/// What to extract from the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    Points,
    Mesh,
}

/// Values of a vertex record kept: x, y, z, nx, ny, nz, red, green, blue.
pub(super) const ROW: usize = 9;

/// What [`walk::walk`] keeps: the vertex element's index, its column slots, the colour scale
/// (each channel's full-scale value, when the vertices carry red, green and blue) and the target.
struct Plan<'a> {
    vertex: usize,
    slots: &'a [Option<usize>],
    has_normals: bool,
    color_scale: Option<[f64; 3]>,
    want: Want,
}

/// The columns of the vertex element and what they hold.
struct VertexColumns {
    /// Per property: its slot in the record row ([`ROW`]), `None` = ignored.
    slots: Vec<Option<usize>>,
    /// Whether nx, ny, nz are all present.
    normals: bool,
    /// Full-scale value of red, green and blue when all three are present.
    color_scale: Option<[f64; 3]>,
}

/// Reads the `vertex` element of a PLY stream as a point cloud (other elements skipped).
/// `len` is the input's total size in bytes (header + body), `chunk` the read size in bytes.
pub(crate) fn read_ply_points<R: BufRead>(
    r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
    chunk: usize,
) -> Result<PointCloud, IoError> {
    let mut out = VecSink::default();
    let (has_normals, _) = read_ply_into(r, len, limits, src, Want::Points, chunk, &mut out)?;
    Ok(out.into_cloud(has_normals))
}

/// Reads the `vertex` element of a PLY stream into `out`, record by record (other elements
/// skipped); returns whether the vertices carry normals. The reader's memory check applies only
/// when `out` holds the points.
pub(crate) fn stream_ply_points<R: BufRead>(
    r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
    out: &mut dyn PointSink,
) -> Result<bool, IoError> {
    read_ply_into(r, len, limits, src, Want::Points, CHUNK_BYTES, out).map(|(n, _)| n)
}

/// Reads `vertex` + `face` (`vertex_indices` or `vertex_index` list) as a triangle mesh.
pub(crate) fn read_ply_mesh(
    bytes: &[u8],
    limits: &ReadLimits,
    src: &Path,
) -> Result<TriMesh, IoError> {
    let len = bytes.len() as u64;
    let mut out = VecSink::default();
    let (has_normals, triangles) =
        read_ply_into(bytes, len, limits, src, Want::Mesh, CHUNK_BYTES, &mut out)?;
    let c = out.into_cloud(has_normals);
    let n = c.points.len();
    if let Some(bad) = triangles.iter().flatten().find(|&&i| i as usize >= n) {
        return Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "PLY",
            message: format!("face refers to vertex {bad} but there are only {n} vertices"),
        });
    }
    let normals = c
        .normals
        .map(|ns| {
            ns.into_iter()
                .map(|v| crate::geometry::normalized(v).unwrap_or([0.0; 3]))
                .collect()
        })
        .unwrap_or_default();
    Ok(TriMesh {
        vertices: c.points,
        normals,
        triangles,
        colors: Vec::new(),
    })
}

/// Reads only the header: the declared vertex count and whether nx, ny, nz are all present.
pub(crate) fn peek_vertices<R: BufRead>(mut r: R, src: &Path) -> Result<(u64, bool), IoError> {
    let (h, _) = read_header(&mut r, src)?;
    let vi = vertex_element(&h, src)?;
    let cols = vertex_slots(&h.elements[vi], src)?;
    Ok((h.elements[vi].count, cols.normals))
}

fn vertex_element(h: &Header, src: &Path) -> Result<usize, IoError> {
    h.elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| IoError::MissingField {
            path: src.to_path_buf(),
            format: "PLY",
            field: "element vertex".into(),
        })
}

/// Column slots of the vertex element: 0..3 = xyz, 3..6 = normals, 6..9 = colour.
fn vertex_slots(el: &Element, src: &Path) -> Result<VertexColumns, IoError> {
    let names: [&[&str]; ROW] = [
        &["x"],
        &["y"],
        &["z"],
        &["nx", "normal_x"],
        &["ny", "normal_y"],
        &["nz", "normal_z"],
        &["red", "r", "diffuse_red"],
        &["green", "g", "diffuse_green"],
        &["blue", "b", "diffuse_blue"],
    ];
    let mut slots = vec![None; el.props.len()];
    let mut found = [false; ROW];
    let mut scale = [1.0f64; 3];
    for (i, p) in el.props.iter().enumerate() {
        if !matches!(p.kind, PropKind::Scalar(_)) {
            continue;
        }
        let slot = names
            .iter()
            .position(|alts| alts.contains(&p.name.as_str()));
        if let Some(s) = slot.filter(|&s| !found[s]) {
            found[s] = true;
            slots[i] = Some(s);
            if let (Some(c), PropKind::Scalar(t)) = (s.checked_sub(6), p.kind) {
                scale[c] = t.full_scale();
            }
        }
    }
    if let Some(miss) = (0..3).find(|&s| !found[s]) {
        return Err(IoError::MissingField {
            path: src.to_path_buf(),
            format: "PLY",
            field: names[miss][0].to_string(),
        });
    }
    let normals = found[3..6].iter().all(|&f| f);
    let colors = found[6..].iter().all(|&f| f);
    for s in slots.iter_mut() {
        let drop = match *s {
            Some(3..6) => !normals,
            Some(6..) => !colors,
            _ => false,
        };
        if drop {
            *s = None;
        }
    }
    Ok(VertexColumns {
        slots,
        normals,
        color_scale: colors.then_some(scale),
    })
}

/// Fails fast when the body is shorter than the header's elements need at minimum.
fn check_body_size(h: &Header, body_len: u64, src: &Path) -> Result<(), IoError> {
    let need: u128 = h
        .elements
        .iter()
        .map(|e| u128::from(e.count) * u128::from(e.min_record_bytes(h.encoding)))
        .sum();
    // The last ASCII token needs no trailing separator.
    let slack = u128::from(h.encoding == Encoding::Ascii);
    if need > u128::from(body_len) + slack {
        let what = h
            .elements
            .iter()
            .map(|e| format!("{} `{}` records", e.count, e.name))
            .collect::<Vec<_>>()
            .join(" + ");
        return Err(IoError::Truncated {
            path: src.to_path_buf(),
            format: h.encoding.label(),
            what: format!("header declares {what}"),
            expected: u64::try_from(need).unwrap_or(u64::MAX),
            found: body_len,
        });
    }
    Ok(())
}

/// Reads the header, checks the declared counts, and walks the body handing the vertices to
/// `out`; returns whether they carry normals and the faces' fan triangles (for [`Want::Mesh`]).
fn read_ply_into<R: BufRead>(
    mut r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
    want: Want,
    chunk: usize,
    out: &mut dyn PointSink,
) -> Result<(bool, Vec<[u32; 3]>), IoError> {
    let (h, header_len) = read_header(&mut r, src)?;
    let vi = vertex_element(&h, src)?;
    let count = h.elements[vi].count;
    if count > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: count,
            limit: limits.max_points,
        });
    }
    let VertexColumns {
        slots,
        normals: has_normals,
        color_scale,
    } = vertex_slots(&h.elements[vi], src)?;
    check_body_size(&h, len.saturating_sub(header_len), src)?;
    if count == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "PLY header declares 0 vertices".into(),
        });
    }
    if want == Want::Points && out.holds_points() {
        check_reader_memory(count, has_normals, CountSource::Declared, limits, src)?;
    }
    // Counts were checked against the limits and the body size, so this allocation is bounded.
    out.reserve(count as usize);
    let plan = Plan {
        vertex: vi,
        slots: &slots,
        has_normals,
        color_scale,
        want,
    };
    let triangles = match h.encoding {
        Encoding::Ascii => {
            let mut body = AsciiBody::new(r, h.body_line, chunk, src);
            walk::walk(&mut body, &h, &plan, out)?
        }
        Encoding::BinaryLe | Encoding::BinaryBe => {
            let big = h.encoding == Encoding::BinaryBe;
            walk::walk(&mut BinBody::new(r, big, chunk, src), &h, &plan, out)?
        }
    };
    Ok((has_normals, triangles))
}
