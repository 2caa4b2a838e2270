//! Volume modelling: saved fields bit for bit, CSG against analytic solids, offsets,
//! voxel files read back, morph topology, bad input.

use rbfsurf::frep::expr::{Loader, build};
use rbfsurf::frep::{
    Align, CsgParams, FieldModel, FrepError, MorphParams, VoxelParams, format, mesh_solid, parse,
};
use rbfsurf::geometry::synthetic::Shape;
use rbfsurf::geometry::{Point3, TriMesh};
use rbfsurf::mesh::topology::{analyze, signed_volume};
use rbfsurf::params::ReconParams;
use rbfsurf::pipeline::reconstruct_keeping_field;
use rbfsurf::polygonize::ScalarField;
use rbfsurf::progress::NoProgress;
use std::f64::consts::PI;
use std::path::Path;

fn solid(src: &str, dir: &Path) -> Result<rbfsurf::frep::Solid, FrepError> {
    build(&parse(src)?, &mut Loader::new(dir))
}

fn csg(src: &str, dir: &Path, resolution: usize) -> Result<TriMesh, FrepError> {
    let s = solid(src, dir)?;
    let p = CsgParams {
        resolution,
        ..Default::default()
    };
    mesh_solid(&s, src, &p, &NoProgress).map(|(m, _)| m)
}

fn fitted(shape: &str, n: usize, params: &ReconParams) -> FieldModel {
    let cloud = Shape::by_name(shape).unwrap().sample(n, 7);
    let (_, field) = reconstruct_keeping_field(&cloud, params, &NoProgress).unwrap();
    field.expect("CSRBF keeps its field")
}

fn sphere_sd(p: &Point3, c: Point3, r: f64) -> f64 {
    ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt() - r
}

/// Volume of the union of two unit-radius-r balls at distance d (two minus the lens).
fn two_ball_union(r: f64, d: f64) -> f64 {
    let lens = PI * (4.0 * r + d) * (2.0 * r - d).powi(2) / 12.0;
    2.0 * 4.0 / 3.0 * PI * r.powi(3) - lens
}

#[test]
fn set_operations_on_primitives_match_the_analytic_solids() {
    let dir = Path::new(".");
    let res = 96;
    // Union of two balls r = 1 at distance 1: one closed genus-0 component.
    let m = csg("union(sphere(0,0,0,1), sphere(1,0,0,1))", dir, res).unwrap();
    let t = analyze(&m);
    assert!(t.watertight && t.manifold, "{t:?}");
    assert_eq!((t.components, t.genus), (1, Some(0)));
    let want = two_ball_union(1.0, 1.0);
    let got = signed_volume(&m);
    assert!(
        (got - want).abs() / want < 0.01,
        "union volume {got} vs {want}"
    );
    let cell = 3.2 / res as f64;
    let err = m
        .vertices
        .iter()
        .map(|v| {
            sphere_sd(v, [0.0; 3], 1.0)
                .min(sphere_sd(v, [1.0, 0.0, 0.0], 1.0))
                .abs()
        })
        .fold(0.0, f64::max);
    assert!(err < cell, "union surface off by {err} (cell {cell})");
    // Intersection: the lens.
    let m = csg("intersection(sphere(0,0,0,1), sphere(1,0,0,1))", dir, res).unwrap();
    let lens = PI * 5.0 / 12.0;
    let got = signed_volume(&m);
    assert!(
        (got - lens).abs() / lens < 0.02,
        "lens volume {got} vs {lens}"
    );
    // Box minus a through-cylinder: a genus-1 solid with the exact volume.
    let m = csg(
        "difference(box(-1,-1,-1,1,1,1), cylinder(0,0,-2,0,0,2,0.5))",
        dir,
        res,
    )
    .unwrap();
    let t = analyze(&m);
    assert!(t.watertight && t.manifold, "{t:?}");
    assert_eq!((t.components, t.genus), (1, Some(1)));
    let want = 8.0 - PI * 0.25 * 2.0;
    let got = signed_volume(&m);
    assert!(
        (got - want).abs() / want < 0.02,
        "box−cylinder volume {got} vs {want}"
    );
}

