//! The README's Rust code, compiled by `cargo test --doc` (not run: it opens a file)
//! in a crate whose only dependency is `octrace-runtime`, as an application's would
//! be: what the README shows needs nothing else (`glam` and the format's types come
//! re-exported).
#![doc = include_str!("../../README.md")]
