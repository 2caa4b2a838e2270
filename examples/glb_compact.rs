//! Measures the compact GLB against the plain one for a mesh file (any format `read_mesh` reads):
//! bytes and bytes per triangle of both, encode and decode times (best of `REPEAT`), and the
//! largest distance between a vertex of the decoded compact file and the nearest vertex of the
//! plain one, relative to the bounding-box diagonal (the dequantization error).
//!
//! `cargo run --release --example glb_compact -- MESH [REPEAT]`

use std::time::Instant;

use rbfsurf::io::{GlbCompression, MeshMeta, decode_glb, encode_glb_with, read_mesh};
use rbfsurf::spatial::{IndexKind, build_index};

fn best<T>(repeat: usize, mut f: impl FnMut() -> T) -> (T, f64) {
    let mut out = None;
    let mut best = f64::INFINITY;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        let v = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(v);
    }
    (out.expect("one run"), best)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args_os().skip(1);
    let path = args.next().ok_or("usage: glb_compact MESH [REPEAT]")?;
    let repeat: usize = args.next().map_or(Ok(5), |r| r.to_string_lossy().parse())?;
    let mesh = read_mesh(std::path::Path::new(&path))?;
    let meta = MeshMeta::default();
    let diag = rbfsurf::geometry::Aabb::from_points(&mesh.vertices).diagonal();
    let mut decoded = Vec::new();
    for c in [GlbCompression::None, GlbCompression::Meshopt] {
        let (glb, enc) = best(repeat, || encode_glb_with(&mesh, &meta, c));
        let glb = glb?;
        let (back, dec) = best(repeat, || decode_glb(&glb));
        let back = back?;
        println!(
            "{:8} {:>10} bytes {:6.2} B/triangle ({} triangles in the file, {} in the mesh) encode {:.1} ms decode {:.1} ms",
            c.name(),
            glb.len(),
            glb.len() as f64 / back.triangles.len() as f64,
            back.triangles.len(),
            mesh.triangles.len(),
            enc * 1e3,
            dec * 1e3
        );
        decoded.push(back);
    }
    let index = build_index(&decoded[0].vertices, IndexKind::KdTree, 16)?;
    let mut near = Vec::new();
    let worst = (decoded[1].vertices.iter())
        .map(|p| {
            index.nearest_k(p, 1, &mut near);
            near[0].1
        })
        .fold(0.0f64, f64::max);
    println!(
        "max dequantization error {worst:.3e} = {:.3e} of the bbox diagonal {diag:.4}",
        worst / diag
    );
    Ok(())
}
