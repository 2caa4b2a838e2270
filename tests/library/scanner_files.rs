//! Scanner files made in the tests themselves (no downloads): LAS/LAZ written with the `las`
//! crate, E57 with the `e57` crate, from one coloured point set.

// Shared with the service tests, which use only part of it.
#![allow(dead_code)]

use std::io::Cursor;
use std::path::Path;

use rbfsurf::geometry::Point3;

/// Points with 16-bit colour and intensity, as a scanner would store them.
#[derive(Debug, Clone)]
pub struct Scan {
    /// Coordinates, on the LAS grid of [`Scan::offset`] and [`SCALE`] (exactly representable
    /// as `raw · scale + offset`, so every format stores the same values).
    pub points: Vec<Point3>,
    /// 16-bit RGB.
    pub rgb: Vec<[u16; 3]>,
    /// 16-bit intensity.
    pub intensity: Vec<u16>,
    /// LAS offset (the grid origin).
    pub offset: Point3,
}

/// LAS coordinate scale used by [`Scan::on_grid`], metres per unit.
pub const SCALE: f64 = 1e-5;

/// A smooth colour field in [0.1, 0.9]³ around `centre` (radius `r`): linear in each coordinate.
pub fn color_field(p: Point3, centre: Point3, r: f64) -> [f64; 3] {
    [0, 1, 2].map(|k| 0.5 + 0.4 * ((p[k] - centre[k]) / r).clamp(-1.0, 1.0))
}

impl Scan {
    /// `points` snapped to the LAS grid at `offset`, coloured by [`color_field`] around `centre`
    /// with radius `r`; intensity from the height.
    pub fn on_grid(points: &[Point3], offset: Point3, centre: Point3, r: f64) -> Scan {
        let snapped: Vec<Point3> = points
            .iter()
            .map(|p| [0, 1, 2].map(|k| SCALE * ((p[k] - offset[k]) / SCALE).round() + offset[k]))
            .collect();
        let rgb = snapped
            .iter()
            .map(|&p| color_field(p, centre, r).map(|c| (c * 65535.0).round() as u16))
            .collect();
        let intensity = snapped
            .iter()
            .map(|p| (((p[2] - centre[2]) / r).clamp(-1.0, 1.0) * 20000.0 + 30000.0) as u16)
            .collect();
        Scan {
            points: snapped,
            rgb,
            intensity,
            offset,
        }
    }

    /// The colours as the readers return them: 16-bit scaled to [0, 1].
    pub fn unit_rgb(&self) -> Vec<[f32; 3]> {
        (self.rgb.iter())
            .map(|c| c.map(|v| f32::from(v) / 65535.0))
            .collect()
    }
}

/// LAS options: version, point format, compression, CRS.
#[derive(Debug, Clone)]
pub struct LasSpec {
    pub version: (u8, u8),
    pub format: u8,
    pub laz: bool,
    /// OGC WKT, written as the WKT VLR (LAS 1.4 only).
    pub wkt: Option<String>,
    /// EPSG code written as GeoTIFF ProjectedCSTypeGeoKey (3072).
    pub epsg: Option<u16>,
}

impl LasSpec {
    pub fn new(version: (u8, u8), format: u8, laz: bool) -> LasSpec {
        LasSpec {
            version,
            format,
            laz,
            wkt: None,
            epsg: None,
        }
    }
}

/// The GeoKeyDirectory VLR (LASF_Projection 34735) with one key: ProjectedCSTypeGeoKey = `epsg`.
fn geokeys(epsg: u16) -> las::Vlr {
    let words: [u16; 8] = [1, 1, 0, 1, 3072, 0, 1, epsg];
    las::Vlr {
        user_id: "LASF_Projection".into(),
        record_id: 34735,
        description: "GeoKeyDirectoryTag".into(),
        data: words.iter().flat_map(|w| w.to_le_bytes()).collect(),
    }
}

/// `scan` as LAS or LAZ bytes per `spec`.
pub fn las_bytes(scan: &Scan, spec: &LasSpec) -> Vec<u8> {
    let mut b = las::Builder::from(spec.version);
    let mut format = las::point::Format::new(spec.format).unwrap();
    format.is_compressed = spec.laz;
    b.point_format = format;
    let t = |k: usize| las::Transform {
        scale: SCALE,
        offset: scan.offset[k],
    };
    b.transforms = las::Vector {
        x: t(0),
        y: t(1),
        z: t(2),
    };
    if let Some(e) = spec.epsg {
        b.vlrs.push(geokeys(e));
    }
    let mut header = b.into_header().unwrap();
    if let Some(w) = &spec.wkt {
        header.set_wkt_crs(w.as_bytes().to_vec()).unwrap();
    }
    let mut w = las::Writer::new(Cursor::new(Vec::new()), header).unwrap();
    for (i, p) in scan.points.iter().enumerate() {
        let [r, g, bl] = scan.rgb[i];
        let point = las::Point {
            x: p[0],
            y: p[1],
            z: p[2],
            intensity: scan.intensity[i],
            gps_time: format.has_gps_time.then_some(i as f64),
            color: format.has_color.then(|| las::Color::new(r, g, bl)),
            nir: format.has_nir.then_some(7),
            waveform: format.has_waveform.then(Default::default),
            ..Default::default()
        };
        w.write_point(point).unwrap();
    }
    w.into_inner().unwrap().into_inner()
}

