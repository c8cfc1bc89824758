//! Traces rays through octrace baked scenes.
//!
//! Open a `.oct` file with [`Scene::open`] (validated, in memory) or [`Scene::map`]
//! (validated, memory-mapped), then ask [`Scene::intersect`] for the nearest hit or
//! [`Scene::occluded`] for any hit, one ray at a time or over slices on all cores.
//! The walk is the one of Portalez & Duguet, *Lancer de rayons dans un octree* (2016):
//! cube-map entry, exit face from Plücker signs, neighbour from two more signs.
//! [`reference::Reference`] is the `f64` brute-force oracle the tests compare with.
//! With the `gpu` feature (on by default), `gpu::GpuTracer` runs the same walk in a
//! wgpu compute kernel on Vulkan, from the same bytes, with the same answers, and
//! `gpu::GpuRenderer` renders the effects of [`render::effects`] there, shading
//! included. [`world::World`] places scenes many times by transforms, moves them
//! between frames and traces them as one.
//!
//! # Example
//! A scene baked by `octrace bake` (or `octrace_bake`), opened and traced with this
//! crate alone:
//! ```no_run
//! use octrace_runtime::glam::Vec3; // the glam this crate speaks, re-exported
//! use octrace_runtime::{Ray, Scene};
//! let scene = Scene::open("bunny.oct")?;
//! let ray = Ray::new(Vec3::new(0.0, 0.1, 1.0), Vec3::new(0.0, 0.0, -1.0));
//! if let Some(hit) = scene.intersect(&ray) {
//!     println!("t = {} on input triangle {}", hit.t, hit.triangle);
//! }
//! let hits = scene.intersect_batch(&vec![ray; 1024]); // many rays: on all cores
//! # let _ = hits;
//! # Ok::<(), octrace_runtime::Error>(())
//! ```
//!
//! Baking in the same program, with `octrace-bake`:
//! ```
//! use octrace_runtime::glam::Vec3;
//! use octrace_runtime::{Ray, Scene};
//! let mesh = octrace_bake::procedural::sphere([0.0; 3], 1.0, 16, 24);
//! let baked = octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto())?;
//! let scene = Scene::from_baked(baked)?;
//! let hit = scene.intersect(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)).expect("hits the sphere");
//! assert!((hit.t - 4.0).abs() < 0.01);
//! assert!(!scene.occluded(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::X)));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

pub mod baselines;
pub mod cpu;
mod error;
mod exact;
#[cfg(feature = "gpu")]
pub mod gpu;
mod ray;
pub mod raysets;
pub mod reference;
pub mod render;
mod scene;
pub mod spawn;
pub mod surface;
#[doc(hidden)]
pub mod testing;
pub mod winding;
pub mod world;

/// The vector type of the API (`Ray::new` takes `glam::Vec3`), re-exported so that a
/// caller needs no `glam` of its own (or a matching version of it).
pub use glam;
/// The file format's crate: [`format::SceneView`], [`format::Shading`] and the other
/// types the runtime hands out.
pub use octrace_format as format;

pub use cpu::{ClosestPoint, ExitTest, MemoryOrder, Tracer, TriangleTest, WalkStats};
pub use error::{Error, Result};
pub use exact::exact_stage_runs;
pub use ray::{Hit, Ray};
pub use scene::Scene;
pub use surface::HitSurface;

/// The baselines at their former paths, for code written before they moved to
/// [`baselines`] (hidden: not for new code).
#[doc(hidden)]
pub use baselines::{bvh, kdtree, unconstrained};
