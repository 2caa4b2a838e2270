//! Mesh writers (GLB, binary little-endian PLY, OBJ) and the atomic file write they share:
//! the bytes go to a temporary file in the destination directory, are flushed to disk, and the
//! temporary file is renamed over the destination. On any error nothing is left at the destination
//! and an existing file there is untouched. Time and memory O(mesh size).
//!
//! References: G. Turk, "The PLY Polygon File Format" (1994); Wavefront OBJ format description.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use super::glb::{check_mesh, encode_glb_with, origin_for, unit_normals};
use super::{IoError, MeshFormat, MeshMeta};
use crate::geometry::TriMesh;

/// Writes `bytes` to `path` atomically: temporary file in the same directory, `fsync`, rename.
///
/// A missing directory or any I/O failure gives [`IoError::Write`]; the temporary file is removed
/// and a file already at `path` keeps its old content. The new file gets mode 0644 on Unix.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let p = dir.path().join("out.bin");
/// rbfsurf::io::write_atomic(&p, b"abc").unwrap();
/// assert_eq!(std::fs::read(&p).unwrap(), b"abc");
/// ```
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let werr = |source: std::io::Error| IoError::Write {
        path: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".rbfsurf-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(werr)?;
    tmp.write_all(bytes).map_err(werr)?;
    tmp.flush().map_err(werr)?;
    tmp.as_file().sync_all().map_err(werr)?;
    tmp.persist(path).map_err(|e| werr(e.error))?;
    Ok(())
}

/// Writes `mesh` to `path` in `format` (see [`MeshFormat`]), atomically via [`write_atomic`].
///
/// GLB: see [`encode_glb_with`]. PLY: binary little-endian, `float x y z [nx ny nz]` (vertices that round
/// to one f32 position merged, as for GLB),
/// `list uchar int vertex_indices`. OBJ: `v`, `vn`, `f a//a b//b c//c` (1-based), full f64 precision.
///
/// ```
/// use rbfsurf::{geometry::TriMesh, io::{read_mesh, write_mesh, MeshFormat}};
/// let mesh = TriMesh { vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///                      normals: vec![], triangles: vec![[0, 1, 2]], colors: vec![] };
/// let dir = tempfile::tempdir().unwrap();
/// let p = dir.path().join("tri.ply");
/// write_mesh(&p, &mesh, MeshFormat::Ply).unwrap();
/// assert_eq!(read_mesh(&p).unwrap().triangles, mesh.triangles);
/// ```
pub fn write_mesh(path: &Path, mesh: &TriMesh, format: MeshFormat) -> Result<(), IoError> {
    write_mesh_with(path, mesh, format, &MeshMeta::default())
}

/// [`write_mesh`] with metadata: the CRS goes to GLB `asset.extras.crs`, a PLY `comment crs`
/// line and an OBJ `# crs` comment. Vertex colours: GLB `COLOR_0` (linear), PLY `uchar red green
/// blue` (sRGB, as stored); OBJ has none.
pub fn write_mesh_with(
    path: &Path,
    mesh: &TriMesh,
    format: MeshFormat,
    meta: &MeshMeta,
) -> Result<(), IoError> {
    let bytes = match format {
        MeshFormat::Glb(o) => encode_glb_with(mesh, meta, o.compression)?,
        MeshFormat::Ply => encode_ply(mesh, meta)?,
        MeshFormat::Obj => encode_obj(mesh, meta)?,
    };
    write_atomic(path, &bytes)?;
    match format {
        MeshFormat::Glb(o) if o.lods > 0 => write_lods(path, mesh, meta, o).inspect_err(|_| {
            let _ = std::fs::remove_file(path);
        }),
        _ => Ok(()),
    }
}

/// `NAME.lodK.glb` next to `path` (`NAME.glb`), for K = 1, 2, …
pub fn lod_path(path: &Path, k: usize) -> std::path::PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(Default::default, |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}.lod{k}.glb"))
}

/// Writes `o.lods` simplified levels of `mesh` next to `path` ([`lod_path`]), each GLB recording
/// its level, triangle count and simplification error in `asset.extras.lod`. On failure the
/// levels already written are removed.
fn write_lods(
    path: &Path,
    mesh: &TriMesh,
    meta: &MeshMeta,
    o: super::GlbOptions,
) -> Result<(), IoError> {
    let mut written = Vec::new();
    let result = (|| {
        for (k, lod) in crate::mesh::lod::simplify_levels(mesh, o.lods)
            .iter()
            .enumerate()
        {
            let info = serde_json::json!({
                "level": k + 1,
                "triangles": lod.mesh.triangles.len(),
                "error": lod.error,
                "error_rel": lod.error_rel,
            });
            let bytes = encode_glb_with(&lod.mesh, meta, o.compression)?;
            let bytes = super::glb::with_asset_extra(&bytes, "lod", info)?;
            let p = lod_path(path, k + 1);
            write_atomic(&p, &bytes)?;
            written.push(p);
        }
        Ok(())
    })();
    if result.is_err() {
        for p in &written {
            let _ = std::fs::remove_file(p);
        }
    }
    result
}

