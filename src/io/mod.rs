//! Stage `io`: point-cloud readers (PLY, XYZ/PTS/CSV text, OBJ vertices, LAS/LAZ, E57) and mesh
//! readers/writers (OFF, PLY, OBJ, GLB = binary glTF 2.0).
//!
//! Readers do not clean: non-finite coordinates are passed through for the `clean` stage to drop and
//! count. Every reader is linear in the file size, bounded by [`ReadLimits`] (checked before any
//! allocation proportional to a declared count). [`read_point_cloud`] streams PLY and text files
//! (memory: the points plus a 64 KiB chunk, never the whole file); [`peek_point_count`] reads only
//! a header or the first 64 KiB, to refuse inputs that cannot fit before reading them. Writers are atomic ([`write_atomic`]): a temporary
//! file in the destination directory is renamed over the target only once complete.
//!
//! References: Turk, "The PLY polygon file format" (1994); Khronos glTF 2.0 specification (2021);
//! Wavefront OBJ and Geomview OFF format descriptions.

mod budget;
mod e57;
mod error;
mod glb;
mod glb_anim;
mod las;
mod obj;
mod off;
mod ply;
mod snap;
pub(crate) mod split;
mod stream;
mod text;
mod write;

#[cfg(test)]
mod fuzz_tests;

use std::io::{BufRead, BufReader, Read};
use std::path::Path;

pub use budget::{PointCountHint, peek_point_count, reader_peak_mib};
pub use error::IoError;
pub use glb::{
    GlbCompression, GlbOptions, decode_glb, encode_glb, encode_glb_with, glb_asset_extra, glb_crs,
};
pub use glb_anim::encode_animated_glb;
pub use stream::{PointChunk, PointChunks, StreamInput, stream_points};
pub use write::{lod_path, write_atomic, write_mesh, write_mesh_with, write_points_ply};

use crate::geometry::{PointCloud, TriMesh};

/// Point-cloud file formats understood by [`read_point_cloud`] / [`parse_point_cloud`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PointFormat {
    /// Stanford PLY, ASCII or binary (either endianness); the `vertex` element.
    Ply,
    /// Whitespace/comma separated text, `.xyz` or `.txt`.
    Xyz,
    /// Leica-style `.pts`: optional point-count first line, then text rows.
    Pts,
    /// Comma/semicolon separated text, usually with a header row of column names.
    Csv,
    /// Wavefront OBJ: the `v` (and matching `vn`) lines.
    Obj,
    /// ASPRS LAS 1.0–1.4, uncompressed or LAZ (LASzip) compressed, any point format 0–10.
    Las,
    /// ASTM E2807 E57: every scan of the file, each moved by its pose.
    E57,
}

impl PointFormat {
    /// Format implied by the file extension (case-insensitive), or `None` if unknown.
    /// `.txt` is read as XYZ.
    pub fn from_path(path: &Path) -> Option<PointFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "ply" => Some(PointFormat::Ply),
            "xyz" | "txt" => Some(PointFormat::Xyz),
            "pts" => Some(PointFormat::Pts),
            "csv" => Some(PointFormat::Csv),
            "obj" => Some(PointFormat::Obj),
            "las" | "laz" => Some(PointFormat::Las),
            "e57" => Some(PointFormat::E57),
            _ => None,
        }
    }

    /// Format recognised from the first bytes: `ply` magic → PLY; `LASF` → LAS/LAZ; `ASTM-E57` →
    /// E57; text whose first data line starts with `v ` → OBJ; other text → XYZ (the text reader
    /// also handles CSV and PTS). Other binary → `None`.
    pub fn sniff(bytes: &[u8]) -> Option<PointFormat> {
        if is_ply_magic(bytes) {
            return Some(PointFormat::Ply);
        }
        if let Some(f) = binary_magic(bytes) {
            return Some(f);
        }
        if !looks_like_text(bytes) {
            return None;
        }
        let first_data = bytes
            .split(|&b| b == b'\n')
            .map(|l| l.trim_ascii())
            .find(|l| !l.is_empty() && !l.starts_with(b"#"));
        match first_data {
            Some(l) if l.starts_with(b"v ") || l.starts_with(b"vn ") || l.starts_with(b"o ") => {
                Some(PointFormat::Obj)
            }
            _ => Some(PointFormat::Xyz),
        }
    }

    /// Human-readable name used in error messages.
    pub fn name(self) -> &'static str {
        match self {
            PointFormat::Ply => "PLY",
            PointFormat::Xyz => "XYZ",
            PointFormat::Pts => "PTS",
            PointFormat::Csv => "CSV",
            PointFormat::Obj => "OBJ",
            PointFormat::Las => "LAS",
            PointFormat::E57 => "E57",
        }
    }
}

