//! Worlds of instances: baked scenes, each opened once and shared, placed many times
//! by affine transforms, moved between frames and traced as one scene.
//!
//! A [`World`] holds instances of [`Scene`]s (`Arc`s: one file's arrays for all its
//! instances) and a top level, a BVH over the instances' world boxes built by binned
//! SAH. Edits (`add`, `set_transform`, `remove`) are staged; [`World::commit`] makes
//! them visible to the queries at once: it refits the top level's boxes where only
//! placements changed (rebuilding it when the refit tree's SAH cost passes twice its
//! build's) and rebuilds it where instances came or went. Queries see the last
//! commit, never a half-made edit.
//!
//! # What a query answers
//! A ray is carried into an instance's space (origin and direction through the
//! inverse transform in `f64`, each rounded once to `f32`; the direction is not
//! normalised, so distances along the ray are the same numbers in both spaces) and
//! traced there by the instance's own walk, with its guarantees (watertight, the
//! exact test): within an instance, the answers are its scene's for that rounded
//! ray. From far away (more than two of the instance box's diagonals), the origin is
//! first moved along the ray to just before the box, in `f64`, and the hit's distance
//! shifted back (rounded once): the carried origin then rounds at the instance's
//! scale, not the distance's. Against the same triangles placed and baked into one file, a nearest hit's
//! distance differs by the rounding of the carried ray (some `f32` ulps of the
//! origin's and the hit's coordinates, over the cosine of the angle of incidence),
//! and a ray within that of a triangle's edge may hit the neighbouring triangle.
//! Of hits at the same distance in two instances, the lower instance id is the
//! nearest hit; where instances overlap, each answers for its own triangles (nothing
//! is made watertight across them).
//!
//! The queries: nearest and any hit ([`World::intersect`], [`World::occluded`] and
//! their batches), every crossing in order merged across instances
//! ([`World::crossings`]) and their counts ([`World::count_crossings`]),
//! inside/outside ([`World::contains`]: inside some closed instance), and closest
//! points ([`World::closest_point`]: each instance searched in its own space, or
//! where its placement stretches distances, its placed triangles measured in the
//! world). The effects renderer draws a world
//! ([`crate::render::effects::render_effects_world`]): each instance's materials,
//! textures and lights, placed. On the GPU (the `gpu` feature), `GpuWorld` answers
//! the ray queries with the instances' walks in the kernel, the CPU's answers bit
//! for bit.
//!
//! [`World::open`] opens an instanced file (`octrace_format::instanced`: a glTF's
//! meshes placed many times, each baked once): its scenes, and its instances with
//! the materials each draws ([`World::add_with_materials`]).
//!
//! ```
//! use std::sync::Arc;
//! use octrace_bake::{bake, procedural, BuildParams};
//! use octrace_runtime::world::{Transform, World};
//! use octrace_runtime::{glam::Vec3, Ray, Scene};
//! let ball = Arc::new(Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?);
//! let mut world = World::new();
//! let left = world.add(&ball, Transform::translation([-3.0, 0.0, 0.0]))?;
//! let right = world.add(&ball, Transform::translation([3.0, 0.0, 0.0]))?;
//! world.commit();
//! let ray = Ray::new(Vec3::new(3.0, 0.0, -5.0), Vec3::Z);
//! assert_eq!(world.intersect(&ray).map(|h| h.instance), Some(right));
//! world.set_transform(left, Transform::translation([3.0, 0.0, -2.5]))?; // in front
//! world.commit();
//! assert_eq!(world.intersect(&ray).map(|h| h.instance), Some(left));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod file;
#[cfg(feature = "gpu")]
mod gpu;
mod rounds;
mod top;
mod transform;

use std::collections::HashMap;
use std::sync::Arc;

use glam::Vec3;
use rayon::prelude::*;

#[cfg(feature = "gpu")]
pub use gpu::{GpuWorld, GpuWorldTimings};
pub use transform::Transform;

use crate::cpu::{ClosestPoint, Crossing, CrossingCount};
use crate::error::{Error, Result};
use crate::ray::{Hit, Ray};
use crate::surface::HitSurface;
use crate::Scene;
use octrace_format::StoredIndex;
use rounds::{Boxes, OnCpu};
use top::{Aabb, Top};

/// A crossing of a world's triangles ([`World::crossings`]): the instance, and the
/// crossing in its scene's terms (`t` along the world's ray, `enters` the placed
/// triangle's side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldCrossing {
    /// The instance's id.
    pub instance: u32,
    /// The crossing.
    pub crossing: Crossing,
}

/// The boxes a ray's batch rounds take at most ([`World::intersect_batch`]); a ray
/// whose walk enters more is finished by the one-ray walk within its nearest hit.
const FIRST_BOXES: usize = 8;

/// Where only whether there is a hit counts.
const NO_HIT: Hit = Hit { t: 0.0, triangle: u32::MAX, u: 0.0, v: 0.0, leaf: 0, prim: StoredIndex(u32::MAX) };