#[test]
fn offset_of_a_sphere_moves_its_radius_and_transforms_move_it() {
    let m = csg("offset(sphere(0,0,0,1), 0.25)", Path::new("."), 64).unwrap();
    let err = m
        .vertices
        .iter()
        .map(|v| sphere_sd(v, [0.0; 3], 1.25).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-3, "offset sphere radius off by {err}");
    let m = csg(
        "translate(scale(sphere(0,0,0,1), 2), 5, 0, 0)",
        Path::new("."),
        64,
    )
    .unwrap();
    let err = m
        .vertices
        .iter()
        .map(|v| sphere_sd(v, [5.0, 0.0, 0.0], 2.0).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-3, "moved sphere off by {err}");
    let m = csg("rotate(torus(0,0,0,1,0.25), 1,0,0, 90)", Path::new("."), 64).unwrap();
    let b = rbfsurf::geometry::Aabb::from_points(&m.vertices);
    // The torus now lies in the xz plane: thin along y.
    assert!(
        (b.extent()[1] - 0.5).abs() < 0.02 && (b.extent()[2] - 2.5).abs() < 0.02,
        "{b:?}"
    );
}

#[test]
fn a_saved_field_loads_and_evaluates_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let variants = [
        ReconParams::default(),
        ReconParams {
            levels: 2,
            ..Default::default()
        },
        ReconParams {
            blocks: "1000".parse().unwrap(),
            ..Default::default()
        },
    ];
    for (k, params) in variants.iter().enumerate() {
        let model = fitted("torus", 3000, params);
        let bytes = format::encode(&model);
        let path = dir.path().join(format!("t{k}.field"));
        std::fs::write(&path, &bytes).unwrap();
        let back = format::read(&path).unwrap();
        assert_eq!(format::encode(&back), bytes, "re-encoding differs");
        let mut rng = rbfsurf::geometry::synthetic::SplitMix64(3);
        for _ in 0..2000 {
            let p = [0, 1, 2].map(|_| -0.1 + 1.2 * rng.next_f64());
            let (a, b) = (model.rbf.value(&p), back.rbf.value(&p));
            assert_eq!(a.to_bits(), b.to_bits(), "variant {k} at {p:?}: {a} vs {b}");
            let (ga, gb) = (model.rbf.gradient(&p), back.rbf.gradient(&p));
            assert_eq!(ga.map(f64::to_bits), gb.map(f64::to_bits));
            let q = model.normalization.inverse(&p);
            assert_eq!(model.value(&q).to_bits(), back.value(&q).to_bits());
        }
    }
}

#[test]
fn bad_field_files_and_expressions_are_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let model = fitted("sphere", 800, &ReconParams::default());
    let bytes = format::encode(&model);
    let good = dir.path().join("good.field");
    std::fs::write(&good, &bytes).unwrap();
    let mut corrupt = bytes.clone();
    corrupt[bytes.len() / 2] ^= 1;
    std::fs::write(dir.path().join("corrupt.field"), &corrupt).unwrap();
    let mut v2 = bytes.clone();
    v2[8] = 2;
    std::fs::write(dir.path().join("v2.field"), &v2).unwrap();
    std::fs::write(dir.path().join("short.field"), &bytes[..100]).unwrap();
    let d = dir.path();
    let e = |src: &str| {
        solid(src, d)
            .err()
            .unwrap_or_else(|| panic!("{src} should fail"))
    };
    assert!(matches!(e("corrupt.field"), FrepError::Corrupt { .. }));
    assert!(matches!(e("short.field"), FrepError::Corrupt { .. }));
    assert!(matches!(e("v2.field"), FrepError::Version { found: 2, .. }));
    assert!(matches!(e("missing.field"), FrepError::Read { .. }));
    assert!(matches!(
        e("onion(good.field, good.field)"),
        FrepError::UnknownOperation { .. }
    ));
    assert!(matches!(e("union(good.field)"), FrepError::Arity { .. }));
    assert!(matches!(e("sphere(0, 0, 1)"), FrepError::Arity { .. }));
    assert!(matches!(e("union(good.field, 3)"), FrepError::Arity { .. }));
    assert!(matches!(
        e("union(good.field, good.field"),
        FrepError::Syntax { .. }
    ));
    assert!(matches!(
        e("sphere(0,0,0,-1)"),
        FrepError::BadArgument { .. }
    ));
    // Quoted paths work; the solid is usable.
    assert!(solid("union('good.field', \"good.field\", 0.5)", d).is_ok());
    // Disjoint intersection: empty, refused before meshing.
    let err = csg("intersection(sphere(0,0,0,1), sphere(5,0,0,1))", d, 32).unwrap_err();
    assert!(matches!(err, FrepError::Empty(_)), "{err}");
    // Overlapping boxes but disjoint solids: refused after meshing found nothing.
    let err = csg(
        "intersection(sphere(0,0,0,1), sphere(1.9,1.9,1.9,1))",
        d,
        32,
    )
    .unwrap_err();
    assert!(matches!(err, FrepError::Empty(_)), "{err}");
}

