//! The report's configurations: each accuracy knob turned from the defaults, the
//! peer libraries, the octree walked without the SIMD steps or without the 2:1
//! constraint, and the seeds' baselines, each a structure that can be built on any
//! mesh (the mesh, its far copy, the closed solids).

use std::sync::Arc;
use std::time::Instant;

use octrace_bake::octree::{build_unbalanced, ResolvedParams};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::baselines::bvh::{Bvh, BvhBuild};
use octrace_runtime::baselines::kdtree::KdTree;
use octrace_runtime::baselines::unconstrained::UnconstrainedOctree;
use octrace_runtime::{ExitTest, Hit, Ray, Scene, Tracer, TriangleTest};

use super::measure::{answers_by, tracer_answers, Answer, Traced};

/// One accuracy knob turned from the defaults.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Knob {
    Defaults,
    MollerTrumbore,
    F64,
    SlabExit,
    /// The defaults' Plücker exit on the one-walk-at-a-time loop (no eight-lane
    /// walk): what the slab row gives up besides its test.
    OneWalk,
    Margin(f32),
    Depth(i32),
    LeafSize(u32),
}

/// The knobs of the report, in its order.
pub(super) const KNOBS: [Knob; 12] = [
    Knob::Defaults,
    Knob::MollerTrumbore,
    Knob::F64,
    Knob::SlabExit,
    Knob::OneWalk,
    Knob::Margin(0.0),
    Knob::Margin(1.0 / 65536.0),
    Knob::Depth(-2),
    Knob::Depth(-1),
    Knob::Depth(1),
    Knob::LeafSize(8),
    Knob::LeafSize(32),
];

impl Knob {
    pub(super) fn group(self) -> &'static str {
        match self {
            Knob::Defaults => "defaults",
            Knob::MollerTrumbore | Knob::F64 => "triangle test",
            Knob::SlabExit | Knob::OneWalk => "exit face",
            Knob::Margin(_) => "bake margin",
            Knob::Depth(_) => "depth limit",
            Knob::LeafSize(_) => "leaf target",
        }
    }

    pub(super) fn setting(self, base: &ResolvedParams) -> String {
        match self {
            Knob::Defaults => format!(
                "watertight f32, Plücker exit, margin {}, depth {}, leaf {}",
                power_of_two(base.margin),
                base.max_depth,
                base.leaf_size
            ),
            Knob::MollerTrumbore => "Möller-Trumbore f32".into(),
            Knob::F64 => "Möller-Trumbore f64".into(),
            Knob::SlabExit => "slab distances (one walk at a time: no eight-lane walk)".into(),
            Knob::OneWalk => "Plücker, one walk at a time (the slab row's loop)".into(),
            Knob::Margin(m) => power_of_two(m),
            Knob::Depth(_) => self.params(base).resolve(0).max_depth.to_string(),
            Knob::LeafSize(_) => self.params(base).resolve(0).leaf_size.to_string(),
        }
    }

    /// The bake parameters: `base` (a mesh's automatic ones) with this knob turned.
    pub(super) fn params(self, base: &ResolvedParams) -> BuildParams {
        let mut p = BuildParams {
            max_depth: Some(base.max_depth),
            leaf_size: Some(base.leaf_size),
            margin: base.margin,
            ..BuildParams::auto()
        };
        match self {
            Knob::Margin(m) => p.margin = m,
            Knob::Depth(d) => p.max_depth = Some(base.max_depth.saturating_add_signed(d).max(1)),
            Knob::LeafSize(n) => p.leaf_size = Some(n),
            Knob::Defaults | Knob::MollerTrumbore | Knob::F64 | Knob::SlabExit | Knob::OneWalk => {}
        }
        p
    }

    /// `scene`'s tracer with this knob's tests.
    pub(super) fn tracer(self, scene: &Scene) -> Tracer<'_> {
        let test = match self {
            Knob::MollerTrumbore => TriangleTest::MollerTrumbore,
            Knob::F64 => TriangleTest::F64,
            _ => TriangleTest::Watertight,
        };
        let exit = if self == Knob::SlabExit { ExitTest::Slab } else { ExitTest::Plucker };
        scene.tracer().with_triangle_test(test).with_exit_test(exit).with_lanes(self != Knob::OneWalk)
    }
}

