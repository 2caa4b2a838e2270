//! `EXT_meshopt_compression` decoding: every compressed bufferView is decoded with meshoptimizer's
//! codecs (attributes, triangles, indices; the octahedral filter) and appended to a copy of the BIN
//! chunk, and the view is rewritten to point at the decoded bytes, so the accessor reader sees a
//! plain glTF. The extension's layout rules are checked first, and a stream may not declare more
//! data than its bytes can encode (attributes: 64 elements bytes per byte, the codec's 2-bit group
//! header; triangles: one code byte per triangle), so hostile counts cannot make us allocate.
//!
//! Time and memory O(decoded size).
//!
//! Reference: Khronos glTF extension `EXT_meshopt_compression`, Appendix A (bitstream) and B
//! (filters).

use std::path::Path;

use serde_json::Value;

use super::super::IoError;

/// The extensions this reader implements (removed from `extensionsRequired` once handled).
pub(super) const HANDLED: [&str; 2] = ["EXT_meshopt_compression", "KHR_mesh_quantization"];
const EXT: &str = "EXT_meshopt_compression";

/// Most decoded bytes one compressed attribute byte can give: each group of 16 elements needs at
/// least 2 header bits per element byte (Appendix A), i.e. 64 decoded bytes per encoded byte.
const MAX_ATTRIBUTE_RATIO: usize = 64;

struct Ctx<'a> {
    src: &'a Path,
}

impl Ctx<'_> {
    fn invalid(&self, message: String) -> IoError {
        IoError::Invalid {
            path: self.src.to_path_buf(),
            format: "GLB",
            message,
        }
    }

    fn unsupported(&self, feature: String) -> IoError {
        IoError::Unsupported {
            path: self.src.to_path_buf(),
            format: "GLB",
            feature,
        }
    }
}

/// One compressed view's extension object.
struct Compressed {
    buffer: u64,
    offset: usize,
    length: usize,
    stride: usize,
    count: usize,
    mode: String,
    filter: String,
}

fn field(ext: &Value, name: &str, ctx: &Ctx, view: usize) -> Result<usize, IoError> {
    ext.get(name)
        .and_then(Value::as_u64)
        .and_then(|v| usize::try_from(v).ok())
        .ok_or_else(|| {
            ctx.invalid(format!(
                "bufferViews[{view}].extensions.{EXT}.{name} is missing or not a count"
            ))
        })
}

fn parse(ext: &Value, ctx: &Ctx, view: usize) -> Result<Compressed, IoError> {
    let text = |name: &str, default: &str| -> Result<String, IoError> {
        match ext.get(name) {
            None => Ok(default.to_string()),
            Some(Value::String(s)) => Ok(s.clone()),
            Some(_) => Err(ctx.invalid(format!(
                "bufferViews[{view}].extensions.{EXT}.{name} is not a string"
            ))),
        }
    };
    Ok(Compressed {
        buffer: field(ext, "buffer", ctx, view)? as u64,
        offset: match ext.get("byteOffset") {
            None => 0,
            Some(_) => field(ext, "byteOffset", ctx, view)?,
        },
        length: field(ext, "byteLength", ctx, view)?,
        stride: field(ext, "byteStride", ctx, view)?,
        count: field(ext, "count", ctx, view)?,
        mode: text("mode", "")?,
        filter: text("filter", "NONE")?,
    })
}

