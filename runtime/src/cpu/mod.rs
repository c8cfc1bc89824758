//! CPU tracing. The walk of Portalez & Duguet, one file a form of it:
//!
//! * `tracer.rs`: the tracer (a scene's view, its frame, the walk's options);
//! * `walk.rs`: a walk's state, the leaf visit every form shares, and the scalar step
//!   (the always-compiled reference the SIMD forms are tested against, bit for bit);
//! * `locate.rs`: where a walk starts (point location, the cube map);
//! * `fans.rs`: the hierarchies of the leaves whose triangles share one vertex;
//! * `simd/`: the SSE step and the eight-lane AVX2 step, on `hw.rs`'s primitives;
//! * `one_ray.rs` and `batch.rs`: the calls, which pick a form (`order.rs`: the
//!   memory order of incoherent batches).
//!
//! Dependencies go one way: `hw`, `tables`, `triangle`, `watertight` below the walk
//! (`tracer`, `walk`, `locate`), the walk below `simd/`, `simd/` below the calls.

mod batch;
mod closest;
mod crossings;
mod crossings_batch;
pub(crate) mod fans;
pub(crate) mod hw;
pub(crate) mod inside;
mod locate;
mod locate_grid;
mod one_ray;
mod order;
mod simd;
pub mod tables;
mod tracer;
mod triangle;
mod walk;
pub mod watertight;

pub(crate) use closest::along_curve;
pub(crate) use closest::{cross, dot, sub};
pub use closest::{signed, ClosestPoint, ClosestScratch, SurfaceBounds};
pub use crossings::{Crossing, CrossingCount};
#[cfg(feature = "gpu")]
pub(crate) use crossings_batch::over_budget;
pub use crossings_batch::{BatchCrossings, CROSSING_BYTES};
pub use fans::{FanIndex, FanSummary, MIN_REFERENCES as FAN_MIN_REFERENCES, MIN_TRIANGLES as FAN_MIN_TRIANGLES};
pub use inside::{Solid, COUNT_DIRECTION};
pub use locate_grid::LocateGrid;
pub(crate) use tracer::{box_slack, BOX_T_SLACK};
pub use tracer::{mesh_box, root_corners, ExitTest, MemoryOrder, Tracer, TreeFrame, TriangleTest, WalkStats};
pub(crate) use walk::{clip, exit_along_moving_axes, point_at};

#[cfg(test)]
mod tests;