/// `2^-20` for a power of two, `0` for zero, else the number.
pub(super) fn power_of_two(x: f32) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let e = x.log2();
    if e == e.round() {
        format!("2^{}", e as i32)
    } else {
        format!("{x:e}")
    }
}

/// What a configuration is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Config {
    Knob(Knob),
    /// The `k`-th peer of this build (`build_peers`).
    Peer(usize),
    /// The defaults' bake walked by the portable scalar step.
    ScalarStep,
    /// The tree without the 2:1 constraint, with ropes.
    Unconstrained,
    Bvh(BvhBuild),
    KdTree,
}

/// A configuration built on a mesh.
pub(super) struct Built {
    pub traced: Box<dyn Traced>,
    /// Seconds to build (bake, BVH build, ...), bytes of the file or in memory,
    /// leaves or nodes, references per triangle (octrees).
    pub seconds: f64,
    pub bytes: u64,
    pub nodes: u64,
    pub references_per_triangle: f64,
    /// The SAH cost (the seeds' baselines).
    pub sah_cost: Option<f64>,
    /// The octree's scene, where the configuration is one.
    pub scene: Option<Arc<Scene>>,
}

impl Config {
    /// Every configuration of this build: the knobs, the peers, the scalar step and
    /// the unconstrained tree, the seeds' baselines.
    pub(super) fn all() -> Vec<Config> {
        let mut all: Vec<Config> = KNOBS.into_iter().map(Config::Knob).collect();
        all.extend((0..peer_names().len()).map(Config::Peer));
        all.extend([Config::ScalarStep, Config::Unconstrained]);
        all.extend(BvhBuild::ALL.into_iter().map(Config::Bvh));
        all.push(Config::KdTree);
        all
    }

    /// The row's group: the knob's, or "peer", "octree", "baseline".
    pub(super) fn group(self) -> &'static str {
        match self {
            Config::Knob(k) => k.group(),
            Config::Peer(_) => "peer",
            Config::ScalarStep | Config::Unconstrained => "octree",
            Config::Bvh(_) | Config::KdTree => "baseline",
        }
    }

    pub(super) fn setting(self, base: &ResolvedParams) -> String {
        match self {
            Config::Knob(k) => k.setting(base),
            Config::Peer(k) => peer_names()[k].into(),
            Config::ScalarStep => "2:1 balanced (the paper), scalar step".into(),
            Config::Unconstrained => "unconstrained, ropes, scalar step".into(),
            Config::Bvh(b) => format!("BVH, {}", b.name()),
            Config::KdTree => "SAH kd-tree, Havran's depth and failures".into(),
        }
    }

    /// Builds this configuration on `mesh`, whose automatic parameters are `base`.
    pub(super) fn build(self, mesh: &Mesh, base: &ResolvedParams) -> anyhow::Result<Built> {
        // A bake, timed, with its file's size.
        let timed_bake = |params: &BuildParams| -> anyhow::Result<(Scene, f64, u64)> {
            let t = Instant::now();
            let baked = bake(mesh, params)?;
            let seconds = t.elapsed().as_secs_f64();
            let bytes = baked.to_file_bytes(0)?.len() as u64;
            Ok((Scene::from_baked(baked)?, seconds, bytes))
        };
        let octree = |params: &BuildParams, traced: fn(Arc<Scene>, Knob) -> Box<dyn Traced>, knob: Knob| {
            let (scene, seconds, bytes) = timed_bake(params)?;
            let stats = octrace_format::stats::SceneStatistics::compute(&scene.view())?;
            let scene = Arc::new(scene);
            anyhow::Ok(Built {
                traced: traced(scene.clone(), knob),
                seconds,
                bytes,
                nodes: stats.leaves,
                references_per_triangle: stats.triangle_references as f64 / stats.triangles.max(1) as f64,
                sah_cost: None,
                scene: Some(scene),
            })
        };
        let defaults = Knob::Defaults.params(base);
        Ok(match self {
            Config::Knob(knob) => {
                octree(&knob.params(base), |scene, knob| Box::new(OctreeTraced { scene, knob }), knob)?
            }
            Config::ScalarStep => octree(&defaults, |scene, _| Box::new(ScalarTraced(scene)), Knob::Defaults)?,
            Config::Unconstrained => {
                let t = Instant::now();
                let u = build_unbalanced(mesh, &defaults)?;
                let tree = UnconstrainedOctree::build(u.root_lo, u.root_size, &u.leaves, &u.triangles, &u.ids);
                let seconds = t.elapsed().as_secs_f64();
                let (bytes, nodes) = (tree.memory_bytes() as u64, tree.leaf_count() as u64);
                let refs = tree.references() as f64 / u.triangles.len().max(1) as f64;
                let traced = Box::new(Structure(tree));
                Built { traced, seconds, bytes, nodes, references_per_triangle: refs, sah_cost: None, scene: None }
            }
            Config::Peer(k) => {
                let (scene, ..) = timed_bake(&defaults)?;
                let peer = build_peers(&scene.view())?.swap_remove(k);
                let seconds = peer.build_seconds();
                let ids = scene.view().triangle_ids.to_vec();
                let traced = Box::new(PeerTraced { peer, ids });
                Built { traced, seconds, bytes: 0, nodes: 0, references_per_triangle: 0.0, sah_cost: None, scene: None }
            }
            Config::Bvh(build) => baseline(&timed_bake(&defaults)?.0, |t, ids| Bvh::build(t, ids, build)),
            Config::KdTree => baseline(&timed_bake(&defaults)?.0, KdTree::build),
        })
    }
}

