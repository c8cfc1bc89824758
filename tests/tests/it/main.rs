//! octrace's integration tests, one module per area.

mod bunny;
mod format;
mod mesh;
mod raysets;
mod render;
