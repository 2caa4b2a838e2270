//! ASPRS LAS 1.0–1.4 and LAZ (LASzip-compressed LAS) reader: every point data record format 0–10,
//! coordinates as `raw · scale + offset` in f64 (so UTM eastings and northings keep their
//! millimetres), RGB (formats 2, 3, 5, 7, 8, 10) and intensity carried along, the CRS (WKT VLR or
//! GeoTIFF keys) passed on verbatim.
//!
//! The fixed header is read and checked here before the `las` crate sees the file: point count
//! against [`ReadLimits::max_points`] and the memory budget, point data offset, VLR count and the
//! first EVLR's length against the file size, and for uncompressed data the body size the header
//! implies (a truncated file is refused before reading). For LAZ the chunk table's declared chunk
//! count is checked against the point count before the decompressor allocates it. Records are
//! then decoded [`CHUNK_POINTS`] at a time from one reused buffer (`las::PointData` columns), so
//! memory is the point arrays plus one chunk. A panic inside the LAZ decoder on corrupt data is
//! caught and reported as invalid data.
//!
//! References: ASPRS, "LAS Specification 1.4 – R15" (2019); Isenburg, "LASzip: lossless
//! compression of LiDAR data" (2013); OGC GeoTIFF 1.1 (2019) for the GeoKey directory.

use std::io::{BufRead, Read, Seek, SeekFrom};
use std::path::Path;

use las::PointDataBuilder;

use super::budget::{CountSource, ReaderCost, check_memory};
use super::{IoError, ReadLimits};
use crate::geometry::PointCloud;

/// File signature of LAS and LAZ.
pub(crate) const MAGIC: &[u8; 4] = b"LASF";

/// Records decoded per step.
pub(crate) const CHUNK_POINTS: usize = 16_384;

const FORMAT: &str = "LAS";

fn invalid(src: &Path, message: impl Into<String>) -> IoError {
    IoError::Invalid {
        path: src.to_path_buf(),
        format: FORMAT,
        message: message.into(),
    }
}

fn read_err(src: &Path, source: std::io::Error) -> IoError {
    IoError::Read {
        path: src.to_path_buf(),
        source,
    }
}

/// What the fixed header says, checked against the file size.
struct Checked {
    points: u64,
    compressed: bool,
    record_len: u64,
    offset_to_points: u64,
}

/// Reads the fixed header at the start of `r` and checks it against the file length `len`.
fn precheck<R: Read + Seek>(r: &mut R, len: u64, src: &Path) -> Result<Checked, IoError> {
    r.seek(SeekFrom::Start(0)).map_err(|e| read_err(src, e))?;
    let raw =
        las::raw::Header::read_from(&mut *r).map_err(|e| invalid(src, format!("header: {e}")))?;
    let legacy = u64::from(raw.number_of_point_records);
    let points = match raw.large_file {
        Some(l) if l.number_of_point_records > 0 => l.number_of_point_records,
        _ => legacy,
    };
    let offset_to_points = u64::from(raw.offset_to_point_data);
    let too_short = |what: String, expected: u64| IoError::Truncated {
        path: src.to_path_buf(),
        format: FORMAT,
        what,
        expected,
        found: len,
    };
    if offset_to_points > len {
        return Err(too_short(
            "header puts the point data at an offset past the end".into(),
            offset_to_points,
        ));
    }
    // Every VLR has a 54-byte header, all of them between the header and the point data.
    let vlr_bytes = u64::from(raw.number_of_variable_length_records) * 54;
    if u64::from(raw.header_size) + vlr_bytes > offset_to_points {
        return Err(invalid(
            src,
            format!(
                "{} VLRs cannot fit between the {}-byte header and the point data at byte {offset_to_points}",
                raw.number_of_variable_length_records, raw.header_size
            ),
        ));
    }
    let compressed = raw.point_data_record_format & 0xC0 != 0;
    let record_len = u64::from(raw.point_data_record_length);
    if let Some(evlr) = raw.evlr.filter(|e| e.number_of_evlrs > 0) {
        check_evlr(r, evlr.start_of_first_evlr, len, src)?;
    }
    Ok(Checked {
        points,
        compressed,
        record_len,
        offset_to_points,
    })
}

