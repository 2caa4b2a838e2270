//! Displayed vertex colours: a sphere whose points carry an sRGB-encoded colour field linear in
//! the position (LAS and LAZ with 16-bit colour and with 8-bit values in the 16-bit fields, E57
//! with 16-bit and 8-bit integer colour and with float colour), reconstructed with default
//! parameters into both GLB storages. glTF 2.0 defines COLOR_0 as linear; a conforming viewer
//! (three.js, the Khronos sample viewer) shows its sRGB encoding, which must match the field at
//! the vertices. The plain file is read with the `gltf` crate, the compressed one with rbfsurf's
//! decoder (which returns sRGB-encoded colours).

use std::path::Path;

use crate::scanner_files::{E57Coords, LasSpec, Scan, color_field, e57_bytes, las_bytes, write};
use crate::scanners::{UTM, sphere_scan};
use rbfsurf::geometry::Point3;
use rbfsurf::io::{GlbCompression, GlbOptions, MeshFormat, ReadLimits, decode_glb};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::{PointSource, RunOutput, run};
use rbfsurf::progress::NoProgress;

/// sRGB encoding (IEC 61966-2-1) of a linear value in [0, 1], as a viewer's output stage does it.
fn encode_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// World positions and COLOR_0 as stored (linear) of a plain GLB, read with the `gltf` crate.
fn plain_glb(path: &Path) -> (Vec<Point3>, Vec<[f32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let g = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = g.blob.as_deref().unwrap();
    let (mut pos, mut col) = (Vec::new(), Vec::new());
    for node in g.document.nodes() {
        let Some(mesh) = node.mesh() else { continue };
        let t = node.transform().decomposed().0;
        for prim in mesh.primitives() {
            let r = prim.reader(|_| Some(blob));
            let p = r.read_positions().unwrap();
            pos.extend(p.map(|p| [0, 1, 2].map(|k| f64::from(t[k]) + f64::from(p[k]))));
            col.extend(r.read_colors(0).expect("COLOR_0").into_rgb_f32());
        }
    }
    (pos, col)
}

/// Mean and 99th percentile over vertices and channels of |displayed − field|.
fn displayed_error(pos: &[Point3], shown: &[[f32; 3]]) -> (f64, f64) {
    assert_eq!(pos.len(), shown.len(), "one colour per vertex");
    assert!(!pos.is_empty());
    let mut err: Vec<f64> = (pos.iter().zip(shown))
        .flat_map(|(p, c)| {
            let want = color_field(*p, UTM, 10.0);
            (0..3).map(move |k| (f64::from(c[k]) - want[k]).abs())
        })
        .collect();
    let mean = err.iter().sum::<f64>() / err.len() as f64;
    err.sort_by(f64::total_cmp);
    (mean, err[err.len() * 99 / 100])
}

/// Reconstructs `input` with default parameters into `name` with `compression`.
fn reconstruct(input: &Path, dir: &Path, name: &str, compression: GlbCompression) {
    let mesh = dir.join(name);
    let out = RunOutput {
        mesh: &mesh,
        format: MeshFormat::Glb(GlbOptions::compressed(compression)),
        report: None,
        field: None,
        job_memory_mib: None,
    };
    let p = ReconParams::default();
    let r = run(
        PointSource::File(input),
        &p,
        &ReadLimits::default(),
        &out,
        &NoProgress,
    );
    assert_eq!(r.unwrap().report.attributes.color, "rgb", "{name}");
}

/// A one-scan E57 (identity pose) of `scan` with colour of `data_type`, values `value(c16)` from
/// the 16-bit colour, and the given colour limits (`None`: the type's range applies).
fn e57_custom(
    scan: &Scan,
    data_type: e57::RecordDataType,
    value: impl Fn(u16) -> e57::RecordValue,
    limits: Option<(e57::RecordValue, e57::RecordValue)>,
) -> Vec<u8> {
    use e57::{Record, RecordName, RecordValue};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.e57");
    let mut w = e57::E57Writer::from_file(&path, "rbfsurf-colour-test").unwrap();
    let channel = |name| Record {
        name,
        data_type: data_type.clone(),
    };
    let protos = vec![
        Record::CARTESIAN_X_F64,
        Record::CARTESIAN_Y_F64,
        Record::CARTESIAN_Z_F64,
        channel(RecordName::ColorRed),
        channel(RecordName::ColorGreen),
        channel(RecordName::ColorBlue),
    ];
    let mut pc = w.add_pointcloud("scan-0", protos).unwrap();
    if let Some((lo, hi)) = limits {
        pc.set_color_limits(Some(e57::ColorLimits {
            red_min: Some(lo.clone()),
            red_max: Some(hi.clone()),
            green_min: Some(lo.clone()),
            green_max: Some(hi.clone()),
            blue_min: Some(lo),
            blue_max: Some(hi),
        }));
    }
    for (p, c) in scan.points.iter().zip(&scan.rgb) {
        let mut values: Vec<RecordValue> = p.iter().map(|&v| RecordValue::Double(v)).collect();
        values.extend(c.map(&value));
        pc.add_point(values).unwrap();
    }
    pc.finalize().unwrap();
    w.finalize().unwrap();
    drop(w);
    std::fs::read(&path).unwrap()
}

/// A binary PLY of `scan` with double coordinates and red, green, blue as `uchar` (the 16-bit
/// values' high bytes) or as `ushort`.
fn ply_bytes(scan: &Scan, sixteen: bool) -> Vec<u8> {
    let ty = if sixteen { "ushort" } else { "uchar" };
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\n\
         property double y\nproperty double z\nproperty {ty} red\nproperty {ty} green\n\
         property {ty} blue\nend_header\n",
        scan.points.len()
    )
    .into_bytes();
    for (p, c) in scan.points.iter().zip(&scan.rgb) {
        p.iter().for_each(|v| out.extend(v.to_le_bytes()));
        for v in c {
            if sixteen {
                out.extend(v.to_le_bytes());
            } else {
                out.push((v >> 8) as u8);
            }
        }
    }
    out
}