/// Mesh output formats of [`write_mesh`] (reading also accepts OFF, see [`read_mesh`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Binary glTF 2.0 (`.glb`): positions, normals, indices (compact by default, see
    /// [`GlbOptions`]).
    Glb(GlbOptions),
    /// Binary little-endian PLY (`.ply`).
    Ply,
    /// Wavefront OBJ text (`.obj`).
    Obj,
}

impl MeshFormat {
    /// Output format from the extension of `path` (`.glb`, `.ply`, `.obj`, case-insensitive); GLB
    /// with the default [`GlbOptions`].
    pub fn from_path(path: &Path) -> Result<MeshFormat, IoError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("glb") => Ok(MeshFormat::Glb(GlbOptions::default())),
            Some("ply") => Ok(MeshFormat::Ply),
            Some("obj") => Ok(MeshFormat::Obj),
            other => Err(IoError::UnknownFormat {
                path: path.to_path_buf(),
                detail: format!(
                    "extension {:?} is not a mesh output format (.glb, .ply, .obj)",
                    other.unwrap_or("")
                ),
            }),
        }
    }

    /// `self` with these GLB options when it is GLB (other formats unchanged).
    pub fn with_glb(self, options: GlbOptions) -> MeshFormat {
        match self {
            MeshFormat::Glb(_) => MeshFormat::Glb(options),
            other => other,
        }
    }
}

/// What a written mesh records besides its geometry and colours.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MeshMeta {
    /// Coordinate reference system of the vertices, passed on verbatim from the input (see
    /// [`crate::geometry::PointCloud::crs`]).
    pub crs: Option<String>,
}

/// Resource limits for readers; checked before allocating anything proportional to a declared size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimits {
    /// Maximum number of points (or mesh vertices) accepted. Default 50,000,000.
    pub max_points: usize,
    /// Maximum file size in bytes. Default 4 GiB.
    pub max_bytes: u64,
    /// Memory budget of the point-cloud reader itself, MiB (see [`reader_peak_mib`]): inputs
    /// whose points (and normals) would need more are refused before allocating. Default 8192.
    pub max_memory_mib: u64,
}

impl Default for ReadLimits {
    fn default() -> Self {
        ReadLimits {
            max_points: 50_000_000,
            max_bytes: 4 << 30,
            max_memory_mib: 8192,
        }
    }
}

/// Name used in error messages for in-memory data.
pub(crate) const MEMORY_SOURCE: &str = "<input>";

/// Reads a point cloud from `path` (any path, UTF-8 or not).
///
/// The format comes from content sniffing (a file starting with `ply` is PLY whatever its name)
/// then the extension (see [`PointFormat::from_path`]), then text sniffing. Returns `n` points
/// (and optionally `n` normals) in the file's own units; nothing is cleaned or rescaled.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let p = dir.path().join("tri.xyz");
/// std::fs::write(&p, "0 0 0\n1 0 0\n0 1 0\n").unwrap();
/// let pc = rbfsurf::io::read_point_cloud(&p, &Default::default()).unwrap();
/// assert_eq!(pc.points.len(), 3);
/// ```
pub fn read_point_cloud(path: &Path, limits: &ReadLimits) -> Result<PointCloud, IoError> {
    let (mut r, len, format) = open_point_file(path, limits)?;
    let pc = match format {
        PointFormat::Ply => ply::read_ply_points(r, len, limits, path, ply::CHUNK_BYTES)?,
        PointFormat::Xyz | PointFormat::Pts | PointFormat::Csv => {
            text::read_text_points(r, len, format, limits, path)?
        }
        PointFormat::Las | PointFormat::E57 => {
            // These readers seek (header, chunk table, binary sections): a fresh buffered file.
            drop(r);
            let (file, _) = open_limited(path, limits.max_bytes)?;
            let seekable = BufReader::with_capacity(budget::READ_BUFFER_BYTES, file);
            if format == PointFormat::Las {
                las::read_las_points(seekable, len, limits, path)?
            } else {
                e57::read_e57_points(seekable, len, limits, path)?
            }
        }
        PointFormat::Obj => {
            let mut bytes = Vec::with_capacity(len as usize);
            r.read_to_end(&mut bytes).map_err(|source| IoError::Read {
                path: path.to_path_buf(),
                source,
            })?;
            obj::read_obj_points(&bytes, limits, path)?
        }
    };
    non_empty(pc, format, path)
}

