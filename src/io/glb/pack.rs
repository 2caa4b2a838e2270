//! Compact GLB encoder: `KHR_mesh_quantization` + `EXT_meshopt_compression`.
//!
//! Positions are quantized to unsigned 16-bit integers on a uniform grid over the mesh's bounding
//! box (the same step on all three axes), stored unnormalized as VEC3 padded to 8 bytes; the node
//! carries the dequantization (`translation` = grid origin, uniform `scale` = grid step, both
//! exactly representable f32), so `node · q` gives the position back; the step is 1/65535 of the
//! longest bbox edge ([`grid_for`]). Normals are signed normalized bytes (VEC3 padded to 4
//! bytes), colours linear unsigned normalized shorts (VEC3 padded to 8 bytes), indices u16 or u32.
//! Vertices that quantize to the same grid point are merged first (triangles that lose a corner are
//! dropped, as for f32 rounding in [`super::super::snap`]). Triangles are ordered for the vertex
//! cache and vertices for fetch, then each stream is compressed with meshoptimizer's codecs:
//! vertex codec version 0 (header `0xa0`, mode `ATTRIBUTES`) and the triangle index codec
//! (header `0xe1`, mode `TRIANGLES`). The uncompressed layout lives in a fallback buffer without
//! data (`extensions.EXT_meshopt_compression.fallback = true`); both extensions are required.
//!
//! Time O(V + F) (meshoptimizer's cache optimizer is linear), memory O(V + F).
//!
//! References: Khronos glTF extensions `KHR_mesh_quantization` and `EXT_meshopt_compression`
//! (Kapoulkine, St. Pierre); A. Kapoulkine, meshoptimizer (vertex/index codecs, Forsyth-style
//! vertex cache optimisation).

use std::collections::BTreeMap;

use serde_json::{Value, json};

use super::super::{IoError, MeshMeta};
use super::{check_mesh, enc_err, srgb_to_linear, unit_normals};
use crate::geometry::TriMesh;

/// glTF component types used here.
const I8: u32 = 5120;
const U16: u32 = 5123;
const U32: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// Bits per quantized position coordinate (see [`grid_for`]).
const POSITION_BITS: u32 = 16;

/// The position grid: `p = origin + step · q`, `q` in `0..=max_q` on each axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Grid {
    /// Grid origin (f32, at or below the bbox minimum on each axis).
    pub origin: [f32; 3],
    /// Grid step (f32, the same on every axis).
    pub step: f32,
    /// Bits per coordinate.
    pub bits: u32,
}

impl Grid {
    /// The largest quantized value, `2^bits − 1`.
    pub fn max_q(&self) -> u32 {
        (1 << self.bits) - 1
    }

    /// The grid point nearest to `p` (clamped into the grid).
    pub fn quantize(&self, p: &[f64; 3]) -> [u16; 3] {
        let max = f64::from(self.max_q());
        [0, 1, 2].map(|k| {
            let q = ((p[k] - f64::from(self.origin[k])) / f64::from(self.step)).round();
            q.clamp(0.0, max) as u16
        })
    }

    /// The position of grid point `q`, exactly (f64 holds `origin + step · q` without rounding).
    pub fn dequantize(&self, q: [u16; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| f64::from(self.origin[k]) + f64::from(self.step) * f64::from(q[k]))
    }

    /// Worst-case distance between a position and its grid point: half a step on each axis.
    #[cfg(test)]
    pub fn max_error(&self) -> f64 {
        0.5 * f64::from(self.step) * 3f64.sqrt()
    }
}

/// The grid for `mesh`: origin at the bbox minimum rounded down to f32, step = longest bbox edge /
/// (2¹⁶ − 1) rounded up to f32. The precision follows the mesh's own scale: the step is 1.5·10⁻⁵ of
/// the longest edge, so a position moves by at most √3/2 step = 1.3·10⁻⁵ of it (and of the
/// diagonal), an order of magnitude below the reconstruction's accuracy (Chamfer ~10⁻⁴ of the
/// diagonal), and 1/16 of the finest marching grid cell (4096 cells along the longest edge; at
/// the default 64–200 cells, under 1/300 of a cell).
pub(crate) fn grid_for(mesh: &TriMesh) -> Result<Grid, IoError> {
    let b = crate::geometry::Aabb::from_points(&mesh.vertices);
    let origin = b.min.map(|c| {
        let f = c as f32;
        if f64::from(f) > c { f.next_down() } else { f }
    });
    if origin.iter().any(|c| !c.is_finite()) {
        return Err(enc_err(format!("bounding box {:?} overflows f32", b.min)));
    }
    let span = (0..3)
        .map(|k| b.max[k] - f64::from(origin[k]))
        .fold(0.0f64, f64::max);
    let bits = POSITION_BITS;
    let max_q = f64::from((1u32 << bits) - 1);
    let mut step = (span / max_q) as f32;
    if f64::from(step) * max_q < span {
        step = step.next_up();
    }
    if !(step.is_finite() && step > 0.0) {
        step = if span > 0.0 { f32::MIN_POSITIVE } else { 1.0 };
    }
    if !step.is_finite() || f64::from(step) * max_q < span {
        return Err(enc_err(format!("bounding box extent {span} overflows f32")));
    }
    Ok(Grid { origin, step, bits })
}

