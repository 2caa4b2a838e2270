//! Volume data: sample a solid on a regular grid and write it as VTK XML ImageData (`.vti`, what
//! ParaView and VTK read) or NRRD (`.nrrd`).
//!
//! The grid covers the solid's box ([`Solid::bounds`]) grown by two cells, with `resolution`
//! samples along its longest edge and the same spacing on every axis; values are the F-rep values
//! (`F ≥ 0` inside, about a signed distance in input units near the surface) as float32, x fastest.
//! The `.vti` file has one point-data array `F` (float32, raw appended, little-endian, UInt64
//! header) and states the sign convention in an XML comment and in the array's `sign` attribute.

use super::FrepError;
use super::ops::Solid;
use crate::geometry::{Aabb, Point3};
use crate::io::write_atomic;
use rayon::prelude::*;
use std::path::Path;

/// How finely to sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VoxelParams {
    /// Samples along the longest edge (2..=1024).
    pub resolution: usize,
}

/// A sampled volume.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelGrid {
    /// Position of sample (0, 0, 0), input units.
    pub origin: Point3,
    /// Distance between samples, input units (equal on every axis).
    pub spacing: f64,
    /// Samples along x, y, z.
    pub dims: [usize; 3],
    /// `F` at every sample, x fastest, then y, then z.
    pub values: Vec<f32>,
}

/// Sample `solid` (see the module doc).
pub fn voxelize(solid: &Solid, params: &VoxelParams) -> Result<VoxelGrid, FrepError> {
    if !(2..=1024).contains(&params.resolution) {
        return Err(FrepError::Param {
            name: "resolution",
            value: params.resolution.to_string(),
            expected: "2..=1024 samples along the longest edge",
        });
    }
    let b = solid.bounds().ok_or_else(|| {
        FrepError::Empty("the bounding boxes of the operands do not overlap".into())
    })?;
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    if !(longest > 0.0 && longest.is_finite()) {
        return Err(FrepError::Empty("the solid's box has no extent".into()));
    }
    let spacing = longest / (params.resolution - 1) as f64;
    let b = b.inflated(2.0 * spacing);
    let e = b.extent();
    let dims = e.map(|x| (x / spacing).ceil() as usize + 1);
    let origin = b.min;
    let slab = dims[0] * dims[1];
    let mut values = vec![0f32; slab * dims[2]];
    values
        .par_chunks_mut(slab)
        .enumerate()
        .for_each(|(k, out)| {
            let z = origin[2] + k as f64 * spacing;
            let pts: Vec<Point3> = (0..slab)
                .map(|i| {
                    let (ix, iy) = (i % dims[0], i / dims[0]);
                    [
                        origin[0] + ix as f64 * spacing,
                        origin[1] + iy as f64 * spacing,
                        z,
                    ]
                })
                .collect();
            let region = Aabb::from_points(&pts);
            let mut v = vec![0.0; slab];
            solid.values(&region, &pts, &mut v);
            for (o, x) in out.iter_mut().zip(v) {
                *o = x as f32;
            }
        });
    Ok(VoxelGrid {
        origin,
        spacing,
        dims,
        values,
    })
}

/// The `.vti` bytes of `grid`.
pub fn encode_vti(grid: &VoxelGrid) -> Vec<u8> {
    let [nx, ny, nz] = grid.dims;
    let (o, s) = (grid.origin, grid.spacing);
    let (lo, hi) = grid
        .values
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let header = format!(
        r#"<?xml version="1.0"?>
<!-- rbfsurf voxelize: F-rep values, F >= 0 inside the solid, F < 0 outside, F = 0 on the surface; about a signed distance in input units near it -->
<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64">
  <ImageData WholeExtent="0 {} 0 {} 0 {}" Origin="{:e} {:e} {:e}" Spacing="{:e} {:e} {:e}" Direction="1 0 0 0 1 0 0 0 1">
    <Piece Extent="0 {} 0 {} 0 {}">
      <PointData Scalars="F">
        <DataArray type="Float32" Name="F" NumberOfComponents="1" format="appended" offset="0" RangeMin="{:e}" RangeMax="{:e}" sign="positive-inside"/>
      </PointData>
      <CellData/>
    </Piece>
  </ImageData>
  <AppendedData encoding="raw">
   _"#,
        nx - 1,
        ny - 1,
        nz - 1,
        o[0],
        o[1],
        o[2],
        s,
        s,
        s,
        nx - 1,
        ny - 1,
        nz - 1,
        lo,
        hi
    );
    let mut out = header.into_bytes();
    out.extend_from_slice(&((grid.values.len() * 4) as u64).to_le_bytes());
    out.extend(grid.values.iter().flat_map(|v| v.to_le_bytes()));
    out.extend_from_slice(b"\n  </AppendedData>\n</VTKFile>\n");
    out
}

/// The `.nrrd` bytes of `grid` (NRRD 4, raw little-endian float32, space origin and directions).
pub fn encode_nrrd(grid: &VoxelGrid) -> Vec<u8> {
    let [nx, ny, nz] = grid.dims;
    let (o, s) = (grid.origin, grid.spacing);
    let header = format!(
        "NRRD0004\n# rbfsurf voxelize: F >= 0 inside the solid, F < 0 outside (F-rep)\ntype: float\ndimension: 3\nspace: right-anterior-superior\nsizes: {nx} {ny} {nz}\nspace directions: ({s:e},0,0) (0,{s:e},0) (0,0,{s:e})\nspace origin: ({:e},{:e},{:e})\nkinds: domain domain domain\nendian: little\nencoding: raw\n\n",
        o[0], o[1], o[2]
    );
    let mut out = header.into_bytes();
    out.extend(grid.values.iter().flat_map(|v| v.to_le_bytes()));
    out
}

/// Write `grid` to `path` (`.vti` or `.nrrd`, by extension) atomically.
pub fn write_volume(path: &Path, grid: &VoxelGrid) -> Result<(), FrepError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let bytes = match ext.as_deref() {
        Some("vti") => encode_vti(grid),
        Some("nrrd") => encode_nrrd(grid),
        _ => {
            return Err(FrepError::Param {
                name: "output",
                value: path.display().to_string(),
                expected: "a .vti (VTK XML ImageData) or .nrrd file",
            });
        }
    };
    write_atomic(path, &bytes)?;
    Ok(())
}
