//! Scanner formats end to end: LAS 1.0–1.4 in every point format, LAZ, E57 (several scans with
//! poses, Cartesian and spherical) read exactly; the same points in LAS, LAZ and E57 give the same
//! mesh; vertex colours match a smooth colour field on the written GLB (read back with the `gltf`
//! crate); a UTM-shifted cloud gives the same mesh shifted in the written GLB and PLY; the CRS
//! reaches the report and the files; hostile files (truncated, lying headers, absurd counts,
//! flipped bytes) are refused with an error, never a panic.

use std::path::Path;

use crate::scanner_files::{E57Coords, LasSpec, Scan, color_field, e57_bytes, las_bytes, write};
use rbfsurf::geometry::synthetic::{Shape, SplitMix64};
use rbfsurf::geometry::{Point3, PointCloud};
use rbfsurf::io::{
    GlbCompression, GlbOptions, IoError, MeshFormat, PointFormat, ReadLimits, parse_point_cloud,
    peek_point_count, read_point_cloud,
};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::{PointSource, RunOutput, run};
use rbfsurf::progress::NoProgress;

pub(crate) const UTM: Point3 = [512_345.0, 4_102_345.0, 250.0];

/// `n` points of a sphere of radius 10 m centred at `centre`, on the LAS grid, coloured.
pub(crate) fn sphere_scan(n: usize, seed: u64, centre: Point3, offset: Point3) -> Scan {
    let shape = Shape::Sphere {
        center: centre,
        radius: 10.0,
    };
    let pc = shape.sample(n, seed);
    Scan::on_grid(&pc.points, offset, centre, 10.0)
}

pub(crate) fn parse(bytes: &[u8], format: PointFormat) -> Result<PointCloud, IoError> {
    parse_point_cloud(bytes, format, &ReadLimits::default())
}

pub(crate) fn same_bits(a: &[Point3], b: &[Point3]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(p, q)| (0..3).all(|k| p[k].to_bits() == q[k].to_bits()))
}

#[test]
fn every_las_version_and_point_format_reads_exactly() {
    let scan = sphere_scan(500, 1, UTM, [UTM[0] - 20.0, UTM[1] - 20.0, 0.0]);
    let cases: [((u8, u8), &[u8]); 5] = [
        ((1, 0), &[0, 1]),
        ((1, 1), &[0, 1]),
        ((1, 2), &[0, 1, 2, 3]),
        ((1, 3), &[0, 1, 2, 3, 4, 5]),
        ((1, 4), &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10]),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (version, formats) in cases {
        for &format in formats {
            // LASzip compresses the formats without waveform packets.
            let lazs: &[bool] = if matches!(format, 4 | 5 | 9 | 10) {
                &[false]
            } else {
                &[false, true]
            };
            for &laz in lazs {
                let ctx = format!("LAS {}.{} format {format} laz {laz}", version.0, version.1);
                let bytes = las_bytes(&scan, &LasSpec::new(version, format, laz));
                let from_bytes = parse(&bytes, PointFormat::Las).unwrap();
                let ext = if laz { "laz" } else { "las" };
                let path = write(dir.path(), &format!("f{format}.{ext}"), &bytes);
                let from_file = read_point_cloud(&path, &ReadLimits::default()).unwrap();
                assert_eq!(from_bytes, from_file, "{ctx}");
                assert!(same_bits(&from_file.points, &scan.points), "{ctx}");
                let has_color = matches!(format, 2 | 3 | 5 | 7 | 8 | 10);
                match &from_file.colors {
                    Some(c) => {
                        assert!(has_color, "{ctx}");
                        assert_eq!(c, &scan.unit_rgb(), "{ctx}");
                    }
                    None => assert!(!has_color, "{ctx}"),
                }
                let max = *scan.intensity.iter().max().unwrap();
                let want: Vec<f32> = (scan.intensity.iter())
                    .map(|&v| f32::from(v) / f32::from(max))
                    .collect();
                assert_eq!(from_file.intensity.as_ref(), Some(&want), "{ctx}");
                let hint = peek_point_count(&path).unwrap();
                assert_eq!((hint.points, hint.exact), (500, true), "{ctx}");
            }
        }
    }
}