/// The rays [`World::intersect_batch`] takes on one thread at a time.
pub const PIECE: usize = 4096;

/// A nearest hit in a world: the instance, and the hit in its scene's terms
/// (`hit.t` is the distance along the world's ray; `hit.triangle` and `hit.prim`
/// index the instance's scene). [`World::surface`] gives the point and normals in
/// world space, the part and the material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldHit {
    /// The instance's id ([`World::add`]'s).
    pub instance: u32,
    /// The hit in the instance's scene.
    pub hit: Hit,
}

impl WorldHit {
    /// Whether this hit is the nearer of it and `best`: the lower distance, and of
    /// equal ones the lower instance id (the one rule every query keeps).
    #[inline]
    fn beats(&self, best: Option<WorldHit>) -> bool {
        best.is_none_or(|b| self.hit.t < b.hit.t || self.hit.t == b.hit.t && self.instance < b.instance)
    }
}

/// A closest point in a world ([`World::closest_point`]): the instance, and the
/// closest point in world terms (`closest.point` and `closest.distance` in the
/// world; `triangle`, `prim`, `u` and `v` of the instance's scene).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldClosest {
    /// The instance's id.
    pub instance: u32,
    /// The closest point.
    pub closest: ClosestPoint,
}

/// An instance as the queries read it.
#[derive(Clone, Copy, Debug)]
struct Placed {
    scene: u32,
    to_world: Transform,
    to_local: Transform,
    bounds: Aabb,
    /// Bounds on the factor the placement scales lengths by (`stretch_of`).
    stretch: [f64; 2],
    /// A positive lower bound on that factor (the least singular value of the linear
    /// part), for searches through a stretching placement.
    least: f64,
    /// How far rounding a placed vertex to `f32` can move it.
    slack: f64,
}

/// A placement scales distances evenly where its least and greatest factors on
/// lengths are this close (relative): a rotation given in `f32` (orthogonal to about
/// `1e-7`) is one.
const EVEN: f64 = 1e-6;

/// Bounds on the factors by which `t` scales lengths (its linear part's singular
/// values): Gershgorin's disks of `LᵀL`, exact for a diagonal `L` and tight for a
/// rotation times a uniform scale.
fn stretch_of(t: &Transform) -> [f64; 2] {
    let l = |i: usize, j: usize| t.rows[i][j];
    let m = |a: usize, b: usize| (0..3).map(|i| l(i, a) * l(i, b)).sum::<f64>();
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for a in 0..3 {
        let off: f64 = (0..3).filter(|&b| b != a).map(|b| m(a, b).abs()).sum();
        lo = lo.min(m(a, a) - off);
        hi = hi.max(m(a, a) + off);
    }
    [lo.max(0.0).sqrt(), hi.sqrt()]
}

/// Checks that every entry of `map` names a material of `scene`.
fn check_map(scene: &Scene, map: &[u32]) -> Result<()> {
    let count = scene.view().shading.materials.len();
    match map.iter().enumerate().find(|(_, &m)| m as usize >= count) {
        Some((entry, &material)) => Err(Error::MaterialMap { entry, material, materials: count }),
        None => Ok(()),
    }
}

/// Baked scenes placed by transforms and traced as one (see the module's text).
#[derive(Default)]
pub struct World {
    scenes: Vec<Arc<Scene>>,
    /// Each scene's index in `scenes`, by its address.
    scene_ids: HashMap<usize, u32>,
    /// The committed instances, by id (`None`: removed).
    placed: Vec<Option<Placed>>,
    /// Their boxes (empty for removed ones), as the top level reads them.
    boxes: Vec<Aabb>,
    top: Top,
    /// Edits since the last commit, in order.
    staged: Vec<(u32, Option<Placed>)>,
    /// Each id's scene as the edits leave it (`None`: removed).
    latest: Vec<Option<u32>>,
    /// Each id's material map ([`World::add_with_materials`]), where it has one.
    maps: Vec<Option<Arc<[u32]>>>,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("scenes", &self.scenes.len())
            .field("instances", &self.len())
            .field("staged", &self.staged.len())
            .finish()
    }
}

impl World {
    /// An empty world.
    pub fn new() -> World {
        World::default()
    }

    /// Places `scene` by `transform` (local to world); visible to queries after the
    /// next [`World::commit`]. Returns the instance's id (ids are never reused).
    ///
    /// # Errors
    /// [`Error::Transform`] where the transform cannot be inverted in `f64` or places
    /// the scene's box beyond `f32`'s range.
    pub fn add(&mut self, scene: &Arc<Scene>, transform: Transform) -> Result<u32> {
        self.insert(scene, transform, None)
    }