#[test]
fn scans_combine_with_primitives_and_with_themselves() {
    let dir = tempfile::tempdir().unwrap();
    let model = fitted("sphere", 3000, &ReconParams::default());
    std::fs::write(dir.path().join("s.field"), format::encode(&model)).unwrap();
    let d = dir.path();
    // The scan is a ball of radius 0.4 at (0.5, 0.5, 0.5) (input units = the generator's).
    let res = 80;
    let m = csg("difference(s.field, sphere(0.5, 0.5, 0.9, 0.25))", d, res).unwrap();
    let cell = 1.0 / res as f64;
    let inside = m
        .vertices
        .iter()
        .map(|v| sphere_sd(v, [0.5, 0.5, 0.9], 0.25))
        .fold(f64::INFINITY, f64::min);
    assert!(
        inside > -1e-3 * cell,
        "a vertex lies {inside} inside the subtracted sphere"
    );
    let t = analyze(&m);
    assert!(t.watertight && t.components == 1, "{t:?}");
    // A scan and a shifted copy overlapping: one watertight component.
    let m = csg("union(s.field, translate(s.field, 0.3, 0, 0))", d, res).unwrap();
    let t = analyze(&m);
    assert!(t.watertight && t.manifold, "{t:?}");
    assert_eq!((t.components, t.genus), (1, Some(0)));
    // Offset of the fitted field: radius 0.4 → 0.45, within a few per cent of the offset.
    let m = csg("offset(s.field, 0.05)", d, res).unwrap();
    let err = m
        .vertices
        .iter()
        .map(|v| sphere_sd(v, [0.5; 3], 0.45).abs())
        .fold(0.0, f64::max);
    assert!(
        err < 0.25 * 0.05,
        "offset of the fitted sphere off by {err}"
    );
}

/// Attribute `name="…"` of the first element that has it.
fn attr<'a>(xml: &'a str, name: &str) -> &'a str {
    let key = format!(" {name}=\"");
    let at = xml.find(&key).unwrap_or_else(|| panic!("no {name}")) + key.len();
    &xml[at..at + xml[at..].find('"').unwrap()]
}

