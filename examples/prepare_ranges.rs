//! Runs one out-of-core reconstruction of a point file with prepare's passes read whole or by
//! byte ranges of the given size, and prints each pass task's wall time (count, sample, route
//! per range), prepare's total, the whole run and the peak resident memory, to measure the
//! range split.
//!
//! `cargo run --release --example prepare_ranges -- FILE whole|RANGE_MIB [MAX_MEMORY_MIB]`

use rbfsurf::pipeline::tiled::{InputSplit, TiledInput, TiledOptions, reconstruct_tiled_from};
use std::collections::BTreeMap;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let usage = "usage: prepare_ranges FILE whole|RANGE_MIB [MAX_MEMORY_MIB]";
    let mut args = std::env::args().skip(1);
    let path = std::path::PathBuf::from(args.next().ok_or(usage)?);
    let split = match args.next().ok_or(usage)?.as_str() {
        "whole" => InputSplit::Whole,
        mib => InputSplit::Bytes(mib.parse::<f64>().map(|m| (m * 1048576.0) as u64)?),
    };
    let mut params = rbfsurf::params::ReconParams::default();
    if let Some(m) = args.next() {
        params.max_memory_mib = m.parse()?;
    }
    let limits = rbfsurf::io::ReadLimits::default();
    let input = TiledInput::Stream(rbfsurf::io::StreamInput::File(&path), &limits);
    let options = TiledOptions {
        split,
        ..Default::default()
    };
    let progress = rbfsurf::progress::NoProgress;
    let r = reconstruct_tiled_from(&input, &params, &options, &progress)?.report;
    // Per kind of task (the name without its range number): count, max and sum of seconds.
    let mut kinds: BTreeMap<String, (usize, f64, f64)> = BTreeMap::new();
    for t in &r.tasks {
        let kind = t.task.trim_end_matches(|c: char| c.is_ascii_digit()).trim();
        let e = kinds.entry(kind.to_string()).or_default();
        *e = (e.0 + 1, e.1.max(t.seconds), e.2 + t.seconds);
    }
    println!("{} points, split {split:?}", r.input.points);
    for (kind, (n, max, sum)) in kinds {
        println!("  {kind:<14} tasks {n:>3}  max {max:>7.3} s  sum {sum:>7.3} s");
    }
    println!(
        "  prepare {:.3} s, total {:.3} s, {} blocks, {} triangles, peak_rss {:.1} MiB",
        r.timings_s.clean,
        r.timings_s.total,
        r.blocks.len(),
        r.mesh.triangles,
        rbfsurf::report::peak_rss_mib()
    );
    Ok(())
}