    /// [`World::add`] with a material map: the instance draws material `materials[k]`
    /// of its scene wherever the scene has material `k` (an entry past the map's end
    /// keeps its own). An instanced file's placements of one mesh with different
    /// materials are such instances. Instances given the same `Arc` share it. The map
    /// changes what the renderer draws and the material [`World::surface`] names; no
    /// geometric query reads it.
    ///
    /// # Errors
    /// As [`World::add`]; [`Error::MaterialMap`] where an entry names a material the
    /// scene does not have.
    ///
    /// # Example
    /// ```
    /// use std::sync::Arc;
    /// use octrace_runtime::world::{Transform, World};
    /// let mut scene = octrace_format::testing::single_leaf_scene();
    /// scene.shading.materials = vec![Default::default(), Default::default()];
    /// scene.material_ids = vec![0];
    /// let scene = Arc::new(octrace_runtime::Scene::from_baked(scene)?);
    /// let mut world = World::new();
    /// let blue = world.add_with_materials(&scene, Transform::IDENTITY, &Arc::from([1]))?;
    /// world.commit();
    /// assert_eq!(world.materials(blue), Some(&[1u32][..]));
    /// assert!(world.add_with_materials(&scene, Transform::IDENTITY, &Arc::from([2])).is_err());
    /// # Ok::<(), octrace_runtime::Error>(())
    /// ```
    pub fn add_with_materials(
        &mut self,
        scene: &Arc<Scene>,
        transform: Transform,
        materials: &Arc<[u32]>,
    ) -> Result<u32> {
        check_map(scene, materials)?;
        self.insert(scene, transform, (!materials.is_empty()).then(|| Arc::clone(materials)))
    }

    /// Places `scene` with `map` (checked against it by the caller).
    fn insert(&mut self, scene: &Arc<Scene>, transform: Transform, map: Option<Arc<[u32]>>) -> Result<u32> {
        let key = Arc::as_ptr(scene) as usize;
        let index = match self.scene_ids.get(&key) {
            Some(&i) => i,
            None => {
                let i = self.scenes.len() as u32;
                self.scenes.push(Arc::clone(scene));
                self.scene_ids.insert(key, i);
                i
            }
        };
        let placed = self.place(index, transform)?;
        let id = u32::try_from(self.latest.len()).ok().filter(|&id| id < u32::MAX).ok_or(Error::Transform {
            what: "a new instance".into(),
            reason: "a world holds at most 2^32 - 1 instances",
        })?;
        self.latest.push(Some(index));
        self.maps.push(map);
        self.staged.push((id, Some(placed)));
        Ok(id)
    }

    /// Moves instance `id` to `transform`, at the next commit.
    ///
    /// # Errors
    /// [`Error::NoInstance`] where the world holds no such instance; [`Error::Transform`]
    /// as [`World::add`].
    pub fn set_transform(&mut self, id: u32, transform: Transform) -> Result<()> {
        let scene = self.latest.get(id as usize).copied().flatten().ok_or(Error::NoInstance { id })?;
        let placed = self.place(scene, transform)?;
        self.staged.push((id, Some(placed)));
        Ok(())
    }

    /// Removes instance `id`, at the next commit.
    ///
    /// # Errors
    /// [`Error::NoInstance`] where the world holds no such instance.
    pub fn remove(&mut self, id: u32) -> Result<()> {
        match self.latest.get_mut(id as usize) {
            Some(slot @ Some(_)) => *slot = None,
            _ => return Err(Error::NoInstance { id }),
        }
        self.staged.push((id, None));
        Ok(())
    }

    /// Makes the staged edits visible: the top level refit where only placements
    /// changed (rebuilt where that tree's SAH cost passes twice its build's), rebuilt
    /// where instances came or went.
    pub fn commit(&mut self) {
        if self.staged.is_empty() {
            return;
        }
        let mut rebuild = self.placed.is_empty();
        for (id, edit) in self.staged.drain(..) {
            let id = id as usize;
            if id >= self.placed.len() {
                self.placed.resize(id + 1, None);
                self.boxes.resize(id + 1, Aabb::EMPTY);
            }
            rebuild |= self.placed[id].is_some() != edit.is_some();
            self.boxes[id] = edit.map_or(Aabb::EMPTY, |p| p.bounds);
            self.placed[id] = edit;
        }
        if rebuild || !self.top.refit(&self.boxes) {
            let live = (0..self.placed.len() as u32).filter(|&id| self.placed[id as usize].is_some()).collect();
            self.top = Top::build(&self.boxes, live);
        }
    }

    /// The committed instances.
    pub fn len(&self) -> usize {
        self.placed.iter().flatten().count()
    }

    /// Whether no instance is committed.
    pub fn is_empty(&self) -> bool {
        self.placed.iter().all(Option::is_none)
    }

    /// Instance `id`'s scene and placement, as committed.
    pub fn instance(&self, id: u32) -> Option<(&Arc<Scene>, Transform)> {
        let p = self.placed.get(id as usize)?.as_ref()?;
        Some((&self.scenes[p.scene as usize], p.to_world))
    }