#[test]
fn eight_bit_colour_in_the_sixteen_bit_fields_is_read_as_eight_bit() {
    let mut scan = sphere_scan(200, 2, [0.0; 3], [0.0; 3]);
    scan.rgb.iter_mut().for_each(|c| *c = c.map(|v| v >> 8));
    let pc = parse(
        &las_bytes(&scan, &LasSpec::new((1, 2), 2, false)),
        PointFormat::Las,
    )
    .unwrap();
    let want: Vec<[f32; 3]> = (scan.rgb.iter())
        .map(|c| c.map(|v| f32::from(v) / 255.0))
        .collect();
    assert_eq!(pc.colors, Some(want));
}

#[test]
fn e57_scans_come_back_in_the_file_frame_with_colour_and_intensity() {
    let scan = sphere_scan(900, 3, UTM, UTM);
    for coords in [E57Coords::Cartesian, E57Coords::Spherical] {
        for scans in [1, 3] {
            let bytes = e57_bytes(&scan, scans, coords, Some("EPSG:32633"));
            let pc = parse(&bytes, PointFormat::E57).unwrap();
            assert_eq!(pc.points.len(), scan.points.len());
            let worst = (pc.points.iter().zip(&scan.points))
                .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max))
                .fold(0.0, f64::max);
            // Pose round trip at UTM coordinates: f64 rounding only (1e-9 m).
            assert!(worst < 1e-6, "{coords:?} {scans} scans: off by {worst} m");
            assert_eq!(pc.colors.as_ref(), Some(&scan.unit_rgb()));
            let want: Vec<f32> = (scan.intensity.iter())
                .map(|&v| f32::from(v) / 65535.0)
                .collect();
            let got = pc.intensity.as_ref().unwrap();
            assert!(got.iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-6));
            assert_eq!(pc.crs.as_deref(), Some("EPSG:32633"));
        }
    }
}

#[test]
fn the_crs_comes_from_wkt_geotiff_keys_and_e57_metadata() {
    let scan = sphere_scan(100, 4, UTM, UTM);
    let wkt = r#"PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84"],AUTHORITY["EPSG","32633"]]"#;
    let mut spec = LasSpec::new((1, 4), 7, true);
    spec.wkt = Some(wkt.into());
    let pc = parse(&las_bytes(&scan, &spec), PointFormat::Las).unwrap();
    assert_eq!(pc.crs.as_deref(), Some(wkt));
    let mut spec = LasSpec::new((1, 2), 3, false);
    spec.epsg = Some(32633);
    let pc = parse(&las_bytes(&scan, &spec), PointFormat::Las).unwrap();
    assert_eq!(pc.crs.as_deref(), Some("EPSG:32633"));
    let pc = parse(
        &las_bytes(&scan, &LasSpec::new((1, 2), 3, false)),
        PointFormat::Las,
    )
    .unwrap();
    assert_eq!(pc.crs, None);
    let e57 = e57_bytes(&scan, 1, E57Coords::Cartesian, None);
    assert_eq!(parse(&e57, PointFormat::E57).unwrap().crs, None);
}

/// A reconstruction of `input` written as GLB (and PLY) in `dir` through the run stage.
fn run_to(input: &Path, dir: &Path, name: &str, format: MeshFormat) -> rbfsurf::report::Report {
    let mesh = dir.join(name);
    let report = dir.join(format!("{name}.json"));
    let out = RunOutput {
        mesh: &mesh,
        format,
        report: Some(&report),
        field: None,
        job_memory_mib: None,
    };
    // Every grid triangle: the simplifier's collapse order follows rounding-level differences of the
    // field, so the simplified meshes of a shifted cloud are equally accurate but not the same.
    let p = ReconParams {
        chord_error: rbfsurf::params::ChordTolerance::Off,
        ..Default::default()
    };
    run(
        PointSource::File(input),
        &p,
        &ReadLimits::default(),
        &out,
        &NoProgress,
    )
    .unwrap()
    .report
}

/// Plain float GLB, which the `gltf` crate reads (it has no meshopt decoder).
const PLAIN_GLB: MeshFormat = MeshFormat::Glb(GlbOptions::compressed(GlbCompression::None));

