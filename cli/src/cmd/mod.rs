//! One module per subcommand.

pub(crate) mod bake;
pub(crate) mod bench;
pub(crate) mod contains;
pub(crate) mod demo;
pub(crate) mod distance;
pub(crate) mod inspect;
pub(crate) mod rays;
pub(crate) mod render;
pub(crate) mod report;
pub(crate) mod soak;
pub(crate) mod trace;
pub(crate) mod trace_crossings;
pub(crate) mod verify;