/// `crs` on one line (WKT may span lines), for a comment.
fn one_line(crs: &str) -> String {
    crs.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Writes a point cloud as binary little-endian PLY (`double x y z`, `float nx ny nz` when present),
/// atomically. Doubles keep coordinates far from the origin (e.g. 1e6) exact.
pub fn write_points_ply(path: &Path, cloud: &crate::geometry::PointCloud) -> Result<(), IoError> {
    let normals = cloud
        .normals
        .as_ref()
        .filter(|n| n.len() == cloud.points.len());
    let mut out =
        String::from("ply\nformat binary_little_endian 1.0\ncomment generated by rbfsurf\n");
    let _ = writeln!(out, "element vertex {}", cloud.points.len());
    out.push_str("property double x\nproperty double y\nproperty double z\n");
    if normals.is_some() {
        out.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    out.push_str("end_header\n");
    let mut bytes = out.into_bytes();
    bytes.reserve(cloud.points.len() * 36);
    for (i, p) in cloud.points.iter().enumerate() {
        bytes.extend(p.iter().flat_map(|c| c.to_le_bytes()));
        if let Some(n) = normals {
            bytes.extend(n[i].iter().flat_map(|&c| (c as f32).to_le_bytes()));
        }
    }
    write_atomic(path, &bytes)
}

/// Binary little-endian PLY bytes of `mesh`: f32 coordinates (vertices that round to one f32
/// position merged, see [`super::snap`]), or f64 coordinates for a mesh far from the origin (the
/// GLB node-translation criterion: bbox centre farther than its extent), so UTM-size coordinates
/// stay exact; unit f32 normals and `uchar red green blue` colours when present; the CRS as a
/// `comment crs` line.
pub(crate) fn encode_ply(mesh: &TriMesh, meta: &MeshMeta) -> Result<Vec<u8>, IoError> {
    check_mesh(mesh, "PLY")?;
    let double = origin_for(mesh).is_some();
    // f32 coordinates: vertices that round to one position are merged first (as for GLB).
    let merged = if double {
        std::borrow::Cow::Borrowed(mesh)
    } else {
        super::snap::merge_f32_duplicates(mesh)
    };
    let mesh: &TriMesh = &merged;
    check_mesh(mesh, "PLY")?;
    let normals = unit_normals(mesh);
    let mut head =
        String::from("ply\nformat binary_little_endian 1.0\ncomment generated by rbfsurf\n");
    if let Some(crs) = &meta.crs {
        let _ = writeln!(head, "comment crs {}", one_line(crs));
    }
    let _ = writeln!(head, "element vertex {}", mesh.vertices.len());
    let ty = if double { "double" } else { "float" };
    for axis in ["x", "y", "z"] {
        let _ = writeln!(head, "property {ty} {axis}");
    }
    if !normals.is_empty() {
        head.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if !mesh.colors.is_empty() {
        head.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    let _ = writeln!(head, "element face {}", mesh.triangles.len());
    head.push_str("property list uchar int vertex_indices\nend_header\n");
    let coords = if double { 24 } else { 12 };
    let per_vertex = coords + if normals.is_empty() { 0 } else { 12 } + 3;
    let mut out = Vec::with_capacity(
        head.len() + mesh.vertices.len() * per_vertex + mesh.triangles.len() * 13,
    );
    out.extend_from_slice(head.as_bytes());
    for (i, p) in mesh.vertices.iter().enumerate() {
        if double {
            out.extend(p.iter().flat_map(|&c| c.to_le_bytes()));
        } else {
            out.extend(p.iter().flat_map(|&c| (c as f32).to_le_bytes()));
        }
        if let Some(n) = normals.get(i) {
            out.extend(n.iter().flat_map(|c| c.to_le_bytes()));
        }
        if let Some(c) = mesh.colors.get(i) {
            out.extend(c.map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8));
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        // check_mesh guarantees indices < vertex count ≤ i32::MAX.
        out.extend(t.iter().flat_map(|&i| (i as i32).to_le_bytes()));
    }
    Ok(out)
}

/// OBJ text of `mesh`: a comment header, `v` (and `vn`) lines, then 1-based `f` lines.
pub(crate) fn encode_obj(mesh: &TriMesh, meta: &MeshMeta) -> Result<Vec<u8>, IoError> {
    check_mesh(mesh, "OBJ")?;
    let normals = unit_normals(mesh);
    let mut s = String::with_capacity(mesh.vertices.len() * 60 + mesh.triangles.len() * 30);
    let _ = writeln!(
        s,
        "# rbfsurf mesh: {} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    if let Some(crs) = &meta.crs {
        let _ = writeln!(s, "# crs {}", one_line(crs));
    }
    for p in &mesh.vertices {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    for n in &normals {
        let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| u64::from(i) + 1);
        if normals.is_empty() {
            let _ = writeln!(s, "f {a} {b} {c}");
        } else {
            let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
        }
    }
    Ok(s.into_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::glb::tests::octahedron;
    use crate::io::{GlbCompression, GlbOptions, read_mesh};

    const PLAIN_GLB: MeshFormat = MeshFormat::Glb(GlbOptions::compressed(GlbCompression::None));

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".rbfsurf-"))
            .collect()
    }

    #[test]
    fn every_format_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let m = octahedron();
        for (name, fmt) in [
            ("m.glb", PLAIN_GLB),
            ("m.ply", MeshFormat::Ply),
            ("m.obj", MeshFormat::Obj),
        ] {
            for with_normals in [true, false] {
                let mut src = m.clone();
                if !with_normals {
                    src.normals.clear();
                }
                let p = dir.path().join(name);
                write_mesh(&p, &src, fmt).unwrap();
                let default = fmt.with_glb(GlbOptions::default());
                assert_eq!(MeshFormat::from_path(&p).unwrap(), default);
                let back = read_mesh(&p).unwrap();
                assert_eq!(back.triangles, src.triangles, "{name}");
                for (a, b) in back.vertices.iter().zip(&src.vertices) {
                    assert!(
                        (0..3).all(|k| (a[k] - b[k]).abs() < 1e-7),
                        "{name}: {a:?} {b:?}"
                    );
                }
                assert_eq!(back.normals.len(), src.normals.len(), "{name}");
                for (n, p) in back.normals.iter().zip(&src.vertices) {
                    let want = crate::geometry::normalized(*p).unwrap();
                    assert!(
                        (0..3).all(|k| (n[k] - want[k]).abs() < 1e-6),
                        "{name}: {n:?}"
                    );
                }
            }
        }
        assert!(leftovers(dir.path()).is_empty());
    }

    #[test]
    fn missing_directory_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("no/such/dir/out.glb");
        let e = write_mesh(&p, &octahedron(), PLAIN_GLB).unwrap_err();
        assert!(matches!(e, IoError::Write { .. }), "{e}");
        assert!(e.to_string().contains("out.glb"), "{e}");
        assert!(!p.exists());
        assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
    }

    #[test]
    fn failures_do_not_clobber_existing_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("keep.ply");
        std::fs::write(&p, b"old").unwrap();
        let mut bad = octahedron();
        bad.triangles[0] = [0, 1, 99];
        let compact = MeshFormat::Glb(GlbOptions::default());
        for fmt in [compact, PLAIN_GLB, MeshFormat::Ply, MeshFormat::Obj] {
            assert!(matches!(
                write_mesh(&p, &bad, fmt),
                Err(IoError::Encode { .. })
            ));
            assert_eq!(std::fs::read(&p).unwrap(), b"old");
        }
        // Rename onto a non-empty directory fails after the temp file was written: it is removed.
        let target = dir.path().join("occupied");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("inside"), b"x").unwrap();
        let e = write_atomic(&target, b"new").unwrap_err();
        assert!(matches!(e, IoError::Write { .. }), "{e}");
        assert!(target.join("inside").exists());
        assert!(
            leftovers(dir.path()).is_empty(),
            "{:?}",
            leftovers(dir.path())
        );
        write_atomic(&p, b"new").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
    }

    #[test]
    fn ply_header_is_as_documented() {
        let bytes = encode_ply(&octahedron(), &MeshMeta::default()).unwrap();
        let text = String::from_utf8_lossy(
            &bytes[..bytes
                .windows(11)
                .position(|w| w == b"end_header\n")
                .unwrap()],
        )
        .into_owned();
        assert!(text.contains("format binary_little_endian 1.0\n"));
        assert!(text.contains(
            "property float nz\nelement face 8\nproperty list uchar int vertex_indices\n"
        ));
        let obj =
            String::from_utf8(encode_obj(&octahedron(), &MeshMeta::default()).unwrap()).unwrap();
        assert!(obj.starts_with("# rbfsurf mesh: 6 vertices, 8 triangles\nv 1.5 0 0\n"));
        assert!(obj.contains("\nf 1//1 3//3 5//5\n"));
    }
}