    /// Instance `id`'s material map ([`World::add_with_materials`]; empty where it has
    /// none), or `None` where the world holds no such instance (as committed).
    pub fn materials(&self, id: u32) -> Option<&[u32]> {
        self.placed.get(id as usize)?.as_ref()?;
        Some(self.maps.get(id as usize)?.as_deref().unwrap_or(&[]))
    }

    /// The box of the committed instances' world boxes (each rounded outward), or
    /// `None` for an empty world.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let live = self.placed.iter().flatten();
        live.map(|p| (p.bounds.lo, p.bounds.hi)).reduce(|(lo, hi), (l, h)| {
            (std::array::from_fn(|k| lo[k].min(l[k])), std::array::from_fn(|k| hi[k].max(h[k])))
        })
    }

    /// Instance `id`'s scene (its index in [`World::scenes`]) and its placement both
    /// ways, as committed.
    pub(crate) fn placement(&self, id: u32) -> Option<(u32, Transform, Transform)> {
        let p = self.placed.get(id as usize)?.as_ref()?;
        Some((p.scene, p.to_world, p.to_local))
    }

    /// The scenes the world has held, each once (instances of one scene share it).
    pub fn scenes(&self) -> &[Arc<Scene>] {
        &self.scenes
    }

    /// Each committed instance's id and its scene's index in [`World::scenes`].
    pub(crate) fn placed_scenes(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.placed.iter().enumerate().filter_map(|(id, p)| p.map(|p| (id as u32, p.scene)))
    }

    /// The bytes the world itself takes (its scenes' not counted: they are shared).
    pub fn bytes(&self) -> usize {
        self.placed.len() * (std::mem::size_of::<Option<Placed>>() + std::mem::size_of::<Aabb>())
            + self.top.bytes()
            + self.latest.len() * std::mem::size_of::<Option<u32>>()
            + self.maps.len() * std::mem::size_of::<Option<Arc<[u32]>>>()
    }

    /// The nearest hit of `ray` in `[tmin, tmax]` (see the module's text).
    pub fn intersect(&self, ray: &Ray) -> Option<WorldHit> {
        self.intersect_from(ray, None, &[])
    }

    /// [`World::intersect`] given the nearest hit `best` among the instances `asked`
    /// (skipped): the same answer.
    fn intersect_from(&self, ray: &Ray, mut best: Option<WorldHit>, asked: &[u32]) -> Option<WorldHit> {
        if !ray.is_traceable() {
            return None;
        }
        let o = ray.origin.to_array();
        let d = ray.dir.to_array();
        let reach = best.map_or(ray.tmax, |b| b.hit.t);
        self.top.walk(o, d, ray.tmin, reach, |id, _, tmax| {
            if asked.contains(&id) {
                return false;
            }
            let Some(p) = &self.placed[id as usize] else { return false };
            let local = carried(p, ray, *tmax);
            if let Some(hit) = self.scenes[p.scene as usize].intersect(&local.ray).and_then(|h| local.back(h, *tmax)) {
                let this = WorldHit { instance: id, hit };
                if this.beats(best) {
                    best = Some(this);
                    *tmax = hit.t;
                }
            }
            false
        });
        best
    }

    /// Whether anything lies on `ray` in `[tmin, tmax]`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.occluded_from(ray, &[])
    }

    /// [`World::occluded`] but for the instances `asked` (found not to occlude it).
    fn occluded_from(&self, ray: &Ray, asked: &[u32]) -> bool {
        if !ray.is_traceable() {
            return false;
        }
        let mut found = false;
        self.top.walk(ray.origin.to_array(), ray.dir.to_array(), ray.tmin, ray.tmax, |id, _, tmax| {
            if asked.contains(&id) {
                return false;
            }
            let Some(p) = &self.placed[id as usize] else { return false };
            let local = carried(p, ray, *tmax);
            let scene = &self.scenes[p.scene as usize];
            // Any blocker within the carried ray's reach; where the one found lies in
            // its margin past `tmax`, the nearest decides.
            found = scene.tracer().occluder(&local.ray).is_some_and(|h| {
                local.back(h, *tmax).is_some()
                    || scene.intersect(&local.ray).and_then(|h| local.back(h, *tmax)).is_some()
            });
            found
        });
        found
    }

    /// Every crossing of `ray` with the world's triangles in `[tmin, tmax]`, in order
    /// along it (of equal distances, the lower instance first), each instance's once
    /// as its scene's [`Scene::crossings`] says; `enters` is the placed triangle's
    /// (turned for a mirroring transform). Where instances overlap, each crosses on
    /// its own: nothing is merged across them.
    pub fn crossings(&self, ray: &Ray) -> Vec<WorldCrossing> {
        let mut out = Vec::new();
        self.crossings_from(ray, &[], &mut out);
        // Stable: an instance's own crossings keep their order.
        out.sort_by(|a, b| a.crossing.t.total_cmp(&b.crossing.t).then(a.instance.cmp(&b.instance)));
        out
    }

    /// The crossings of `ray` with the instances its walk enters but those `asked`,
    /// appended to `out` unsorted (each instance's in its own order).
    pub(crate) fn crossings_from(&self, ray: &Ray, asked: &[u32], out: &mut Vec<WorldCrossing>) {
        if !ray.is_traceable() {
            return;
        }
        self.top.walk(ray.origin.to_array(), ray.dir.to_array(), ray.tmin, ray.tmax, |id, _, _| {
            if asked.contains(&id) {
                return false;
            }
            let Some(p) = &self.placed[id as usize] else { return false };
            let local = carried(p, ray, ray.tmax);
            p.placed_crossings(id, &local, ray.tmax, &self.scenes[p.scene as usize].crossings(&local.ray), out);
            false
        });
    }

    /// How many times `ray` crosses the world's triangles in `[tmin, tmax]`, and how
    /// many of those arrive on a placed triangle's front ([`World::crossings`]).
    pub fn count_crossings(&self, ray: &Ray) -> CrossingCount {
        self.count_crossings_from(ray, &[])
    }

    /// [`World::count_crossings`] of the instances but those `asked`.
    pub(crate) fn count_crossings_from(&self, ray: &Ray, asked: &[u32]) -> CrossingCount {
        let mut count = CrossingCount::default();
        if !ray.is_traceable() {
            return count;
        }
        self.top.walk(ray.origin.to_array(), ray.dir.to_array(), ray.tmin, ray.tmax, |id, _, _| {
            if asked.contains(&id) {
                return false;
            }
            let Some(p) = &self.placed[id as usize] else { return false };
            let local = carried(p, ray, ray.tmax);
            let scene = &self.scenes[p.scene as usize];
            let c = if local.counted_by_list(ray.tmax) {
                local.count_of_list(ray.tmax, &scene.crossings(&local.ray))
            } else {
                scene.tracer().count_crossings(&local.ray)
            };
            let c = p.placed_count(c);
            count.total += c.total;
            count.entries += c.entries;
            false
        });
        count
    }

    /// [`World::count_crossings`] for many rays, on all cores.
    pub fn count_crossings_batch(&self, rays: &[Ray]) -> Vec<CrossingCount> {
        rays.par_iter().with_min_len(64).map(|r| self.count_crossings(r)).collect()
    }

    /// Whether `p` lies inside some closed instance: its scene's exact
    /// [`Scene::contains`] at `p` carried into the instance's space (in `f64`,
    /// rounded once: a point within that rounding of an instance's surface may be
    /// answered as the point beside it). Instances of scenes that are not closed
    /// contain nothing.
    pub fn contains(&self, p: [f32; 3]) -> bool {
        if !p.iter().all(|c| c.is_finite()) {
            return false;
        }
        let mut inside = false;
        self.top.holding(p, |id| {
            if inside {
                return;
            }
            let Some(placed) = &self.placed[id as usize] else { return };
            let local = placed.to_local.point(p.map(f64::from)).map(|c| c as f32);
            inside = self.scenes[placed.scene as usize].contains(local).unwrap_or(false);
        });
        inside
    }

    /// [`World::contains`] for many points, on all cores.
    pub fn contains_batch(&self, points: &[[f32; 3]]) -> Vec<bool> {
        points.par_iter().with_min_len(256).map(|p| self.contains(*p)).collect()
    }

    /// The point of the world's surface closest to `p`, of every instance's triangles
    /// (see [`World::closest_point_within`]).
    ///
    /// # Errors
    /// As [`World::closest_point_within`].
    pub fn closest_point(&self, p: [f32; 3]) -> Result<Option<WorldClosest>> {
        self.closest_point_within(p, f32::INFINITY)
    }

    /// The closest point of the world's surface to `p` if it lies at most
    /// `max_distance` away: instances taken nearest box first, each searched within the
    /// best distance so far by its scene's exact search over its own tree. Where the
    /// placement scales distances evenly (rotations, mirrors, uniform scales and
    /// translations), `p` is carried into the instance's space (in `f64`, rounded once),
    /// searched there ([`Scene::closest_point_within`]), and the point carried back to
    /// the world in `f64` and its distance measured there (rounded once): against the
    /// same triangles placed and baked into one file, the distance differs by the
    /// rounding of the carried point (`f32` ulps of its local coordinates, times the
    /// placement's scale), and of two triangles as near as that either may answer.
    /// Where it stretches them unevenly, the search measures the placed triangles
    /// themselves (each vertex carried in `f64`, rounded to `f32`, as a bake of them
    /// stores it) from `p` in the world, pruning the tree's nodes by their distance
    /// times the placement's least scale: the baked file's answer, its distance
    /// correctly rounded. Of equally near points the lower instance id's. `None` for a
    /// point that is not finite, an empty world, or nothing within `max_distance`.
    ///
    /// # Errors
    /// [`Error::Alloc`] where a scene's search tree cannot be made.
    pub fn closest_point_within(&self, p: [f32; 3], max_distance: f32) -> Result<Option<WorldClosest>> {
        if !p.iter().all(|c| c.is_finite()) || max_distance.is_nan() {
            return Ok(None);
        }
        let pw = p.map(f64::from);
        let mut best: Option<WorldClosest> = None;
        let mut failed = None;
        self.top.nearest(p, f64::from(max_distance), |id, _| {
            let bound = best.map_or(max_distance, |b| b.closest.distance);
            let Some(placed) = &self.placed[id as usize] else { return f64::from(bound) };
            let scene = &self.scenes[placed.scene as usize];
            let found = if placed.even() {
                // In the instance's space: every point of the instance within `bound`
                // of p in the world lies within bound / (least scale) of p's carried
                // point, less its rounding.
                let local = placed.to_local.point(pw).map(|c| c as f32);
                let rounding = local.iter().fold(0.0f64, |m, c| m.max(f64::from(c.abs()))) * f64::from(f32::EPSILON);
                let reach = (f64::from(bound) / placed.stretch[0] * (1.0 + 1e-5) + 2.0 * rounding) as f32;
                scene.closest_point_checked(local, reach.next_up()).map(|found| {
                    found.map(|c| {
                        let at = placed.to_world.point(c.point.map(f64::from));
                        let distance = (0..3).map(|k| (at[k] - pw[k]).powi(2)).sum::<f64>().sqrt() as f32;
                        ClosestPoint { distance, point: at.map(|x| x as f32), ..c }
                    })
                })
            } else {
                // Stretched: the placed triangles measured in the world.
                scene.closest_point_placed(p, &placed.to_world, &placed.to_local, placed.least, placed.slack, bound)
            };
            let found = found.unwrap_or_else(|e| {
                failed.get_or_insert(e);
                None
            });
            if let Some(closest) = found {
                let d = closest.distance;
                let nearer = best.is_none_or(|b| d < b.closest.distance || d == b.closest.distance && id < b.instance);
                if d <= max_distance && nearer {
                    best = Some(WorldClosest { instance: id, closest });
                }
            }
            f64::from(best.map_or(max_distance, |b| b.closest.distance))
        });
        match failed {
            Some(e) => Err(e),
            None => Ok(best),
        }
    }

    /// [`World::closest_point_within`] for many points, on all cores. The points are
    /// taken along a space-filling curve through the world's box (neighbours share
    /// instances' trees in cache, as the scene's batch does), the answers written
    /// where their points are.
    ///
    /// # Errors
    /// As [`World::closest_point_within`]; [`Error::Alloc`] where the answers' memory
    /// cannot be had.
    pub fn closest_points_batch(&self, points: &[[f32; 3]], max_distance: f32) -> Result<Vec<Option<WorldClosest>>> {
        let mut out = octrace_format::memory::try_vec(points.len(), "closest points")?;
        let each = |points: &[[f32; 3]], out: &mut [Option<WorldClosest>]| {
            out.par_iter_mut().zip(points.par_iter()).with_min_len(64).try_for_each(|(o, p)| {
                *o = self.closest_point_within(*p, max_distance)?;
                Ok::<(), Error>(())
            })
        };
        let Some((lo, hi)) = self.bounds() else {
            each(points, &mut out)?;
            return Ok(out);
        };
        let mut done = Ok(());
        crate::cpu::along_curve(lo.map(f64::from), hi.map(f64::from), points, &mut out, |p, o| done = each(p, o));
        done.map(|()| out)
    }

    /// [`World::intersect`] for many rays, on all cores, with the same answers: in
    /// pieces of [`PIECE`] rays, each ray's first instances (the first eight boxes its
    /// walk enters, nearest first) taken in rounds, a round's rays grouped by
    /// instance and walked by the instance's batch walk (sixteen rays at a time),
    /// each ray's reach shortened by its nearest hit so far; a ray whose walk enters
    /// more boxes is finished by the one-ray walk within that reach.
    pub fn intersect_batch(&self, rays: &[Ray]) -> Vec<Option<WorldHit>> {
        let mut out = vec![None; rays.len()];
        out.par_chunks_mut(PIECE).zip(rays.par_chunks(PIECE)).for_each(|(out, rays)| self.piece(false, rays, out));
        out
    }

    /// [`World::occluded`] for many rays, on all cores, with the same answers: as
    /// [`World::intersect_batch`], each ray done at its first blocker.
    pub fn occluded_batch(&self, rays: &[Ray]) -> Vec<bool> {
        let mut out = vec![None; rays.len()];
        out.par_chunks_mut(PIECE).zip(rays.par_chunks(PIECE)).for_each(|(out, rays)| self.piece(true, rays, out));
        out.iter().map(Option::is_some).collect()
    }

    /// [`World::intersect_batch`] (or, `any`, a blocker for [`World::occluded_batch`])
    /// on this thread, for one piece.
    fn piece(&self, any: bool, rays: &[Ray], out: &mut [Option<WorldHit>]) {
        let boxes = Boxes::of(self, rays, FIRST_BOXES);
        let Ok(()) = self.rounds(any, rays, &boxes, out, &mut OnCpu);
        self.finish_all(any, rays, &boxes, out);
    }

    /// The surface at `hit` in world space: the point carried by the instance's
    /// transform (in `f64`, rounded once; `point_error` grows by the transform's
    /// scale and that rounding), the normals by its inverse transpose (normalised;
    /// the geometric normal is that of the placed triangle's vertices in order, so a
    /// mirroring transform turns it), and the part and material of the instance's
    /// scene; `None` where the world holds no such instance (removed since).
    pub fn surface(&self, hit: &WorldHit) -> Option<HitSurface> {
        let p = self.placed.get(hit.instance as usize).copied().flatten()?;
        let mut s = self.scenes[p.scene as usize].surface(&hit.hit);
        if let Some(map) = &self.maps[hit.instance as usize] {
            s.material = s.material.map(|m| octrace_format::instanced::drawn(map, m));
        }
        let wide = |v: Vec3| v.to_array().map(f64::from);
        let point = p.to_world.point(wide(s.point));
        let e = wide(s.point_error);
        let rows = &p.to_world.rows;
        s.point_error = Vec3::from_array(std::array::from_fn(|i| {
            let carried = rows[i][0].abs() * e[0] + rows[i][1].abs() * e[1] + rows[i][2].abs() * e[2];
            (carried + point[i].abs() * f64::from(f32::EPSILON)) as f32
        }));
        s.point = Vec3::from_array(point.map(|c| c as f32));
        let flip = if p.to_world.determinant() < 0.0 { -1.0 } else { 1.0 };
        let normal = |n: Vec3| {
            let n = wide(n);
            let m = &p.to_local.rows;
            let w: [f64; 3] = std::array::from_fn(|i| m[0][i] * n[0] + m[1][i] * n[1] + m[2][i] * n[2]);
            let len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            if len > 0.0 && len.is_finite() {
                Vec3::from_array(w.map(|c| (c / len) as f32))
            } else {
                Vec3::ZERO
            }
        };
        s.geometric_normal = normal(s.geometric_normal) * flip;
        s.shading_normal = normal(s.shading_normal);
        if s.shading_normal.dot(s.geometric_normal) < 0.0 {
            s.shading_normal = -s.shading_normal;
        }
        Some(s)
    }

    /// Scene `scene` placed by `transform`: its inverse and its world box.
    fn place(&self, scene: u32, to_world: Transform) -> Result<Placed> {
        let to_local = to_world.inverse()?;
        let view = self.scenes[scene as usize].view();
        let (lo, hi) = crate::cpu::mesh_box(&view);
        let (mut wlo, mut whi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for corner in 0..8 {
            let c = [0, 1, 2].map(|k| f64::from(if corner >> k & 1 == 0 { lo[k] } else { hi[k] }));
            let w = to_world.point(c);
            for k in 0..3 {
                wlo[k] = wlo[k].min(w[k]);
                whi[k] = whi[k].max(w[k]);
            }
        }
        // A margin for the rounding of the carried rays and of the corners' products.
        let reach = (0..3).fold(0.0f64, |m, k| m.max(wlo[k].abs()).max(whi[k].abs()).max(whi[k] - wlo[k]));
        let margin = reach * 1e-6;
        let bounds = Aabb {
            lo: wlo.map(|c| ((c - margin) as f32).next_down()),
            hi: whi.map(|c| ((c + margin) as f32).next_up()),
        };
        if !bounds.lo.iter().chain(&bounds.hi).all(|c| c.is_finite()) {
            return Err(Error::Transform {
                what: format!("{:?}", to_world.rows),
                reason: "it places the scene's box beyond f32's range",
            });
        }
        let stretch = stretch_of(&to_world);
        // The least singular value is at least 1 / |L⁻¹|_F (the inverse's spectral
        // norm is at most its Frobenius norm).
        let inverse = to_local.rows.iter().flat_map(|r| &r[..3]).map(|x| x * x).sum::<f64>().sqrt();
        let least = stretch[0].max(1.0 / inverse * (1.0 - 1e-9));
        let coordinate = bounds.lo.iter().chain(&bounds.hi).fold(0.0f64, |m, c| m.max(f64::from(c.abs())));
        let slack = coordinate * f64::from(f32::EPSILON);
        Ok(Placed { scene, to_world, to_local, bounds, stretch, least, slack })
    }
}

