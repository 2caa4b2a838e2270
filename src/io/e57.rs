//! ASTM E2807 E57 reader (the `e57` crate): every scan (`data3D` entry) of the file, each moved
//! into the file's frame by its pose (rotation quaternion and translation, applied in f64),
//! Cartesian coordinates or spherical ones converted to Cartesian; colour and intensity scaled to
//! [0, 1] by the scan's colour and intensity limits (the crate's normalisation); images ignored;
//! `coordinateMetadata` passed on as the CRS.
//!
//! Before the points are read the 48-byte file header is checked against the file size (XML
//! section inside the file), then the summed record counts of all scans against
//! [`ReadLimits::max_points`] and the memory budget. The crate verifies every 1 KiB page's CRC
//! while reading, so a corrupted or truncated file is an error, not garbage points; a point with
//! no valid coordinate (invalid state, direction only) is passed on as NaN for the clean stage to
//! drop and count. A panic inside the crate on hostile data is caught and reported as invalid.
//!
//! Reference: ASTM E2807-11, "Standard Specification for 3D Imaging Data Exchange, Version 1.0".

use std::io::{BufRead, Read, Seek, SeekFrom};
use std::path::Path;

use super::budget::{CountSource, ReaderCost, check_memory};
use super::{IoError, ReadLimits};
use crate::geometry::PointCloud;

/// File signature of E57.
pub(crate) const MAGIC: &[u8; 8] = b"ASTM-E57";

const FORMAT: &str = "E57";

/// Buffers of the crate's reader: the XML section is held whole (bounded by the file size and
/// counted separately), plus paged and packet buffers, bytes.
const BUFFERS: u64 = 1 << 20;

fn invalid(src: &Path, message: impl Into<String>) -> IoError {
    IoError::Invalid {
        path: src.to_path_buf(),
        format: FORMAT,
        message: message.into(),
    }
}

/// Checks the file header against the length `len`; returns the XML section's length.
fn precheck<R: Read + Seek>(r: &mut R, len: u64, src: &Path) -> Result<u64, IoError> {
    let read_err = |source| IoError::Read {
        path: src.to_path_buf(),
        source,
    };
    r.seek(SeekFrom::Start(0)).map_err(read_err)?;
    let mut h = [0u8; 48];
    if r.read_exact(&mut h).is_err() {
        return Err(IoError::Truncated {
            path: src.to_path_buf(),
            format: FORMAT,
            what: "the file header needs 48 bytes".into(),
            expected: 48,
            found: len,
        });
    }
    let word = |i: usize| u64::from_le_bytes(h[i..i + 8].try_into().unwrap_or([0; 8]));
    let (physical, xml_offset, xml_len) = (word(16), word(24), word(32));
    if physical > len {
        return Err(IoError::Truncated {
            path: src.to_path_buf(),
            format: FORMAT,
            what: "the header's file length".into(),
            expected: physical,
            found: len,
        });
    }
    if xml_offset.checked_add(xml_len).is_none_or(|end| end > len) {
        return Err(invalid(
            src,
            format!(
                "XML section of {xml_len} bytes at byte {xml_offset} is past the end of the file"
            ),
        ));
    }
    r.seek(SeekFrom::Start(0)).map_err(read_err)?;
    Ok(xml_len)
}

/// Opens the crate's reader after [`precheck`]; crate errors become [`IoError::Invalid`].
fn open<R: Read + Seek>(mut r: R, len: u64, src: &Path) -> Result<e57::E57Reader<R>, IoError> {
    precheck(&mut r, len, src)?;
    let opened = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| e57::E57Reader::new(r)));
    match opened {
        Ok(Ok(reader)) => Ok(reader),
        Ok(Err(e)) => Err(invalid(src, e.to_string())),
        Err(_) => Err(invalid(src, "the file structure could not be parsed")),
    }
}

/// Total records declared by all scans.
fn declared_points<R: Read + Seek>(reader: &e57::E57Reader<R>) -> u64 {
    (reader.pointclouds().iter()).fold(0u64, |n, pc| n.saturating_add(pc.records))
}

/// Total points declared by the scans of an E57 stream (header and XML section only).
pub(crate) fn peek_points<R: BufRead + Seek>(
    r: &mut R,
    len: u64,
    src: &Path,
) -> Result<u64, IoError> {
    let reader = open(r, len, src)?;
    Ok(declared_points(&reader))
}

/// Reads every point of every scan of an E57 stream of `len` bytes (see the module docs).
pub(crate) fn read_e57_points<R: Read + Seek>(
    r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    let mut reader = open(r, len, src)?;
    let clouds = reader.pointclouds();
    let points = declared_points(&reader);
    if points > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: points,
            limit: limits.max_points,
        });
    }
    let cost = ReaderCost {
        per_point: 40,
        buffers: BUFFERS + reader.xml().len() as u64,
    };
    check_memory(points, cost, CountSource::Declared, limits, src)?;
    if points == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "the E57 file's scans hold 0 points".into(),
        });
    }
    let has_color = clouds.iter().any(|pc| pc.has_color());
    let has_intensity = clouds.iter().any(|pc| pc.has_intensity());
    // Pre-allocated for at most one point per byte of file: a header that lies about its count
    // fails on the data before it could make the reader allocate for points that are not there.
    let n = points.min(len) as usize;
    let mut out = PointCloud {
        points: Vec::with_capacity(n),
        colors: has_color.then(|| Vec::with_capacity(n)),
        intensity: has_intensity.then(|| Vec::with_capacity(n)),
        crs: (reader.coordinate_metadata())
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(str::to_string),
        ..Default::default()
    };
    for (scan, pc) in clouds.iter().enumerate() {
        let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            read_scan(&mut reader, pc, &mut out)
        }));
        match read {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(invalid(src, format!("scan {scan}: {e}"))),
            Err(_) => return Err(invalid(src, format!("scan {scan}: corrupt point data"))),
        }
    }
    Ok(out)
}

/// Appends one scan's points (pose applied, spherical converted) to `out`. Colour and intensity
/// columns the cloud has but this scan lacks (or a point marks invalid) are filled with 0.5.
fn read_scan<R: Read + Seek>(
    reader: &mut e57::E57Reader<R>,
    pc: &e57::PointCloud,
    out: &mut PointCloud,
) -> e57::Result<()> {
    let mut it = reader.pointcloud_simple(pc)?;
    it.apply_pose(true);
    it.spherical_to_cartesian(true);
    it.intensity_to_color(false);
    it.normalize_color(true);
    it.normalize_intensity(true);
    for p in it {
        let p = p?;
        let xyz = match p.cartesian {
            e57::CartesianCoordinate::Valid { x, y, z } => [x, y, z],
            _ => [f64::NAN; 3],
        };
        out.points.push(xyz);
        if let Some(c) = out.colors.as_mut() {
            let rgb = p.color.map_or([0.5; 3], |c| [c.red, c.green, c.blue]);
            c.push(rgb.map(|v| {
                if v.is_finite() {
                    v.clamp(0.0, 1.0)
                } else {
                    0.5
                }
            }));
        }
        if let Some(i) = out.intensity.as_mut() {
            let v = p.intensity.filter(|v| v.is_finite()).unwrap_or(0.5);
            i.push(v.clamp(0.0, 1.0));
        }
    }
    Ok(())
}