#[test]
fn a_vti_file_reads_back_with_the_right_signs() {
    let dir = tempfile::tempdir().unwrap();
    let s = solid(
        "difference(box(0,0,0,2,1,1), sphere(2,1,1,0.5))",
        dir.path(),
    )
    .unwrap();
    let grid = rbfsurf::frep::voxelize(&s, &VoxelParams { resolution: 41 }).unwrap();
    let path = dir.path().join("v.vti");
    rbfsurf::frep::voxel::write_volume(&path, &grid).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let marker = bytes.windows(4).position(|w| w == b"   _").unwrap() + 4;
    let xml = std::str::from_utf8(&bytes[..marker]).unwrap();
    assert!(xml.contains("type=\"ImageData\"") && xml.contains("F >= 0 inside"));
    let ext: Vec<usize> = attr(xml, "WholeExtent")
        .split(' ')
        .map(|v| v.parse().unwrap())
        .collect();
    let dims = [ext[1] + 1, ext[3] + 1, ext[5] + 1];
    let origin: Vec<f64> = attr(xml, "Origin")
        .split(' ')
        .map(|v| v.parse().unwrap())
        .collect();
    let spacing: f64 = attr(xml, "Spacing")
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(attr(xml, "type"), "ImageData");
    let n = u64::from_le_bytes(bytes[marker..marker + 8].try_into().unwrap()) as usize;
    assert_eq!(n, dims.iter().product::<usize>() * 4);
    let data = &bytes[marker + 8..marker + 8 + n];
    let at = |i: usize, j: usize, k: usize| {
        let o = 4 * (i + dims[0] * (j + dims[1] * k));
        f32::from_le_bytes(data[o..o + 4].try_into().unwrap())
    };
    assert!((spacing - 2.0 / 40.0).abs() < 1e-9);
    let mut checked = 0;
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i, j, k].map(|c| c as f64);
                let x = [0, 1, 2].map(|a| origin[a] + p[a] * spacing);
                let in_box = (0..3).all(|a| x[a] > 0.0 && x[a] < [2.0, 1.0, 1.0][a]);
                let inside = in_box && sphere_sd(&x, [2.0, 1.0, 1.0], 0.5) > 0.0;
                let v = at(i, j, k);
                let margin = (0..3)
                    .map(|a| x[a].abs().min((x[a] - [2.0, 1.0, 1.0][a]).abs()))
                    .fold(f64::INFINITY, f64::min)
                    .min(sphere_sd(&x, [2.0, 1.0, 1.0], 0.5).abs());
                if margin > 1e-6 {
                    assert_eq!(v > 0.0, inside, "sample ({i},{j},{k}) at {x:?}: F = {v}");
                    checked += 1;
                }
                assert!((f64::from(v) - s.value(&x)).abs() < 1e-5);
            }
        }
    }
    assert!(checked > dims.iter().product::<usize>() / 2);
}

#[test]
fn a_sphere_morphs_into_a_torus_through_a_topology_change() {
    let a = fitted("sphere", 2000, &ReconParams::default());
    let b = fitted("torus", 3000, &ReconParams::default());
    let params = MorphParams {
        frames: 8,
        mesh: CsgParams {
            resolution: 64,
            ..Default::default()
        },
        align: Align::BoundingBox,
    };
    let a = rbfsurf::frep::Solid::Field(std::sync::Arc::new(a));
    let b = rbfsurf::frep::Solid::Field(std::sync::Arc::new(b));
    let mut meshes = Vec::new();
    let r = rbfsurf::frep::morph(a, b, None, &params, &NoProgress, |_, m| {
        meshes.push(m);
        Ok(())
    })
    .unwrap();
    assert_eq!(r.frames.len(), 8);
    for f in &r.frames {
        assert!(f.watertight && f.manifold, "{f:?}");
    }
    assert_eq!(r.frames[0].genus, Some(0));
    assert_eq!(r.frames[7].genus, Some(1));
    // The middle frame is neither end: some of its vertices are more than two cells from every
    // vertex of either end (nearest-vertex distance, k-d tree).
    let cell = 1.0 / 64.0;
    let farthest = |from: &TriMesh, to: &TriMesh| {
        let tree = rbfsurf::spatial::KdTree::build(&to.vertices).unwrap();
        from.vertices
            .iter()
            .map(|v| tree.nearest_one(v).unwrap().1)
            .fold(0.0, f64::max)
    };
    let (d0, d7) = (
        farthest(&meshes[3], &meshes[0]),
        farthest(&meshes[3], &meshes[7]),
    );
    assert!(
        d0 > 2.0 * cell && d7 > 2.0 * cell,
        "middle frame {d0} from A, {d7} from B"
    );
    let glb = rbfsurf::io::encode_animated_glb(&meshes, 0.25).unwrap();
    let back = rbfsurf::io::decode_glb(&glb).unwrap();
    let total: usize = meshes.iter().map(|m| m.triangles.len()).sum();
    assert_eq!(back.triangles.len(), total);
}