/// Vertex positions (f64: node translation + f32 position) and COLOR_0 (linear → sRGB) of a plain
/// GLB, read with the `gltf` crate, independently of rbfsurf's decoder.
fn glb_with_gltf(path: &Path) -> (Vec<Point3>, Vec<[f32; 3]>, serde_json::Value) {
    let bytes = std::fs::read(path).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = g.blob.as_deref().unwrap();
    let mut pos = Vec::new();
    let mut col = Vec::new();
    for node in g.document.nodes() {
        let Some(mesh) = node.mesh() else { continue };
        let t = node.transform().decomposed().0;
        for prim in mesh.primitives() {
            let r = prim.reader(|_| Some(blob));
            pos.extend(
                r.read_positions()
                    .unwrap()
                    .map(|p| [0, 1, 2].map(|k| f64::from(t[k]) + f64::from(p[k]))),
            );
            if let Some(c) = r.read_colors(0) {
                let srgb = |v: f32| {
                    if v <= 0.003_130_8 {
                        12.92 * v
                    } else {
                        1.055 * v.powf(1.0 / 2.4) - 0.055
                    }
                };
                col.extend(c.into_rgb_f32().map(|c| c.map(srgb)));
            }
        }
    }
    let glb = gltf::binary::Glb::from_slice(&bytes).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
    (pos, col, json)
}

/// Mean absolute error, per channel, of vertex colours against the field.
fn color_mae(pos: &[Point3], col: &[[f32; 3]], centre: Point3) -> f64 {
    let total: f64 = (pos.iter().zip(col))
        .map(|(p, c)| {
            let want = color_field(*p, centre, 10.0);
            (0..3)
                .map(|k| (f64::from(c[k]) - want[k]).abs())
                .sum::<f64>()
        })
        .sum();
    total / (3 * pos.len()) as f64
}

fn sorted(mut v: Vec<Point3>) -> Vec<Point3> {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v
}

/// Largest distance from a vertex of either set to the nearest vertex of the other, `b` moved
/// back by `shift` (a Hausdorff distance between the vertex sets; independent of their order).
fn vertex_distance(a: &[Point3], b: &[Point3], shift: Point3) -> f64 {
    assert_eq!(a.len(), b.len());
    vertex_hausdorff(a, b, shift)
}

/// [`vertex_distance`] for vertex sets of any sizes.
fn vertex_hausdorff(a: &[Point3], b: &[Point3], shift: Point3) -> f64 {
    use rbfsurf::spatial::{IndexKind, build_index};
    let back: Vec<Point3> = b
        .iter()
        .map(|q| [0, 1, 2].map(|k| q[k] - shift[k]))
        .collect();
    let one_way = |from: &[Point3], to: &[Point3]| {
        let index = build_index(to, IndexKind::KdTree, 16).unwrap();
        let mut near = Vec::new();
        from.iter()
            .map(|p| {
                index.nearest_k(p, 1, &mut near);
                near[0].1
            })
            .fold(0.0, f64::max)
    };
    one_way(a, &back).max(one_way(&back, a))
}