/// Uncompressed data: the body the header implies must be in the file (checked after the point
/// limit, so an absurd count is reported as such).
fn check_body(c: &Checked, len: u64, src: &Path) -> Result<(), IoError> {
    let need = u128::from(c.points) * u128::from(c.record_len) + u128::from(c.offset_to_points);
    if c.compressed || need <= u128::from(len) {
        return Ok(());
    }
    Err(IoError::Truncated {
        path: src.to_path_buf(),
        format: FORMAT,
        what: format!(
            "header declares {} points of {} bytes",
            c.points, c.record_len
        ),
        expected: u64::try_from(need).unwrap_or(u64::MAX),
        found: len,
    })
}

/// The first EVLR (the one the `las` crate reads whole) must lie inside the file.
fn check_evlr<R: Read + Seek>(r: &mut R, start: u64, len: u64, src: &Path) -> Result<(), IoError> {
    const EVLR_HEADER: u64 = 60;
    if start.checked_add(EVLR_HEADER).is_none_or(|end| end > len) {
        return Err(invalid(
            src,
            format!("EVLR at byte {start} is past the end"),
        ));
    }
    r.seek(SeekFrom::Start(start + 20))
        .map_err(|e| read_err(src, e))?;
    let mut b = [0u8; 8];
    r.read_exact(&mut b).map_err(|e| read_err(src, e))?;
    let data = u64::from_le_bytes(b);
    if data > len - start - EVLR_HEADER {
        return Err(invalid(
            src,
            format!("EVLR at byte {start} declares {data} bytes, more than the file holds"),
        ));
    }
    Ok(())
}

/// LAZ: the chunk table's declared chunk count must fit the point count (each chunk holds at
/// least one point, a fixed-size chunk `chunk_size`), so the decompressor's table is bounded.
fn check_chunk_table<R: Read + Seek>(
    r: &mut R,
    c: &Checked,
    vlr: &laz::LazVlr,
    len: u64,
    src: &Path,
) -> Result<(), IoError> {
    r.seek(SeekFrom::Start(c.offset_to_points))
        .map_err(|e| read_err(src, e))?;
    let mut b = [0u8; 8];
    if r.read_exact(&mut b).is_err() {
        return Err(IoError::Truncated {
            path: src.to_path_buf(),
            format: "LAZ",
            what: "no chunk table offset after the header".into(),
            expected: c.offset_to_points + 8,
            found: len,
        });
    }
    let table = i64::from_le_bytes(b);
    let Ok(table) = u64::try_from(table) else {
        return Ok(()); // -1: no table written (the decoder reads the chunks sequentially)
    };
    if table < c.offset_to_points + 8 || table.saturating_add(8) > len {
        return Ok(()); // not usable; the decoder reports it when it needs the table
    }
    r.seek(SeekFrom::Start(table + 4))
        .map_err(|e| read_err(src, e))?;
    let mut n = [0u8; 4];
    r.read_exact(&mut n).map_err(|e| read_err(src, e))?;
    let chunks = u64::from(u32::from_le_bytes(n));
    let bound = if vlr.uses_variable_size_chunks() {
        c.points
    } else {
        c.points.div_ceil(u64::from(vlr.chunk_size().max(1)))
    };
    if chunks > bound + 1 {
        return Err(invalid(
            src,
            format!(
                "LAZ chunk table declares {chunks} chunks for {} points",
                c.points
            ),
        ));
    }
    Ok(())
}

/// The declared point count of a LAS/LAZ stream (header only), checked against the file size.
pub(crate) fn peek_points<R: BufRead + Seek>(
    r: &mut R,
    len: u64,
    src: &Path,
) -> Result<u64, IoError> {
    Ok(precheck(r, len, src)?.points)
}

