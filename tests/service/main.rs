//! Integration tests of the command line and the HTTP service (features `cli` and `server`):
//! the binary as a user meets it, the API in-process and on a real listener, `rbfsurf submit`.
//! One test binary, so the crate is linked once (`cargo test --test service`).

mod cli;
#[path = "../common/mod.rs"]
mod common;
mod hostile;
mod http;
mod load;
mod python_clients;
#[path = "../library/scanner_files.rs"]
mod scanner_files;
#[path = "../server_common/mod.rs"]
mod server_common;
mod stop;
mod submit;
mod volume;