/// One compressed bufferView: its bytes in the BIN chunk and its uncompressed layout.
struct Stream {
    data: Vec<u8>,
    count: usize,
    stride: usize,
    mode: &'static str,
    filter: Option<&'static str>,
    target: u32,
}

fn vertex_stream<T>(items: &[T], stride: usize) -> Result<Stream, IoError> {
    let data = meshopt::encode_vertex_buffer_level(items, 2, Some(0))
        .map_err(|e| enc_err(format!("meshopt vertex codec: {e}")))?;
    Ok(Stream {
        data,
        count: items.len(),
        stride,
        mode: "ATTRIBUTES",
        filter: None,
        target: ARRAY_BUFFER,
    })
}

/// Vertex order of first use in `indices` (`remap[old] = new`, `u32::MAX` for a vertex no
/// triangle uses) and the number of used vertices. (meshopt 0.7's `optimize_vertex_fetch_remap`
/// truncates its table to the used count, so it cannot be indexed by every old vertex when a
/// vertex is unused, e.g. after merging on the grid dropped its last triangle.)
fn fetch_remap(indices: &[u32], n: usize) -> (Vec<u32>, usize) {
    let mut remap = vec![u32::MAX; n];
    let mut used = 0u32;
    for &i in indices {
        let r = &mut remap[i as usize];
        if *r == u32::MAX {
            *r = used;
            used += 1;
        }
    }
    (remap, used as usize)
}

/// Remaps `items` by the fetch-order `remap` (`new[remap[i]] = old[i]`).
fn remapped<T: Copy + Default>(items: &[T], remap: &[u32], n: usize) -> Vec<T> {
    let mut out = vec![T::default(); n];
    for (i, &r) in remap.iter().enumerate() {
        if (r as usize) < n {
            out[r as usize] = items[i];
        }
    }
    out
}

/// A mesh ready to encode: merged on the grid, in cache/fetch order.
pub(crate) struct Quantized {
    pub grid: Grid,
    pub positions: Vec<[u16; 4]>,
    pub normals: Vec<[i8; 4]>,
    pub colors: Vec<[u16; 4]>,
    pub indices: Vec<u32>,
}

/// Quantizes `mesh` onto its grid, merges vertices that share a grid point, orders triangles for
/// the vertex cache and vertices for fetch.
pub(crate) fn quantize(mesh: &TriMesh) -> Result<Quantized, IoError> {
    check_mesh(mesh, "GLB")?;
    let grid = grid_for(mesh)?;
    let keys: Vec<Option<[u16; 3]>> = mesh
        .vertices
        .iter()
        .map(|p| Some(grid.quantize(p)))
        .collect();
    let snap = |v: usize| grid.dequantize(keys[v].unwrap_or_default());
    let (merged, source) = match super::super::snap::merge_equal_keys(mesh, &keys, snap) {
        Some((m, s)) => (std::borrow::Cow::Owned(m), s),
        None => (std::borrow::Cow::Borrowed(mesh), (0..keys.len()).collect()),
    };
    check_mesh(&merged, "GLB")?;
    let n = merged.vertices.len();
    let q: Vec<[u16; 4]> = (source.iter())
        .map(|&v| {
            let k = keys[v].unwrap_or_default();
            [k[0], k[1], k[2], 0]
        })
        .collect();
    // Normals in octahedral form, 8 bits per component (the OCTAHEDRAL filter decodes them to
    // normalized bytes): about 1° worst-case direction error.
    let unit: Vec<[f32; 4]> = (unit_normals(&merged).iter())
        .map(|n| [n[0], n[1], n[2], 0.0])
        .collect();
    let normals: Vec<[i8; 4]> = meshopt::encode_filter_oct(&unit, 8);
    // Linear colour as normalized u16 (8-bit sRGB levels stay distinct: the darkest sRGB step
    // is 3.0·10⁻⁴ linear; a 12-bit rounding was measured to compress no better).
    let colors: Vec<[u16; 4]> = (merged.colors.iter())
        .map(|c| {
            let l = |x: f32| (srgb_to_linear(x).clamp(0.0, 1.0) * 65535.0).round() as u16;
            [l(c[0]), l(c[1]), l(c[2]), 0]
        })
        .collect();
    let flat: Vec<u32> = merged.triangles.iter().flatten().copied().collect();
    let cached = meshopt::optimize_vertex_cache(&flat, n);
    let (remap, used) = fetch_remap(&cached, n);
    let indices: Vec<u32> = cached.iter().map(|&i| remap[i as usize]).collect();
    Ok(Quantized {
        grid,
        positions: remapped(&q, &remap, used),
        normals: if normals.is_empty() {
            normals
        } else {
            remapped(&normals, &remap, used)
        },
        colors: if colors.is_empty() {
            colors
        } else {
            remapped(&colors, &remap, used)
        },
        indices,
    })
}