pub(crate) fn max_diff(a: &[Point3], b: &[Point3], shift: Point3) -> f64 {
    assert_eq!(a.len(), b.len());
    (a.iter().zip(b))
        .map(|(p, q)| {
            (0..3)
                .map(|k| (q[k] - shift[k] - p[k]).abs())
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[test]
fn las_laz_and_e57_of_one_scan_give_the_same_coloured_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let scan = sphere_scan(6000, 5, UTM, [UTM[0] - 50.0, UTM[1] - 50.0, 200.0]);
    let mut spec = LasSpec::new((1, 2), 3, false);
    spec.epsg = Some(32633);
    let las = write(dir.path(), "scan.las", &las_bytes(&scan, &spec));
    spec.laz = true;
    let laz = write(dir.path(), "scan.laz", &las_bytes(&scan, &spec));
    let e57 = write(
        dir.path(),
        "scan.e57",
        &e57_bytes(&scan, 2, E57Coords::Cartesian, Some("EPSG:32633")),
    );
    let mut meshes = Vec::new();
    for (name, input) in [("las", &las), ("laz", &laz), ("e57", &e57)] {
        let report = run_to(input, dir.path(), &format!("{name}.glb"), PLAIN_GLB);
        assert_eq!(report.attributes.color, "rgb", "{name}");
        assert_eq!(
            report.attributes.crs.as_deref(),
            Some("EPSG:32633"),
            "{name}"
        );
        assert!(report.mesh.watertight, "{name}: {:?}", report.mesh);
        let (pos, col, json) = glb_with_gltf(&dir.path().join(format!("{name}.glb")));
        assert_eq!(col.len(), pos.len(), "{name}: one colour per vertex");
        assert_eq!(json["asset"]["extras"]["crs"], "EPSG:32633", "{name}");
        let mae = color_mae(&pos, &col, UTM);
        eprintln!("{name}: {} vertices, colour MAE {mae:.4}", pos.len());
        assert!(mae <= 0.05, "{name}: colour MAE {mae}");
        meshes.push(sorted(pos));
    }
    // LAS and LAZ hold the same bits: the same mesh exactly.
    assert_eq!(meshes[0], meshes[1]);
    // E57 went through a pose and back (f64 rounding): the same mesh up to the f32 positions.
    let d = vertex_distance(&meshes[0], &meshes[2], [0.0; 3]);
    eprintln!("LAS vs E57 mesh: max vertex difference {d:.2e} m");
    assert!(d < 1e-4, "LAS and E57 meshes differ by {d} m");
}

#[test]
fn a_utm_shifted_cloud_gives_the_same_mesh_shifted_in_the_written_files() {
    let dir = tempfile::tempdir().unwrap();
    let shift = [5e5, 4.1e6, 250.0];
    let at_origin = sphere_scan(3000, 6, [0.0; 3], [0.0; 3]);
    let mut shifted = at_origin.clone();
    shifted.offset = shift;
    for p in &mut shifted.points {
        *p = [0, 1, 2].map(|k| p[k] + shift[k]);
    }
    let spec = LasSpec::new((1, 2), 3, false);
    let a = write(dir.path(), "a.las", &las_bytes(&at_origin, &spec));
    let b = write(dir.path(), "b.las", &las_bytes(&shifted, &spec));
    // The two clouds as read differ by the shift up to f64 rounding at 4.1e6 m (5e-10 m).
    let pa = read_point_cloud(&a, &ReadLimits::default()).unwrap();
    let pb = read_point_cloud(&b, &ReadLimits::default()).unwrap();
    assert!(max_diff(&pa.points, &pb.points, shift) < 1e-9);
    // GLB: node translation + f32 positions relative to it, read with the gltf crate.
    run_to(&a, dir.path(), "a.glb", PLAIN_GLB);
    run_to(&b, dir.path(), "b.glb", PLAIN_GLB);
    let (ga, _, _) = glb_with_gltf(&dir.path().join("a.glb"));
    let (gb, _, json) = glb_with_gltf(&dir.path().join("b.glb"));
    assert!(json["nodes"][0]["translation"].is_array(), "{json}");
    let d_glb = vertex_distance(&ga, &gb, shift);
    // PLY: doubles far from the origin.
    run_to(&a, dir.path(), "a.ply", MeshFormat::Ply);
    run_to(&b, dir.path(), "b.ply", MeshFormat::Ply);
    let ma = rbfsurf::io::read_mesh(&dir.path().join("a.ply")).unwrap();
    let mb = rbfsurf::io::read_mesh(&dir.path().join("b.ply")).unwrap();
    let head = std::fs::read(dir.path().join("b.ply")).unwrap();
    let head = String::from_utf8_lossy(&head[..400]);
    assert!(head.contains("property double x") && !head.contains("comment crs"));
    assert!(head.contains("property uchar red"), "{head}");
    let d_ply = vertex_distance(&ma.vertices, &mb.vertices, shift);
    // Compact GLB: 16-bit grid over the 20 m object, dequantized by the node transform (the
    // grid origin carries the offset): the object's precision, not the absolute coordinates'.
    let compact = MeshFormat::Glb(GlbOptions::default());
    run_to(&a, dir.path(), "ca.glb", compact);
    run_to(&b, dir.path(), "cb.glb", compact);
    let ca = rbfsurf::io::read_mesh(&dir.path().join("ca.glb")).unwrap();
    let cb = rbfsurf::io::read_mesh(&dir.path().join("cb.glb")).unwrap();
    let d_compact = vertex_hausdorff(&ca.vertices, &cb.vertices, shift);
    let d_quant = vertex_hausdorff(&ma.vertices, &ca.vertices, [0.0; 3]);
    eprintln!(
        "shifted by {shift:?}: GLB max difference {d_glb:.2e} m, PLY {d_ply:.2e} m, compact GLB {d_compact:.2e} m (quantization {d_quant:.2e} m)"
    );
    // 20 m / 65535 = 3e-4 m steps: half a step per axis at most, in each file.
    assert!(d_quant < 3e-4 && d_compact < 6e-4, "{d_quant} {d_compact}");
    // f32 at 4.1e6 m is 0.5 m coarse; relative to the local origin the 20 m object keeps ~1e-6.
    assert!(d_glb < 1e-5, "GLB: {d_glb}");
    assert!(d_ply < 1e-5, "PLY: {d_ply}");
}

/// Patches `bytes[at..at + v.len()]`.
fn patched(bytes: &[u8], at: usize, v: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[at..at + v.len()].copy_from_slice(v);
    b
}

#[test]
fn hostile_las_and_laz_are_refused_before_reading() {
    let scan = sphere_scan(3000, 7, UTM, UTM);
    let las = las_bytes(&scan, &LasSpec::new((1, 2), 3, false));
    let laz = las_bytes(&scan, &LasSpec::new((1, 2), 3, true));
    let las14 = las_bytes(&scan, &LasSpec::new((1, 4), 7, false));
    // Truncated body: refused from the header's count, before reading points.
    let e = parse(&las[..las.len() / 2], PointFormat::Las).unwrap_err();
    assert!(matches!(e, IoError::Truncated { .. }), "{e}");
    assert!(e.to_string().contains("3000 points"), "{e}");
    // A count beyond the point limit (u32::MAX in the legacy field).
    let e = parse(
        &patched(&las, 107, &u32::MAX.to_le_bytes()),
        PointFormat::Las,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::TooManyPoints { .. }), "{e}");
    // A count within the limit that the file cannot hold: truncated (LAS) or failing on the
    // data without allocating for it (LAZ).
    let lie = 40_000_000u32.to_le_bytes();
    let e = parse(&patched(&las, 107, &lie), PointFormat::Las).unwrap_err();
    assert!(matches!(e, IoError::Truncated { .. }), "{e}");
    let e = parse(&patched(&laz, 107, &lie), PointFormat::Las).unwrap_err();
    assert!(
        matches!(e, IoError::Truncated { .. } | IoError::Invalid { .. }),
        "{e}"
    );
    // The memory budget refuses before allocating.
    let tiny = ReadLimits {
        max_memory_mib: 0,
        ..ReadLimits::default()
    };
    let e = parse_point_cloud(&las, PointFormat::Las, &tiny).unwrap_err();
    assert!(matches!(e, IoError::OverMemory { points: 3000, .. }), "{e}");
    // Point data offset past the end; more VLRs than fit before the points.
    let e = parse(
        &patched(&las, 96, &u32::MAX.to_le_bytes()),
        PointFormat::Las,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::Truncated { .. }), "{e}");
    let e = parse(
        &patched(&las, 100, &1000u32.to_le_bytes()),
        PointFormat::Las,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::Invalid { .. }), "{e}");
    // LAS 1.4: an EVLR claiming u64::MAX / 2 bytes; a u64 point count beyond the limit.
    let evlr_start = las14.len() as u64;
    let mut evlr = patched(&las14, 235, &evlr_start.to_le_bytes());
    evlr = patched(&evlr, 243, &1u32.to_le_bytes());
    evlr.extend(std::iter::repeat_n(0u8, 60));
    let n = evlr.len();
    let evlr = patched(&evlr, n - 40, &(u64::MAX / 2).to_le_bytes());
    let e = parse(&evlr, PointFormat::Las).unwrap_err();
    assert!(matches!(e, IoError::Invalid { .. }), "{e}");
    assert!(e.to_string().contains("EVLR"), "{e}");
    let e = parse(
        &patched(&las14, 247, &(1u64 << 40).to_le_bytes()),
        PointFormat::Las,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::TooManyPoints { .. }), "{e}");
    // LAZ chunk table declaring 2^31 chunks.
    let offset = u32::from_le_bytes(laz[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(laz[offset..offset + 8].try_into().unwrap()) as usize;
    let e = parse(
        &patched(&laz, table + 4, &(1u32 << 31).to_le_bytes()),
        PointFormat::Las,
    )
    .unwrap_err();
    assert!(e.to_string().contains("chunk table"), "{e}");
}

/// Keeps the messages of panics that the `laz` decoder raises on corrupt data (the reader catches
/// them and returns an error) out of the test output; every other panic prints as before.
fn quiet_laz_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let in_laz = (info.location()).is_some_and(|l| l.file().contains("/laz-"));
            if !in_laz {
                default(info);
            }
        }));
    });
}