impl Placed {
    /// Whether the placement scales distances evenly ([`EVEN`]).
    fn even(&self) -> bool {
        self.stretch[1] <= self.stretch[0] * (1.0 + EVEN)
    }

    /// A count of the carried ray's crossings as the placed triangles' (entries and
    /// exits swapped by a mirroring placement).
    #[inline]
    fn placed_count(&self, mut c: CrossingCount) -> CrossingCount {
        if self.to_world.determinant() < 0.0 {
            c.entries = c.total - c.entries;
        }
        c
    }

    /// Instance `id`'s crossings of the world's ray, from its scene's `crossings` of
    /// the carried ray `local` (those shifted back past `tmax` dropped, sides turned by
    /// a mirroring placement), appended to `out`.
    fn placed_crossings(
        &self,
        id: u32,
        local: &Carried,
        tmax: f32,
        crossings: &[Crossing],
        out: &mut Vec<WorldCrossing>,
    ) {
        let mirrored = self.to_world.determinant() < 0.0;
        for c in crossings {
            let Some(t) = local.back_t(c.t, tmax) else { continue };
            out.push(WorldCrossing { instance: id, crossing: Crossing { t, enters: c.enters != mirrored, ..*c } });
        }
    }
}

/// A ray carried into an instance's space, and how far along the world's ray its
/// origin was moved.
#[derive(Clone, Copy, Debug)]
struct Carried {
    ray: Ray,
    shift: f64,
}