/// A seed's baseline on the stored triangles of `scene` (degenerate ones left out, as
/// the octree does), timed.
fn baseline<B: Baseline + 'static>(scene: &Scene, build: impl FnOnce(&[[[f32; 3]; 3]], &[u32]) -> B) -> Built {
    let view = scene.view();
    let tris: Vec<[[f32; 3]; 3]> = view.stored_triangles().collect();
    let t = Instant::now();
    let b = build(&tris, view.triangle_ids);
    let seconds = t.elapsed().as_secs_f64();
    let (nodes, sah_cost) = (b.nodes() as u64, Some(b.sah_cost()));
    Built {
        traced: Box::new(Structure(b)),
        seconds,
        bytes: 0,
        nodes,
        references_per_triangle: 0.0,
        sah_cost,
        scene: None,
    }
}

/// An octree bake traced with a knob's tracer (batch calls).
struct OctreeTraced {
    scene: Arc<Scene>,
    knob: Knob,
}

impl Traced for OctreeTraced {
    fn answers(&self, rays: &[Ray], occlusion: bool) -> Vec<Answer> {
        tracer_answers(&self.knob.tracer(&self.scene), rays, occlusion)
    }
}

/// The defaults' bake walked by the scalar step, one ray at a time.
struct ScalarTraced(Arc<Scene>);

impl Traced for ScalarTraced {
    fn answers(&self, rays: &[Ray], occlusion: bool) -> Vec<Answer> {
        let tracer = self.0.tracer();
        let as_tuple = |h: Hit| (h.t, h.triangle, h.u, h.v);
        answers_by(rays, occlusion, |r| tracer.intersect_scalar(r).map(as_tuple), |r| tracer.occluded_scalar(r))
    }
}

/// What the report asks of a structure that answers one ray at a time.
pub(super) trait Baseline: Sync {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)>;
    fn occluded(&self, ray: &Ray) -> bool;
    fn nodes(&self) -> usize;
    fn sah_cost(&self) -> f64;
}

/// A structure answering one ray at a time.
struct Structure<B>(B);

impl<B: Baseline> Traced for Structure<B> {
    fn answers(&self, rays: &[Ray], occlusion: bool) -> Vec<Answer> {
        answers_by(rays, occlusion, |r| self.0.nearest(r), |r| self.0.occluded(r))
    }
}

