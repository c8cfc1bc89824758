//! octrace's integration tests, one module per area.

mod attributes;
mod back_faces;
mod budgets;
mod bunny;
mod closest;
mod crossings;
mod effects;
mod environment;
mod exact;
mod format;
mod gltf_lenient;
mod gpu;
mod gpu_crossings;
mod gpu_stream;
mod hard_cases;
mod hostile;
mod images;
mod inside;
mod materials;
mod mesh;
mod raysets;
mod render;
mod tangents;
mod texcoords;
mod trusted;
mod unconstrained;