impl Carried {
    /// A hit of the carried ray as a hit of the world's: its distance shifted back
    /// (in `f64`, rounded once), or `None` where that lies past `tmax`.
    #[inline]
    fn back(&self, hit: Hit, tmax: f32) -> Option<Hit> {
        if self.shift == 0.0 {
            return Some(hit);
        }
        Some(Hit { t: self.back_t(hit.t, tmax)?, ..hit })
    }

    /// Whether the carried ray's crossings are counted from its list: a moved origin's
    /// reach has a margin past a finite `tmax`, whose crossings are dropped.
    #[inline]
    fn counted_by_list(&self, tmax: f32) -> bool {
        self.shift != 0.0 && tmax != f32::INFINITY
    }

    /// The count of the carried ray's `crossings` that lie within `tmax` once shifted
    /// back.
    fn count_of_list(&self, tmax: f32, crossings: &[Crossing]) -> CrossingCount {
        let mut c = CrossingCount::default();
        for x in crossings {
            if self.back_t(x.t, tmax).is_some() {
                c.total += 1;
                c.entries += u32::from(x.enters);
            }
        }
        c
    }

    /// A distance along the carried ray as one along the world's, or `None` past
    /// `tmax`.
    #[inline]
    fn back_t(&self, t: f32, tmax: f32) -> Option<f32> {
        if self.shift == 0.0 {
            return Some(t);
        }
        let t = (self.shift + f64::from(t)) as f32;
        (t <= tmax).then_some(t)
    }
}

