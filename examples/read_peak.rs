//! Reads one point cloud with [`rbfsurf::io::read_point_cloud`] and prints the point count, the
//! wall time and the process's peak resident memory (VmHWM, Linux), to measure the reader alone.
//!
//! `cargo run --release --example read_peak -- FILE [MAX_POINTS]`

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args_os().skip(1);
    let path = args.next().ok_or("usage: read_peak FILE [MAX_POINTS]")?;
    let mut limits = rbfsurf::io::ReadLimits::default();
    if let Some(m) = args.next() {
        limits.max_points = m.to_string_lossy().parse()?;
    }
    let t = Instant::now();
    let pc = rbfsurf::io::read_point_cloud(std::path::Path::new(&path), &limits)?;
    let secs = t.elapsed().as_secs_f64();
    println!(
        "points {} normals {} read {:.3} s peak_rss {:.1} MiB",
        pc.points.len(),
        pc.normals.is_some(),
        secs,
        rbfsurf::report::peak_rss_mib()
    );
    Ok(())
}