#[test]
fn displayed_colours_match_the_srgb_field_of_las_laz_e57_and_ply() {
    use e57::{RecordDataType, RecordValue};
    let dir = tempfile::tempdir().unwrap();
    let scan = sphere_scan(8000, 9, UTM, [UTM[0] - 50.0, UTM[1] - 50.0, 200.0]);
    let mut eight = scan.clone();
    eight.rgb.iter_mut().for_each(|c| *c = c.map(|v| v >> 8));
    let las12 = LasSpec::new((1, 2), 3, false);
    let laz14 = LasSpec::new((1, 4), 7, true);
    let int = |max: i64| RecordDataType::Integer { min: 0, max };
    let unit_float = RecordDataType::Single {
        min: Some(0.0),
        max: Some(1.0),
    };
    let inputs: Vec<(&str, Vec<u8>)> = vec![
        ("las-16bit.las", las_bytes(&scan, &las12)),
        ("las-8bit-in-16.las", las_bytes(&eight, &las12)),
        ("laz-16bit.laz", las_bytes(&scan, &laz14)),
        ("ply-8bit.ply", ply_bytes(&scan, false)),
        ("ply-16bit.ply", ply_bytes(&scan, true)),
        (
            "e57-16bit.e57",
            e57_bytes(&scan, 2, E57Coords::Cartesian, None),
        ),
        (
            "e57-8bit.e57",
            e57_custom(
                &eight,
                int(255),
                |v| RecordValue::Integer(i64::from(v)),
                Some((RecordValue::Integer(0), RecordValue::Integer(255))),
            ),
        ),
        (
            "e57-float.e57",
            e57_custom(
                &scan,
                unit_float,
                |v| RecordValue::Single(f32::from(v) / 65535.0),
                None,
            ),
        ),
    ];
    for (name, bytes) in inputs {
        let input = write(dir.path(), name, &bytes);
        reconstruct(&input, dir.path(), "plain.glb", GlbCompression::None);
        let (pos, linear) = plain_glb(&dir.path().join("plain.glb"));
        let shown: Vec<[f32; 3]> = linear.iter().map(|c| c.map(encode_srgb)).collect();
        let (mean, p99) = displayed_error(&pos, &shown);
        // A viewer that showed COLOR_0 without the sRGB encoding would be off by ~0.22 here.
        let (raw, _) = displayed_error(&pos, &linear);
        eprintln!("{name} plain: mean {mean:.4}, p99 {p99:.4} (unencoded {raw:.3})");
        assert!(mean <= 0.01 && p99 <= 0.03, "{name}: {mean} {p99}");
        assert!(
            raw > 0.1,
            "{name}: COLOR_0 must be linear, not sRGB ({raw})"
        );

        reconstruct(&input, dir.path(), "meshopt.glb", GlbCompression::Meshopt);
        let m = decode_glb(&std::fs::read(dir.path().join("meshopt.glb")).unwrap()).unwrap();
        let (mean, p99) = displayed_error(&m.vertices, &m.colors);
        eprintln!("{name} meshopt: mean {mean:.4}, p99 {p99:.4}");
        assert!(mean <= 0.01 && p99 <= 0.03, "{name} meshopt: {mean} {p99}");
    }
}
