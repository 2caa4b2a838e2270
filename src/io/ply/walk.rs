//! Walks the PLY body element by element in file order: the `vertex` element into points (and
//! normals), a `face` element's index lists into fan triangles (for meshes), everything else
//! skipped. Works on any [`Body`], so ASCII and binary share one decoding path. Time O(body).

use std::path::Path;

use super::body::{At, Body, Field};
use super::header::{Element, Header, PropKind, Scalar};
use super::{Plan, ROW, Want};
use crate::io::IoError;
use crate::io::stream::PointSink;

/// Reads every element in file order, handing the vertices to `out` and returning the fan
/// triangles of the faces (for [`Want::Mesh`]).
pub(super) fn walk<B: Body>(
    b: &mut B,
    h: &Header,
    plan: &Plan,
    out: &mut dyn PointSink,
) -> Result<Vec<[u32; 3]>, IoError> {
    let mut triangles = Vec::new();
    for (ei, el) in h.elements.iter().enumerate() {
        let face_list = (plan.want == Want::Mesh && el.name == "face")
            .then(|| {
                el.props.iter().position(|p| {
                    matches!(p.kind, PropKind::List { .. })
                        && (p.name == "vertex_indices" || p.name == "vertex_index")
                })
            })
            .flatten();
        if ei == plan.vertex {
            read_vertices(b, el, plan, out)?;
        } else if let Some(li) = face_list {
            read_faces(b, el, li, &mut triangles)?;
        } else {
            skip_element(b, el)?;
        }
    }
    Ok(triangles)
}

/// Byte layout of a vertex record without list properties: its size and the used fields.
fn fixed_layout(el: &Element, slots: &[Option<usize>]) -> Option<(usize, Vec<Field>)> {
    let mut offset = 0;
    let mut fields = Vec::new();
    for (p, slot) in el.props.iter().zip(slots) {
        let PropKind::Scalar(ty) = p.kind else {
            return None;
        };
        if let Some(slot) = *slot {
            fields.push(Field { offset, ty, slot });
        }
        offset += ty.size();
    }
    Some((offset, fields))
}

fn read_vertices<B: Body>(
    b: &mut B,
    el: &Element,
    plan: &Plan,
    out: &mut dyn PointSink,
) -> Result<(), IoError> {
    let layout = fixed_layout(el, plan.slots);
    for record in 0..el.count {
        let at = At {
            el: &el.name,
            record,
        };
        let mut row = [0.0f64; ROW];
        let whole = match &layout {
            Some((size, fields)) => b.fixed_record(*size, fields, &mut row, at)?,
            None => false,
        };
        if !whole {
            read_vertex_values(b, el, plan.slots, &mut row, at)?;
        }
        let normal = plan.has_normals.then_some([row[3], row[4], row[5]]);
        out.push([row[0], row[1], row[2]], normal)?;
        if let Some(scale) = plan.color_scale {
            out.push_color([0, 1, 2].map(|k| (row[6 + k] / scale[k]).clamp(0.0, 1.0) as f32));
        }
    }
    Ok(())
}

/// One vertex record value by value (ASCII, or binary with list properties).
fn read_vertex_values<B: Body>(
    b: &mut B,
    el: &Element,
    slots: &[Option<usize>],
    row: &mut [f64; ROW],
    at: At,
) -> Result<(), IoError> {
    for (p, slot) in el.props.iter().zip(slots) {
        match p.kind {
            PropKind::Scalar(t) => {
                let v = b.scalar(t, at)?;
                if let Some(s) = slot {
                    row[*s] = v;
                }
            }
            PropKind::List { count, item } => {
                let len = list_len(b.scalar(count, at)?, el, b.src())?;
                b.skip(item, len, at)?;
            }
        }
    }
    Ok(())
}

fn read_faces<B: Body>(
    b: &mut B,
    el: &Element,
    list_prop: usize,
    tris: &mut Vec<[u32; 3]>,
) -> Result<(), IoError> {
    let mut poly: Vec<u32> = Vec::new();
    for record in 0..el.count {
        let at = At {
            el: &el.name,
            record,
        };
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                PropKind::Scalar(t) => b.skip(t, 1, at)?,
                PropKind::List { count, item } => {
                    let len = list_len(b.scalar(count, at)?, el, b.src())?;
                    if pi != list_prop {
                        b.skip(item, len, at)?;
                        continue;
                    }
                    poly.clear();
                    for _ in 0..len {
                        let v = b.scalar(item, at)?;
                        poly.push(index_value(v, b.src())?);
                    }
                    fan(&poly, tris);
                }
            }
        }
    }
    Ok(())
}

fn skip_element<B: Body>(b: &mut B, el: &Element) -> Result<(), IoError> {
    if el.props.is_empty() {
        return Ok(());
    }
    if let Some(t) = fixed_scalar_type(el) {
        // All properties scalar of one size: skip the whole element at once.
        let at = At {
            el: &el.name,
            record: 0,
        };
        return b.skip(t, el.count.saturating_mul(el.props.len() as u64), at);
    }
    for record in 0..el.count {
        let at = At {
            el: &el.name,
            record,
        };
        for p in &el.props {
            match p.kind {
                PropKind::Scalar(t) => b.skip(t, 1, at)?,
                PropKind::List { count, item } => {
                    let len = list_len(b.scalar(count, at)?, el, b.src())?;
                    b.skip(item, len, at)?;
                }
            }
        }
    }
    Ok(())
}

/// The common type when all properties are scalars of the same type.
fn fixed_scalar_type(el: &Element) -> Option<Scalar> {
    let mut t = None;
    for p in &el.props {
        match (p.kind, t) {
            (PropKind::Scalar(s), None) => t = Some(s),
            (PropKind::Scalar(s), Some(u)) if s.size() == u.size() => {}
            _ => return None,
        }
    }
    t
}

fn list_len(v: f64, el: &Element, src: &Path) -> Result<u64, IoError> {
    if v >= 0.0 && v.fract() == 0.0 && v < 4.0e9 {
        Ok(v as u64)
    } else {
        Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "PLY",
            message: format!(
                "list length {v} in element `{}` is not a valid count",
                el.name
            ),
        })
    }
}

fn index_value(v: f64, src: &Path) -> Result<u32, IoError> {
    if v >= 0.0 && v.fract() == 0.0 && v < f64::from(u32::MAX) {
        Ok(v as u32)
    } else {
        Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "PLY",
            message: format!("face index {v} is not a valid vertex index"),
        })
    }
}

/// Fan triangulation of a polygon (v0, vi, vi+1); polygons with < 3 corners add nothing.
pub(crate) fn fan(poly: &[u32], tris: &mut Vec<[u32; 3]>) {
    for i in 1..poly.len().saturating_sub(1) {
        tris.push([poly[0], poly[i], poly[i + 1]]);
    }
}
