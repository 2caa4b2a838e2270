//! The independent check of the scanner readers and the test writers, run by
//! `tests/scripts/scanners_independent.py` (laspy, lazrs, pye57): rbfsurf reads the files those
//! libraries wrote and compares with their CSVs, then writes its own for them to read.

use std::path::Path;

use crate::scanner_files::{E57Coords, LasSpec, Scan, e57_bytes, las_bytes, write};
use crate::scanners::{UTM, max_diff, same_bits, sphere_scan};
use rbfsurf::geometry::Point3;
use rbfsurf::io::{ReadLimits, read_point_cloud};

/// Rows of a `x,y,z,r,g,b,i` CSV written by `tests/scripts/scanners_independent.py`.
fn read_csv(path: &Path) -> (Vec<Point3>, Vec<[u16; 3]>, Vec<f64>) {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut xyz, mut rgb, mut intensity) = (Vec::new(), Vec::new(), Vec::new());
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        xyz.push([0, 1, 2].map(|k| f[k].parse::<f64>().unwrap()));
        rgb.push([3, 4, 5].map(|k| f[k].parse::<u16>().unwrap()));
        intensity.push(f[6].parse::<f64>().unwrap());
    }
    (xyz, rgb, intensity)
}

fn write_csv(path: &Path, scan: &Scan) {
    let mut s = String::from("x,y,z,r,g,b,i\n");
    for (i, p) in scan.points.iter().enumerate() {
        let [r, g, b] = scan.rgb[i];
        s.push_str(&format!(
            "{:?},{:?},{:?},{r},{g},{b},{}\n",
            p[0], p[1], p[2], scan.intensity[i]
        ));
    }
    std::fs::write(path, s).unwrap();
}

/// Run by `tests/scripts/scanners_independent.py` (laspy, lazrs, pye57): reads the files those
/// libraries wrote, compares with their CSVs, and writes rbfsurf's own for them to check.
#[test]
#[ignore = "run by tests/scripts/scanners_independent.py, which needs laspy, lazrs and pye57"]
fn independent_files() {
    let dir = std::path::PathBuf::from(
        std::env::var("RBFSURF_INDEPENDENT_DIR").expect("RBFSURF_INDEPENDENT_DIR"),
    );
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if !name.starts_with("theirs") || name.ends_with(".csv") {
            continue;
        }
        let (xyz, rgb, intensity) = read_csv(&dir.join(format!("{name}.csv")));
        let pc = read_point_cloud(&path, &ReadLimits::default()).unwrap();
        let colors = pc.colors.as_ref().unwrap();
        let got = pc.intensity.as_ref().unwrap();
        if name.ends_with(".e57") {
            let d = max_diff(&pc.points, &xyz, [0.0; 3]);
            assert!(d < 1e-6, "{name}: coordinates off by {d}");
            for (c, want) in colors.iter().zip(&rgb) {
                assert!((0..3).all(|k| (c[k] - f32::from(want[k]) / 255.0).abs() < 1e-6));
            }
            // pye57 writes each scan's own intensity limits (its min and max); the script's
            // two scans are the halves.
            let half = intensity.len() / 2;
            for (range, scan) in [(0..half, "scan 0"), (half..intensity.len(), "scan 1")] {
                let part = &intensity[range.clone()];
                let lo = part.iter().fold(f64::MAX, |a, &b| a.min(b));
                let hi = part.iter().fold(f64::MIN, |a, &b| a.max(b));
                for (g, v) in got[range].iter().zip(part) {
                    let want = (v - lo) / (hi - lo);
                    assert!((f64::from(*g) - want).abs() < 1e-5, "{name} {scan}");
                }
            }
        } else {
            assert!(same_bits(&pc.points, &xyz), "{name}: coordinates differ");
            let max = intensity.iter().fold(0.0f64, |a, &b| a.max(b));
            for (c, want) in colors.iter().zip(&rgb) {
                assert!(
                    (0..3).all(|k| c[k] == f32::from(want[k]) / 65535.0),
                    "{name}"
                );
            }
            for (g, v) in got.iter().zip(&intensity) {
                assert!((f64::from(*g) - v / max).abs() < 1e-6, "{name}");
            }
        }
        eprintln!("{name}: {} points agree", pc.points.len());
        checked += 1;
    }
    assert_eq!(
        checked,
        4,
        "expected the script's four files in {}",
        dir.display()
    );
    let scan = sphere_scan(4000, 11, UTM, [UTM[0] - 20.0, UTM[1] - 20.0, 0.0]);
    for (name, spec) in [
        ("ours_12_f3.las", LasSpec::new((1, 2), 3, false)),
        ("ours_14_f7.laz", LasSpec::new((1, 4), 7, true)),
        ("ours_14_f0.las", LasSpec::new((1, 4), 0, false)),
    ] {
        write(&dir, name, &las_bytes(&scan, &spec));
        write_csv(&dir.join(format!("{name}.csv")), &scan);
    }
    // pye57 reads colour into 8-bit buffers: values within 0..=255 for it.
    let mut scan8 = scan.clone();
    scan8.rgb.iter_mut().for_each(|c| *c = c.map(|v| v >> 8));
    let e57 = e57_bytes(&scan8, 3, E57Coords::Cartesian, None);
    write(&dir, "ours.e57", &e57);
    write_csv(&dir.join("ours.e57.csv"), &scan8);
}