impl Baseline for Bvh {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.intersect(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(self, ray)
    }
    fn nodes(&self) -> usize {
        self.node_count()
    }
    fn sah_cost(&self) -> f64 {
        Bvh::sah_cost(self)
    }
}

impl Baseline for KdTree {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.intersect(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        KdTree::occluded(self, ray)
    }
    fn nodes(&self) -> usize {
        self.node_count()
    }
    fn sah_cost(&self) -> f64 {
        KdTree::sah_cost(self)
    }
}

impl Baseline for UnconstrainedOctree {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.intersect(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        UnconstrainedOctree::occluded(self, ray)
    }
    fn nodes(&self) -> usize {
        self.leaf_count()
    }
    fn sah_cost(&self) -> f64 {
        0.0
    }
}

/// A peer's nearest hit: distance, stored triangle, barycentrics where the library
/// gives them.
type PeerHit = (f32, u32, Option<(f32, f32)>);

/// A peer library on the same triangles.
pub(super) trait Peer: Sync {
    fn build_seconds(&self) -> f64;
    fn nearest(&self, r: &Ray) -> Option<PeerHit>;
    fn occluded(&self, r: &Ray) -> bool;
}

/// A peer answering with input ids (`ids`: stored triangle to input id). A peer
/// without barycentrics gives the centre's: the oracle then decides edge ties.
struct PeerTraced {
    peer: Box<dyn Peer>,
    ids: Vec<u32>,
}

impl Traced for PeerTraced {
    fn answers(&self, rays: &[Ray], occlusion: bool) -> Vec<Answer> {
        let nearest = |r: &Ray| {
            self.peer.nearest(r).map(|(t, prim, uv)| {
                let (u, v) = uv.unwrap_or((0.3, 0.3));
                (t, self.ids[prim as usize], u, v)
            })
        };
        answers_by(rays, occlusion, nearest, |r| self.peer.occluded(r))
    }
}

#[cfg(feature = "obvhs")]
impl Peer for crate::peer::Peer {
    fn build_seconds(&self) -> f64 {
        self.build_time.as_secs_f64()
    }
    fn nearest(&self, r: &Ray) -> Option<PeerHit> {
        crate::peer::Peer::nearest(self, r).map(|(t, prim)| (t, prim, None))
    }
    fn occluded(&self, r: &Ray) -> bool {
        crate::peer::Peer::occluded(self, r)
    }
}

#[cfg(feature = "embree")]
impl Peer for crate::embree::Embree {
    fn build_seconds(&self) -> f64 {
        self.build_time.as_secs_f64()
    }
    fn nearest(&self, r: &Ray) -> Option<PeerHit> {
        crate::embree::Embree::nearest(self, r).map(|(t, prim, u, v)| (t, prim, Some((u, v))))
    }
    fn occluded(&self, r: &Ray) -> bool {
        crate::embree::Embree::occluded(self, r)
    }
}

/// The names of the peers this build has, in `build_peers`' order.
// Pushes under features: some builds push nothing, others one or three.
#[allow(clippy::vec_init_then_push)]
fn peer_names() -> Vec<&'static str> {
    #[allow(unused_mut)]
    let mut names = Vec::new();
    #[cfg(feature = "obvhs")]
    names.push("obvhs CWBVH (Möller-Trumbore f32)");
    #[cfg(feature = "embree")]
    names.extend(["Embree 3 BVH, fast mode", "Embree 3 BVH, robust mode"]);
    names
}

/// The peers this build has (cargo features `obvhs`, on by default, and `embree`),
/// built on the view's triangles.
#[allow(clippy::vec_init_then_push)]
fn build_peers(view: &octrace_format::SceneView<'_>) -> anyhow::Result<Vec<Box<dyn Peer>>> {
    #[allow(unused_mut)]
    let mut peers: Vec<Box<dyn Peer>> = Vec::new();
    #[cfg(feature = "obvhs")]
    peers.push(Box::new(crate::peer::Peer::build(view)));
    #[cfg(feature = "embree")]
    for robust in [false, true] {
        peers.push(Box::new(crate::embree::Embree::build(view, robust)?));
    }
    let _ = view;
    Ok(peers)
}
