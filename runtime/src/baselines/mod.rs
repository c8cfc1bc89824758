//! What `octrace report` measures the octree against, apart from the tracer an app
//! uses: the seeds' baselines (a BVH built four ways, seed 001; an SAH kd-tree, seed
//! 003) and the paper's future work, the octree without its 2:1 constraint. Each
//! traces with the octree's own watertight triangle test, so that the report compares
//! structures, not triangle tests.

pub mod bvh;
pub mod kdtree;
pub mod unconstrained;