/// Reads every point of a LAS/LAZ stream of `len` bytes (see the module documentation).
pub(crate) fn read_las_points<R: Read + Seek + Send + Sync>(
    mut r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    let c = precheck(&mut r, len, src)?;
    if c.points > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: c.points,
            limit: limits.max_points,
        });
    }
    // Colour is counted whether or not the format has it: the check runs before the header's
    // VLRs are parsed. Coordinates 24 + RGB 12 + intensity 4 bytes per point.
    let cost = ReaderCost {
        per_point: 40,
        buffers: CHUNK_POINTS as u64 * c.record_len.max(20) + (64 << 10),
    };
    check_memory(c.points, cost, CountSource::Declared, limits, src)?;
    check_body(&c, len, src)?;
    if c.points == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "LAS header declares 0 points".into(),
        });
    }
    r.seek(SeekFrom::Start(0)).map_err(|e| read_err(src, e))?;
    let header = las::Header::new(&mut r).map_err(|e| invalid(src, e.to_string()))?;
    let crs = crs_of(&header);
    // LAZ: pre-allocated for at most one point per byte of file, so a lying count fails on the
    // data before the reader allocates for points that are not there.
    let capacity = c.points.min(len) as usize;
    let mut out = Columns::with_capacity(capacity, header.point_format().has_color);
    if c.compressed {
        let vlr = header
            .laz_vlr()
            .map_err(|e| invalid(src, format!("LAZ: {e}")))?;
        check_chunk_table(&mut r, &c, &vlr, len, src)?;
        r.seek(SeekFrom::Start(c.offset_to_points))
            .map_err(|e| read_err(src, e))?;
        let mut dec =
            laz::LasZipDecompressor::new(r, vlr).map_err(|e| invalid(src, format!("LAZ: {e}")))?;
        stream(&header, c.points, &mut out, src, |buf| {
            dec.decompress_many(buf)
        })?;
    } else {
        r.seek(SeekFrom::Start(c.offset_to_points))
            .map_err(|e| read_err(src, e))?;
        stream(&header, c.points, &mut out, src, |buf| r.read_exact(buf))?;
    }
    Ok(out.finish(crs))
}

/// Decodes `points` records, [`CHUNK_POINTS`] at a time, with `fill` writing each chunk's raw
/// records into the buffer. A panic in `fill` (the LAZ decoder on corrupt data) becomes an error.
fn stream(
    header: &las::Header,
    points: u64,
    out: &mut Columns,
    src: &Path,
    mut fill: impl FnMut(&mut [u8]) -> std::io::Result<()>,
) -> Result<(), IoError> {
    let mut pd = PointDataBuilder::new().for_header(header).build();
    let mut done = 0u64;
    while done < points {
        let n = (points - done).min(CHUNK_POINTS as u64) as usize;
        let buf = pd.resize_for(n);
        let filled = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| fill(buf)));
        match filled {
            Ok(Ok(())) => {}
            Ok(Err(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                return Err(IoError::Truncated {
                    path: src.to_path_buf(),
                    format: FORMAT,
                    what: format!(
                        "header declares {points} points; data ends within points {done}..{}",
                        done + n as u64
                    ),
                    expected: points,
                    found: done,
                });
            }
            Ok(Err(e)) => {
                return Err(invalid(
                    src,
                    format!("point data unreadable near point {done}: {e}"),
                ));
            }
            Err(_) => {
                return Err(invalid(
                    src,
                    format!("corrupt compressed point data near point {done}"),
                ));
            }
        }
        out.push(&pd);
        done += n as u64;
    }
    Ok(())
}

/// Point columns as read: coordinates in f64, raw 16-bit RGB and intensity.
struct Columns {
    points: Vec<[f64; 3]>,
    rgb: Option<Vec<[u16; 3]>>,
    intensity: Vec<u16>,
}

impl Columns {
    fn with_capacity(n: usize, color: bool) -> Self {
        Columns {
            points: Vec::with_capacity(n),
            rgb: color.then(|| Vec::with_capacity(n)),
            intensity: Vec::with_capacity(n),
        }
    }

    fn push(&mut self, pd: &las::PointData) {
        let xyz = pd.x().zip(pd.y()).zip(pd.z());
        self.points.extend(xyz.map(|((x, y), z)| [x, y, z]));
        self.intensity.extend(pd.intensity());
        if let (Some(rgb), Some(cols)) = (self.rgb.as_mut(), pd.rgb()) {
            rgb.extend(cols.map(|(r, g, b)| [r, g, b]));
        }
    }