/// Encodes `mesh` as a compact GLB (see the module docs); `meta.crs` goes to `asset.extras.crs`.
/// Returns the bytes and the vertex and triangle counts written.
pub(crate) fn encode_compressed(
    mesh: &TriMesh,
    meta: &MeshMeta,
) -> Result<(Vec<u8>, usize, usize), IoError> {
    let qm = quantize(mesh)?;
    let n = qm.positions.len();
    let mut streams = vec![vertex_stream(&qm.positions, 8)?];
    if !qm.normals.is_empty() {
        let mut s = vertex_stream(&qm.normals, 4)?;
        s.filter = Some("OCTAHEDRAL");
        streams.push(s);
    }
    if !qm.colors.is_empty() {
        streams.push(vertex_stream(&qm.colors, 8)?);
    }
    let index_size = if n <= usize::from(u16::MAX) { 2 } else { 4 };
    streams.push(Stream {
        data: meshopt::encode_index_buffer(&qm.indices, n)
            .map_err(|e| enc_err(format!("meshopt index codec: {e}")))?,
        count: qm.indices.len(),
        stride: index_size,
        mode: "TRIANGLES",
        filter: None,
        target: ELEMENT_ARRAY_BUFFER,
    });
    let (views, bin, fallback_len) = lay_out(&streams);
    let doc = document(&qm, views, bin.len(), fallback_len, index_size);
    let out = super::container_value(doc, meta, bin)?;
    Ok((out, n, qm.indices.len() / 3))
}

/// The BIN chunk (compressed streams, each 4-byte aligned) and the bufferViews describing them.
fn lay_out(streams: &[Stream]) -> (Vec<Value>, Vec<u8>, usize) {
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut fallback = 0usize;
    for s in streams {
        let raw = s.count * s.stride;
        let mut ext = json!({
            "buffer": 0, "byteOffset": bin.len(), "byteLength": s.data.len(),
            "byteStride": s.stride, "mode": s.mode, "count": s.count,
        });
        if let Some(f) = s.filter {
            ext["filter"] = json!(f);
        }
        let mut view = json!({
            "buffer": 1, "byteOffset": fallback, "byteLength": raw, "target": s.target,
        });
        if s.mode == "ATTRIBUTES" {
            view["byteStride"] = json!(s.stride);
        }
        view["extensions"] = json!({ "EXT_meshopt_compression": ext });
        views.push(view);
        bin.extend_from_slice(&s.data);
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        fallback += raw.next_multiple_of(4);
    }
    (views, bin, fallback)
}

/// The glTF JSON of a compact GLB: buffers (BIN + fallback), views, accessors, one mesh, node and
/// scene; the node's translation and scale dequantize the positions.
fn document(
    qm: &Quantized,
    views: Vec<Value>,
    bin_len: usize,
    fallback_len: usize,
    index_size: usize,
) -> Value {
    let n = qm.positions.len();
    let (mut lo, mut hi) = ([u16::MAX; 3], [0u16; 3]);
    for p in &qm.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let mut accessors = vec![json!({
        "bufferView": 0, "componentType": U16, "count": n, "type": "VEC3",
        "min": lo, "max": hi,
    })];
    let mut attributes = BTreeMap::from([("POSITION", 0usize)]);
    if !qm.normals.is_empty() {
        attributes.insert("NORMAL", accessors.len());
        accessors.push(json!({
            "bufferView": accessors.len(), "componentType": I8, "normalized": true,
            "count": n, "type": "VEC3",
        }));
    }
    if !qm.colors.is_empty() {
        attributes.insert("COLOR_0", accessors.len());
        accessors.push(json!({
            "bufferView": accessors.len(), "componentType": U16, "normalized": true,
            "count": n, "type": "VEC3",
        }));
    }
    let indices = accessors.len();
    accessors.push(json!({
        "bufferView": indices, "componentType": if index_size == 2 { U16 } else { U32 },
        "count": qm.indices.len(), "type": "SCALAR",
    }));
    let g = qm.grid;
    let extensions = ["EXT_meshopt_compression", "KHR_mesh_quantization"];
    json!({
        "asset": { "version": "2.0", "generator": super::GENERATOR },
        "extensionsUsed": extensions,
        "extensionsRequired": extensions,
        "buffers": [
            { "byteLength": bin_len },
            { "byteLength": fallback_len,
              "extensions": { "EXT_meshopt_compression": { "fallback": true } } },
        ],
        "bufferViews": views,
        "accessors": accessors,
        "meshes": [{ "primitives": [{ "attributes": attributes, "indices": indices, "mode": 4 }] }],
        "nodes": [{ "mesh": 0, "translation": g.origin, "scale": [g.step, g.step, g.step] }],
        "scenes": [{ "nodes": [0] }],
        "scene": 0,
    })
}