#[test]
fn cut_and_flipped_scanner_files_give_errors_not_panics() {
    quiet_laz_panics();
    let scan = sphere_scan(2000, 8, UTM, UTM);
    let files = [
        (
            las_bytes(&scan, &LasSpec::new((1, 4), 8, false)),
            PointFormat::Las,
        ),
        (
            las_bytes(&scan, &LasSpec::new((1, 4), 7, true)),
            PointFormat::Las,
        ),
        (
            las_bytes(&scan, &LasSpec::new((1, 2), 3, true)),
            PointFormat::Las,
        ),
        (
            e57_bytes(&scan, 2, E57Coords::Cartesian, None),
            PointFormat::E57,
        ),
    ];
    let mut rng = SplitMix64(9);
    let mut outcomes = [0usize; 2];
    for (bytes, format) in &files {
        // Every cut: a strict prefix never reads as the whole cloud.
        for k in 1..40 {
            let cut = bytes.len() * k / 40;
            if let Ok(pc) = parse(&bytes[..cut], *format) {
                assert!(
                    pc.points.len() < scan.points.len(),
                    "{format:?} cut at {cut}"
                );
            }
        }
        // Random byte flips anywhere (header, VLRs, compressed data, XML, pages).
        for _ in 0..150 {
            let mut b = bytes.clone();
            for _ in 0..1 + (rng.next_f64() * 4.0) as usize {
                let at = (rng.next_f64() * b.len() as f64) as usize % b.len();
                b[at] ^= 1 << (rng.next_u64() % 8);
            }
            let r = parse(&b, *format);
            outcomes[usize::from(r.is_ok())] += 1;
        }
    }
    eprintln!(
        "flipped files: {} refused, {} read",
        outcomes[0], outcomes[1]
    );
    assert!(outcomes[0] > 0);
}