/// A rotation quaternion (w, x, y, z) of `angle` radians about the unit axis `axis`.
fn quaternion(axis: Point3, angle: f64) -> [f64; 4] {
    let (s, c) = (0.5 * angle).sin_cos();
    [c, s * axis[0], s * axis[1], s * axis[2]]
}

/// Rotation matrix (row-major) of the unit quaternion `q`.
fn rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// How the points of an E57 scan are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum E57Coords {
    /// `cartesianX/Y/Z` as f64.
    Cartesian,
    /// `sphericalRange/Azimuth/Elevation` as f64 (converted by the reader).
    Spherical,
}

/// `scan` as E57 bytes: split into `scans` scans, each stored in its own frame (the inverse of a
/// distinct pose applied) with that pose recorded, so a reader that applies the poses gets the
/// original coordinates back. Colour as 16-bit integers (limits 0..65535), intensity 16-bit.
pub fn e57_bytes(scan: &Scan, scans: usize, coords: E57Coords, crs: Option<&str>) -> Vec<u8> {
    use e57::{Record, RecordDataType, RecordName, RecordValue};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scan.e57");
    let mut w = e57::E57Writer::from_file(&path, "rbfsurf-test-file").unwrap();
    w.set_coordinate_metadata(crs.map(str::to_string));
    let n = scan.points.len();
    let u16_type = RecordDataType::Integer { min: 0, max: 65535 };
    let xyz = match coords {
        E57Coords::Cartesian => [
            Record::CARTESIAN_X_F64,
            Record::CARTESIAN_Y_F64,
            Record::CARTESIAN_Z_F64,
        ],
        E57Coords::Spherical => [
            Record::SPHERICAL_RANGE_F64,
            Record::SPHERICAL_AZIMUTH_F64,
            Record::SPHERICAL_ELEVATION_F64,
        ],
    };
    let prototype = |name| Record {
        name,
        data_type: u16_type.clone(),
    };
    for s in 0..scans {
        let range = s * n / scans..(s + 1) * n / scans;
        let axis = [0.6, 0.0, 0.8];
        let q = quaternion(axis, 0.3 + s as f64);
        let t = [
            scan.offset[0] + 10.0 * s as f64,
            scan.offset[1] - 3.0,
            scan.offset[2] + 1.5,
        ];
        let r = rotation(q);
        let mut protos = xyz.to_vec();
        protos.extend([
            prototype(RecordName::ColorRed),
            prototype(RecordName::ColorGreen),
            prototype(RecordName::ColorBlue),
            prototype(RecordName::Intensity),
        ]);
        let mut pc = w.add_pointcloud(&format!("scan-{s}"), protos).unwrap();
        pc.set_transform(Some(e57::Transform {
            rotation: e57::Quaternion {
                w: q[0],
                x: q[1],
                y: q[2],
                z: q[3],
            },
            translation: e57::Translation {
                x: t[0],
                y: t[1],
                z: t[2],
            },
        }));
        pc.set_color_limits(Some(e57::ColorLimits {
            red_min: Some(RecordValue::Integer(0)),
            red_max: Some(RecordValue::Integer(65535)),
            green_min: Some(RecordValue::Integer(0)),
            green_max: Some(RecordValue::Integer(65535)),
            blue_min: Some(RecordValue::Integer(0)),
            blue_max: Some(RecordValue::Integer(65535)),
        }));
        pc.set_intensity_limits(Some(e57::IntensityLimits {
            intensity_min: Some(RecordValue::Integer(0)),
            intensity_max: Some(RecordValue::Integer(65535)),
        }));
        for i in range {
            // Local = Rᵀ (p − t).
            let d = [0, 1, 2].map(|k| scan.points[i][k] - t[k]);
            let l = [0, 1, 2].map(|k| r[0][k] * d[0] + r[1][k] * d[1] + r[2][k] * d[2]);
            let c = match coords {
                E57Coords::Cartesian => l,
                E57Coords::Spherical => {
                    let range = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
                    [range, l[1].atan2(l[0]), (l[2] / range).asin()]
                }
            };
            let mut values: Vec<RecordValue> = c.iter().map(|&v| RecordValue::Double(v)).collect();
            values.extend(scan.rgb[i].map(|v| RecordValue::Integer(i64::from(v))));
            values.push(RecordValue::Integer(i64::from(scan.intensity[i])));
            pc.add_point(values).unwrap();
        }
        pc.finalize().unwrap();
    }
    w.finalize().unwrap();
    drop(w);
    std::fs::read(&path).unwrap()
}

/// Writes `bytes` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}
