//! Whether `../shared` (the paper's dragon, the Khronos sample models) is beside the
//! repository when the tests are built. The tests that read it run where it is, and
//! elsewhere are listed in the test summary as ignored, with the reason (`cargo test`
//! counts them), instead of passing without having run.
//!
//! Decided once per build of this crate: put `../shared` in place (or set
//! `OCTRACE_SHARED`) before building the tests, or `touch tests/build.rs` afterwards.
//! (Asking Cargo to watch a folder that is not there would rebuild the tests on every
//! run.)

use std::path::PathBuf;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(octrace_shared)");
    println!("cargo::rerun-if-env-changed=OCTRACE_SHARED");
    println!("cargo::rerun-if-changed=build.rs");
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let root = std::env::var_os("OCTRACE_SHARED").map_or_else(|| manifest.join("../../shared"), PathBuf::from);
    if root.join("meshes/dragon.obj").is_file() {
        println!("cargo::rustc-cfg=octrace_shared");
    }
}