/// Decodes every `EXT_meshopt_compression` view of `doc` (rewritten in place) from `bin`; returns
/// the new BIN chunk, or `None` when nothing was compressed. Both handled extensions are taken off
/// `extensionsRequired` / `extensionsUsed`.
pub(super) fn unpack(doc: &mut Value, bin: &[u8], src: &Path) -> Result<Option<Vec<u8>>, IoError> {
    let ctx = Ctx { src };
    for key in ["extensionsRequired", "extensionsUsed"] {
        if let Some(list) = doc.get_mut(key).and_then(Value::as_array_mut) {
            list.retain(|e| !e.as_str().is_some_and(|s| HANDLED.contains(&s)));
        }
    }
    let Some(views) = doc.get_mut("bufferViews").and_then(Value::as_array_mut) else {
        return Ok(None);
    };
    let mut out: Option<Vec<u8>> = None;
    for (i, view) in views.iter_mut().enumerate() {
        let Some(ext) = view.get("extensions").and_then(|e| e.get(EXT)) else {
            continue;
        };
        let c = parse(ext, &ctx, i)?;
        let decoded = decode_view(&c, view, bin, &ctx, i)?;
        let data = out.get_or_insert_with(|| {
            let mut b = bin.to_vec();
            b.resize(bin.len().next_multiple_of(4), 0);
            b
        });
        let at = data.len();
        data.extend_from_slice(&decoded);
        data.resize(data.len().next_multiple_of(4), 0);
        view["buffer"] = Value::from(0);
        view["byteOffset"] = Value::from(at);
        if let Some(exts) = view.get_mut("extensions").and_then(Value::as_object_mut) {
            exts.remove(EXT);
        }
    }
    if let Some(data) = &out {
        match doc.get_mut("buffers").and_then(Value::as_array_mut) {
            Some(buffers) if !buffers.is_empty() => {
                buffers[0]["byteLength"] = Value::from(data.len())
            }
            _ => return Err(ctx.invalid("compressed views but no buffers".into())),
        }
    }
    Ok(out)
}

/// Checks the extension's rules for view `i` and decodes its stream.
fn decode_view(
    c: &Compressed,
    view: &Value,
    bin: &[u8],
    ctx: &Ctx,
    i: usize,
) -> Result<Vec<u8>, IoError> {
    let bad = |what: String| Err(ctx.invalid(format!("bufferViews[{i}] ({EXT}): {what}")));
    if c.buffer != 0 {
        return Err(ctx.unsupported(format!(
            "compressed data in buffer {} (only the GLB BIN chunk, buffer 0, is read)",
            c.buffer
        )));
    }
    let raw = c.count.checked_mul(c.stride);
    let view_len = view.get("byteLength").and_then(Value::as_u64);
    if raw.map(|r| r as u64) != view_len {
        return bad(format!(
            "count {} × byteStride {} is not the view's byteLength {:?}",
            c.count, c.stride, view_len
        ));
    }
    if let Some(s) = view.get("byteStride")
        && s.as_u64() != Some(c.stride as u64)
    {
        return bad(format!(
            "byteStride {s} differs from the extension's {}",
            c.stride
        ));
    }
    let Some(stream) = c
        .offset
        .checked_add(c.length)
        .and_then(|end| bin.get(c.offset..end))
    else {
        return Err(IoError::Truncated {
            path: ctx.src.to_path_buf(),
            format: "GLB",
            what: format!("bufferViews[{i}] compressed stream"),
            expected: c.offset.saturating_add(c.length) as u64,
            found: bin.len() as u64,
        });
    };
    let codec = |e: meshopt::Error| {
        ctx.invalid(format!("bufferViews[{i}]: corrupt {} stream ({e})", c.mode))
    };
    match c.mode.as_str() {
        "ATTRIBUTES" => {
            if c.stride == 0 || !c.stride.is_multiple_of(4) || c.stride > 256 {
                return bad(format!(
                    "ATTRIBUTES byteStride {} (must be a multiple of 4, at most 256)",
                    c.stride
                ));
            }
            if stream.first() != Some(&0xa0) {
                return bad(format!(
                    "vertex stream header {:?} is not 0xa0 (codec version 0)",
                    stream.first()
                ));
            }
            if c.count * c.stride > stream.len().saturating_mul(MAX_ATTRIBUTE_RATIO) {
                return bad(format!(
                    "{} bytes cannot encode {} elements of {} bytes",
                    stream.len(),
                    c.count,
                    c.stride
                ));
            }
            let mut data = decode_attributes(stream, c.count, c.stride).map_err(codec)?;
            apply_filter(&mut data, c, ctx, i)?;
            Ok(data)
        }
        "TRIANGLES" | "INDICES" => {
            if c.filter != "NONE" {
                return bad(format!("filter {} on index data", c.filter));
            }
            let triangles = c.mode == "TRIANGLES";
            if triangles && !c.count.is_multiple_of(3) {
                return bad(format!(
                    "TRIANGLES count {} is not a multiple of 3",
                    c.count
                ));
            }
            // One code byte per triangle (mode 1), at least one byte per index (mode 2).
            let most = if triangles {
                stream.len().saturating_mul(3)
            } else {
                stream.len()
            };
            if c.count > most {
                return bad(format!(
                    "{} bytes cannot encode {} indices",
                    stream.len(),
                    c.count
                ));
            }
            decode_indices(stream, c.count, c.stride, triangles)
                .ok_or_else(|| {
                    ctx.invalid(format!(
                        "bufferViews[{i}]: index byteStride {} (must be 2 or 4)",
                        c.stride
                    ))
                })?
                .map_err(codec)
        }
        other => bad(format!("unknown mode {other:?}")),
    }
}