/// A buffered reader over the point file `path`, its size in bytes and its format; refuses
/// (before reading the body) files over `limits.max_bytes`, empty files and unknown formats.
fn open_point_file(
    path: &Path,
    limits: &ReadLimits,
) -> Result<(BufReader<std::io::Take<std::fs::File>>, u64, PointFormat), IoError> {
    let (file, len) = open_limited(path, limits.max_bytes)?;
    // `take` guards against files that grow while being read.
    let mut r = BufReader::with_capacity(budget::READ_BUFFER_BYTES, file.take(len));
    let head = r.fill_buf().map_err(|source| IoError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let format = detect_point_format(path, head)?;
    if head.len() as u64 >= len && head.trim_ascii().is_empty() {
        return Err(IoError::Empty {
            path: path.to_path_buf(),
            what: "file is empty".into(),
        });
    }
    Ok((r, len, format))
}

/// Refuses in-memory point data over `limits.max_bytes` or without any content.
fn check_bytes(bytes: &[u8], limits: &ReadLimits, src: &Path) -> Result<(), IoError> {
    let len = bytes.len() as u64;
    if len > limits.max_bytes {
        return Err(IoError::TooLarge {
            path: src.to_path_buf(),
            bytes: len,
            limit: limits.max_bytes,
        });
    }
    if bytes.trim_ascii().is_empty() {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "file is empty".into(),
        });
    }
    Ok(())
}

/// Parses an in-memory point cloud of a known format (errors name the source `<input>`).
/// The same streaming readers as [`read_point_cloud`] run over the slice.
///
/// ```
/// use rbfsurf::io::{parse_point_cloud, PointFormat};
/// let pc = parse_point_cloud(b"x,y,z\n1,2,3\n", PointFormat::Csv, &Default::default()).unwrap();
/// assert_eq!(pc.points, vec![[1.0, 2.0, 3.0]]);
/// ```
pub fn parse_point_cloud(
    bytes: &[u8],
    format: PointFormat,
    limits: &ReadLimits,
) -> Result<PointCloud, IoError> {
    parse_point_cloud_named(bytes, format, limits, Path::new(MEMORY_SOURCE))
}

fn parse_point_cloud_named(
    bytes: &[u8],
    format: PointFormat,
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    check_bytes(bytes, limits, src)?;
    let len = bytes.len() as u64;
    let pc = match format {
        PointFormat::Ply => ply::read_ply_points(bytes, len, limits, src, ply::CHUNK_BYTES)?,
        PointFormat::Xyz | PointFormat::Pts | PointFormat::Csv => {
            text::read_text_points(bytes, len, format, limits, src)?
        }
        PointFormat::Obj => obj::read_obj_points(bytes, limits, src)?,
        PointFormat::Las => las::read_las_points(std::io::Cursor::new(bytes), len, limits, src)?,
        PointFormat::E57 => e57::read_e57_points(std::io::Cursor::new(bytes), len, limits, src)?,
    };
    non_empty(pc, format, src)
}

/// `Empty` when a reader found no points at all.
fn non_empty(pc: PointCloud, format: PointFormat, src: &Path) -> Result<PointCloud, IoError> {
    if pc.points.is_empty() {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: format!("no points found in the {} data", format.name()),
        });
    }
    Ok(pc)
}

