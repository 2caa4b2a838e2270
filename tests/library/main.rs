//! Integration tests of the library alone (no command line, no server): end-to-end reconstruction
//! against analytic truth and the shipped data, the large-scan machinery, the parser soak.
//! One test binary, so the crate is linked once (`cargo test --test library`).

mod colour;
#[path = "../common/mod.rs"]
mod common;
mod docs_links;
mod frep;
mod large;
mod open_scans;
mod out_of_core;
mod parser_soak;
mod pipeline;
mod run;
mod scanner_files;
mod scanners;
mod scanners_independent;
mod skip_test;
mod tile_evaluation;