fn decode_indices(
    stream: &[u8],
    count: usize,
    stride: usize,
    triangles: bool,
) -> Option<meshopt::Result<Vec<u8>>> {
    let le16 = |v: Vec<u16>| v.iter().flat_map(|i| i.to_le_bytes()).collect();
    let le32 = |v: Vec<u32>| v.iter().flat_map(|i| i.to_le_bytes()).collect();
    Some(match (stride, triangles) {
        (2, true) => meshopt::decode_index_buffer::<u16>(stream, count).map(le16),
        (4, true) => meshopt::decode_index_buffer::<u32>(stream, count).map(le32),
        (2, false) => meshopt::decode_index_sequence::<u16>(stream, count).map(le16),
        (4, false) => meshopt::decode_index_sequence::<u32>(stream, count).map(le32),
        _ => return None,
    })
}

/// The attribute codec for one element size (the codec needs the stride as a type).
fn attributes_of<const N: usize>(stream: &[u8], count: usize) -> meshopt::Result<Vec<u8>>
where
    [u8; N]: Default,
{
    meshopt::decode_vertex_buffer::<[u8; N]>(stream, count).map(|v| v.concat())
}

fn decode_attributes(stream: &[u8], count: usize, stride: usize) -> meshopt::Result<Vec<u8>> {
    match stride {
        4 => attributes_of::<4>(stream, count),
        8 => attributes_of::<8>(stream, count),
        12 => attributes_of::<12>(stream, count),
        16 => attributes_of::<16>(stream, count),
        20 => attributes_of::<20>(stream, count),
        24 => attributes_of::<24>(stream, count),
        28 => attributes_of::<28>(stream, count),
        32 => attributes_of::<32>(stream, count),
        // rbfsurf writes at most 8-byte elements; wider interleaved vertices are rare.
        _ => Err(meshopt::Error::Config(format!(
            "attribute byteStride {stride} above 32 is not supported"
        ))),
    }
}

fn apply_filter(data: &mut [u8], c: &Compressed, ctx: &Ctx, i: usize) -> Result<(), IoError> {
    match (c.filter.as_str(), c.stride) {
        ("NONE", _) => Ok(()),
        ("OCTAHEDRAL", 4) => {
            let mut v: Vec<[i8; 4]> = data
                .chunks_exact(4)
                .map(|b| [0, 1, 2, 3].map(|k| b[k] as i8))
                .collect();
            meshopt::decode_filter_oct(&mut v);
            for (dst, src) in data.chunks_exact_mut(4).zip(&v) {
                dst.copy_from_slice(&src.map(|x| x as u8));
            }
            Ok(())
        }
        ("OCTAHEDRAL", 8) => {
            let mut v: Vec<[i16; 4]> = (data.chunks_exact(8))
                .map(|b| [0, 1, 2, 3].map(|k| i16::from_le_bytes([b[2 * k], b[2 * k + 1]])))
                .collect();
            meshopt::decode_filter_oct(&mut v);
            for (dst, src) in data.chunks_exact_mut(8).zip(&v) {
                for k in 0..4 {
                    dst[2 * k..2 * k + 2].copy_from_slice(&src[k].to_le_bytes());
                }
            }
            Ok(())
        }
        (f, s) => Err(ctx.unsupported(format!(
            "bufferViews[{i}]: {EXT} filter {f} with byteStride {s}"
        ))),
    }
}