/// Reads a triangle mesh: OFF, PLY (`vertex` + `face`), OBJ (`v` + `f`) or GLB, by content
/// (magic bytes) then extension. Polygons are triangulated as fans; indices are validated.
/// Uses [`ReadLimits::default`] for the vertex count and file size.
pub fn read_mesh(path: &Path) -> Result<TriMesh, IoError> {
    let limits = ReadLimits::default();
    let bytes = read_limited(path, limits.max_bytes)?;
    if bytes.trim_ascii().is_empty() {
        return Err(IoError::Empty {
            path: path.to_path_buf(),
            what: "file is empty".into(),
        });
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let head = bytes.trim_ascii_start();
    if bytes.starts_with(b"glTF") || ext.as_deref() == Some("glb") {
        glb::decode_glb_named(&bytes, path)
    } else if is_ply_magic(&bytes) || ext.as_deref() == Some("ply") {
        ply::read_ply_mesh(&bytes, &limits, path)
    } else if ext.as_deref() == Some("off") || head.starts_with(b"OFF") || head.starts_with(b"NOFF")
    {
        off::read_off(&bytes, &limits, path)
    } else if ext.as_deref() == Some("obj") || PointFormat::sniff(&bytes) == Some(PointFormat::Obj)
    {
        obj::read_obj_mesh(&bytes, &limits, path)
    } else {
        Err(IoError::UnknownFormat {
            path: path.to_path_buf(),
            detail: "not OFF, PLY, OBJ or GLB by extension or content".into(),
        })
    }
}

/// Opens `path` and returns it with its size in bytes; refuses files larger than `max_bytes` and
/// empty files before reading anything.
fn open_limited(path: &Path, max_bytes: u64) -> Result<(std::fs::File, u64), IoError> {
    let file = std::fs::File::open(path).map_err(|source| IoError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    let len = file
        .metadata()
        .map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?
        .len();
    if len > max_bytes {
        return Err(IoError::TooLarge {
            path: path.to_path_buf(),
            bytes: len,
            limit: max_bytes,
        });
    }
    if len == 0 {
        return Err(IoError::Empty {
            path: path.to_path_buf(),
            what: "file is empty (0 bytes)".into(),
        });
    }
    Ok((file, len))
}

/// Reads the whole file, refusing (before reading) files larger than `max_bytes`.
fn read_limited(path: &Path, max_bytes: u64) -> Result<Vec<u8>, IoError> {
    let (file, len) = open_limited(path, max_bytes)?;
    let mut bytes = Vec::with_capacity(len as usize);
    // `take` guards against files that grow while being read (or report a wrong size).
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
    if bytes.len() as u64 > max_bytes {
        return Err(IoError::TooLarge {
            path: path.to_path_buf(),
            bytes: bytes.len() as u64,
            limit: max_bytes,
        });
    }
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: path.to_path_buf(),
            what: "file is empty (0 bytes)".into(),
        });
    }
    Ok(bytes)
}

/// Point format of a file: PLY, LAS or E57 magic wins, then the extension, then text sniffing.
fn detect_point_format(path: &Path, bytes: &[u8]) -> Result<PointFormat, IoError> {
    if is_ply_magic(bytes) {
        return Ok(PointFormat::Ply);
    }
    if let Some(f) = binary_magic(bytes) {
        return Ok(f);
    }
    if let Some(f) = PointFormat::from_path(path) {
        return Ok(f);
    }
    PointFormat::sniff(bytes).ok_or_else(|| IoError::UnknownFormat {
        path: path.to_path_buf(),
        detail: "unknown extension and the content is binary, not text".into(),
    })
}

/// LAS/LAZ (`LASF`) or E57 (`ASTM-E57`) by their file signatures.
fn binary_magic(bytes: &[u8]) -> Option<PointFormat> {
    if bytes.starts_with(las::MAGIC) {
        Some(PointFormat::Las)
    } else if bytes.starts_with(e57::MAGIC) {
        Some(PointFormat::E57)
    } else {
        None
    }
}

/// `ply` followed by a line end.
fn is_ply_magic(bytes: &[u8]) -> bool {
    bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") || bytes.starts_with(b"ply\r")
}