/// `ray` in instance `p`'s space, over `[ray.tmin, tmax]`: the origin and direction
/// through the inverse transform in `f64`, each rounded once (a direction past
/// `f32`'s range makes a ray that hits nothing). An origin more than two box
/// diagonals before the instance's box, where the ray's `tmin` lies before the box,
/// is first moved along the ray to just before the box (in `f64`): near the
/// instance, the carried origin's rounding is the instance's size rather than the
/// distance's, and its walk is the batch walk's (the octree walks origins from far
/// on a slower path of their own). The hit's distance is then shifted back.
#[inline]
fn carried(p: &Placed, ray: &Ray, tmax: f32) -> Carried {
    let wide = |v: Vec3| v.to_array().map(f64::from);
    let (o, d) = (wide(ray.origin), wide(ray.dir));
    let dir = Vec3::from_array(p.to_local.vector(d).map(|c| c as f32));
    let plain = || Carried {
        ray: Ray { origin: Vec3::from_array(p.to_local.point(o).map(|c| c as f32)), tmin: ray.tmin, dir, tmax },
        shift: 0.0,
    };
    // Where the ray enters the instance's world box.
    let (mut enter, mut extent2) = (f64::NEG_INFINITY, 0.0);
    for k in 0..3 {
        let (lo, hi) = (f64::from(p.bounds.lo[k]), f64::from(p.bounds.hi[k]));
        extent2 += (hi - lo) * (hi - lo);
        if d[k] != 0.0 {
            let (t0, t1) = ((lo - o[k]) / d[k], (hi - o[k]) / d[k]);
            enter = enter.max(t0.min(t1));
        } else if o[k] < lo || o[k] > hi {
            return plain();
        }
    }
    let length = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let extent = extent2.sqrt();
    // A hundredth of the box's diagonal before it.
    let shift = enter - 0.01 * extent / length;
    let far = shift * length > 2.0 * extent;
    if !(far && shift.is_finite() && f64::from(ray.tmin) <= shift && shift < f64::from(tmax)) {
        return plain();
    }
    let at = [0, 1, 2].map(|k| o[k] + shift * d[k]);
    // Every local distance whose shifted-back one rounds to at most `tmax`.
    let reach = if tmax == f32::INFINITY {
        f32::INFINITY
    } else {
        let ulp = f64::from(tmax.abs()) * f64::from(f32::EPSILON);
        ((f64::from(tmax) - shift + ulp) as f32).next_up()
    };
    Carried {
        ray: Ray { origin: Vec3::from_array(p.to_local.point(at).map(|c| c as f32)), tmin: 0.0, dir, tmax: reach },
        shift,
    }
}