    /// Scales RGB and intensity to [0, 1] (see [`unit_scale`]); all-zero columns are dropped as
    /// absent (formats whose writers leave them empty).
    fn finish(self, crs: Option<String>) -> PointCloud {
        let colors = self.rgb.and_then(|rgb| {
            let max = rgb.iter().flatten().copied().max().unwrap_or(0);
            let full = color_full_scale(max)?;
            Some(rgb.iter().map(|c| c.map(|v| f32::from(v) / full)).collect())
        });
        let max = self.intensity.iter().copied().max().unwrap_or(0);
        let intensity = (max > 0).then(|| {
            let full = f32::from(max);
            self.intensity
                .iter()
                .map(|&v| f32::from(v) / full)
                .collect()
        });
        PointCloud {
            points: self.points,
            normals: None,
            colors,
            intensity,
            crs,
        }
    }
}

/// Full-scale value of a colour column whose largest value is `max`: 16-bit colour as the LAS
/// specification asks (65535), but many writers store 8-bit values in the 16-bit fields, so a
/// column that never exceeds 255 is read as 8-bit (255). `None` when all values are 0.
fn color_full_scale(max: u16) -> Option<f32> {
    match max {
        0 => None,
        1..=255 => Some(255.0),
        _ => Some(65535.0),
    }
}

/// The CRS of a LAS header: the OGC WKT VLR verbatim, else `EPSG:<projected or geodetic code>`
/// (plus `+<vertical code>`) from the GeoTIFF GeoKey directory.
fn crs_of(h: &las::Header) -> Option<String> {
    if let Some(w) = h.get_wkt_crs_bytes() {
        let text = String::from_utf8_lossy(w);
        let text = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
        if !text.is_empty() {
            return Some(text.to_string());
        }
    }
    let keys = h.get_geotiff_crs().ok().flatten()?;
    let epsg = |k: Option<u16>| k.filter(|c| (1024..=32766).contains(c));
    let horizontal = epsg(keys.get_projected_crs_geo_key_value())
        .or_else(|| epsg(keys.get_geodetic_crs_geo_key_value()))?;
    let mut crs = format!("EPSG:{horizontal}");
    if let Some(v) = epsg(keys.get_vertical_crs_geo_key_value()) {
        crs.push_str(&format!("+{v}"));
    }
    Some(crs)
}

/// The point records of an uncompressed LAS file, for reading them by byte ranges
/// ([`crate::io::split`]): record `k` starts at `body_start + k · record_bytes`.
#[derive(Debug, Clone)]
pub(crate) struct LasRecords {
    /// Byte offset of record 0.
    pub body_start: u64,
    /// Bytes per record.
    pub record_bytes: usize,
    /// Records the header declares.
    pub count: u64,
    header: las::Header,
}

impl LasRecords {
    /// Decodes whole records `raw` (a multiple of `record_bytes`) into `out`, with the
    /// whole-file reader's arithmetic (`raw · scale + offset`).
    pub(crate) fn decode(&self, raw: &[u8], out: &mut Vec<[f64; 3]>) {
        let n = raw.len() / self.record_bytes.max(1);
        let mut pd = PointDataBuilder::new().for_header(&self.header).build();
        pd.resize_for(n)
            .copy_from_slice(&raw[..n * self.record_bytes]);
        let xyz = pd.x().zip(pd.y()).zip(pd.z());
        out.extend(xyz.map(|((x, y), z)| [x, y, z]));
    }
}

/// The records of the LAS stream `r` (`len` bytes) when they can be read by byte ranges (`None`
/// for LAZ, whose records are compressed in chunks). Refuses what the whole-file reader refuses
/// before its body: the point limit, a truncated body, no points.
pub(crate) fn fixed_records<R: Read + Seek>(
    mut r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
) -> Result<Option<LasRecords>, IoError> {
    let c = precheck(&mut r, len, src)?;
    if c.compressed {
        return Ok(None);
    }
    if c.points > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: c.points,
            limit: limits.max_points,
        });
    }
    check_body(&c, len, src)?;
    if c.points == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "LAS header declares 0 points".into(),
        });
    }
    r.seek(SeekFrom::Start(0)).map_err(|e| read_err(src, e))?;
    let header = las::Header::new(&mut r).map_err(|e| invalid(src, e.to_string()))?;
    Ok(Some(LasRecords {
        body_start: c.offset_to_points,
        record_bytes: c.record_len as usize,
        count: c.points,
        header,
    }))
}