#[test]
fn hostile_e57_headers_are_refused() {
    let scan = sphere_scan(500, 10, UTM, UTM);
    let e57 = e57_bytes(&scan, 1, E57Coords::Cartesian, None);
    // XML section claimed past the end; file length beyond the bytes present.
    let e = parse(
        &patched(&e57, 32, &(u64::MAX / 4).to_le_bytes()),
        PointFormat::E57,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::Invalid { .. }), "{e}");
    let e = parse(
        &patched(&e57, 16, &(1u64 << 40).to_le_bytes()),
        PointFormat::E57,
    )
    .unwrap_err();
    assert!(matches!(e, IoError::Truncated { .. }), "{e}");
    let e = parse(&e57[..40], PointFormat::E57).unwrap_err();
    assert!(matches!(e, IoError::Truncated { .. }), "{e}");
    let tiny = ReadLimits {
        max_points: 499,
        ..ReadLimits::default()
    };
    let e = parse_point_cloud(&e57, PointFormat::E57, &tiny).unwrap_err();
    assert!(
        matches!(e, IoError::TooManyPoints { declared: 500, .. }),
        "{e}"
    );
    // Content sniffing: LAS and E57 by their signatures whatever the name.
    assert_eq!(PointFormat::sniff(&e57), Some(PointFormat::E57));
    let las = las_bytes(&scan, &LasSpec::new((1, 2), 0, false));
    assert_eq!(PointFormat::sniff(&las), Some(PointFormat::Las));
    let dir = tempfile::tempdir().unwrap();
    let named_wrong = write(dir.path(), "scan.xyz", &e57);
    assert_eq!(
        read_point_cloud(&named_wrong, &ReadLimits::default())
            .unwrap()
            .points
            .len(),
        500
    );
}