/// True when the first 4 KiB hold no NUL and almost only printable ASCII / UTF-8 text.
fn looks_like_text(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(4096)];
    if head.contains(&0) {
        return false;
    }
    let odd = head
        .iter()
        .filter(|&&b| b < 0x20 && !matches!(b, b'\n' | b'\r' | b'\t' | 0x0c))
        .count();
    let text = match std::str::from_utf8(head) {
        Ok(_) => true,
        // A multi-byte character may be cut at the 4 KiB boundary.
        Err(e) => e.valid_up_to() + 4 >= head.len(),
    };
    text && odd * 100 <= head.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extension_and_sniffing() {
        assert_eq!(
            PointFormat::from_path(Path::new("a.PLY")),
            Some(PointFormat::Ply)
        );
        assert_eq!(
            PointFormat::from_path(Path::new("a.txt")),
            Some(PointFormat::Xyz)
        );
        assert_eq!(PointFormat::from_path(Path::new("a.bin")), None);
        assert_eq!(
            PointFormat::sniff(b"ply\nformat ascii 1.0\n"),
            Some(PointFormat::Ply)
        );
        assert_eq!(
            PointFormat::sniff(b"# c\nv 1 2 3\n"),
            Some(PointFormat::Obj)
        );
        assert_eq!(PointFormat::sniff(b"1 2 3\n"), Some(PointFormat::Xyz));
        assert_eq!(PointFormat::sniff(&[0u8, 1, 2, 200, 7]), None);
        assert_eq!(
            MeshFormat::from_path(Path::new("m.GLB")).unwrap(),
            MeshFormat::Glb(GlbOptions::default())
        );
        assert!(matches!(
            MeshFormat::from_path(Path::new("m.stl")),
            Err(IoError::UnknownFormat { .. })
        ));
    }

    #[test]
    fn ply_content_wins_over_extension() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cloud.xyz");
        std::fs::write(&p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n").unwrap();
        let pc = read_point_cloud(&p, &ReadLimits::default()).unwrap();
        assert_eq!(pc.points, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn file_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let empty = dir.path().join("empty.ply");
        std::fs::write(&empty, b"").unwrap();
        let e = read_point_cloud(&empty, &ReadLimits::default()).unwrap_err();
        assert!(matches!(e, IoError::Empty { .. }), "{e}");
        assert!(e.to_string().contains("empty.ply"), "{e}");

        let missing = dir.path().join("nope.xyz");
        let e = read_point_cloud(&missing, &ReadLimits::default()).unwrap_err();
        assert!(matches!(e, IoError::Open { .. }), "{e}");

        let garbage = dir.path().join("noise.dat");
        std::fs::write(&garbage, [0u8, 159, 146, 150, 1, 2, 3, 0, 255]).unwrap();
        let e = read_point_cloud(&garbage, &ReadLimits::default()).unwrap_err();
        assert!(matches!(e, IoError::UnknownFormat { .. }), "{e}");

        let big = dir.path().join("big.xyz");
        std::fs::write(&big, "1 2 3\n".repeat(100)).unwrap();
        let small = ReadLimits {
            max_points: 10,
            max_bytes: 64,
            ..ReadLimits::default()
        };
        let e = read_point_cloud(&big, &small).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::TooLarge {
                    bytes: 600,
                    limit: 64,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[cfg(unix)]
    #[test]
    fn non_utf8_path_is_readable() {
        use std::os::unix::ffi::OsStrExt;
        let dir = tempfile::tempdir().unwrap();
        let name = std::ffi::OsStr::from_bytes(b"caf\xe9.xyz");
        let p = dir.path().join(name);
        std::fs::write(&p, "1 2 3\n4 5 6\n").unwrap();
        let pc = read_point_cloud(&p, &ReadLimits::default()).unwrap();
        assert_eq!(pc.points.len(), 2);
        std::fs::write(&p, "1 2 zz\n").unwrap();
        let e = read_point_cloud(&p, &ReadLimits::default()).unwrap_err();
        assert!(e.to_string().contains("caf"), "{e}");
    }

    #[test]
    fn the_shipped_data_files_read_with_their_documented_counts() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
        let pc = read_point_cloud(&data.join("kitten.ply"), &ReadLimits::default()).unwrap();
        assert_eq!(pc.points.len(), 5210);
        assert_eq!(pc.normals.as_ref().map(Vec::len), Some(5210));
        let m = read_mesh(&data.join("bunny00.off")).unwrap();
        assert_eq!((m.vertices.len(), m.triangles.len()), (37706, 75408));
    }
}
