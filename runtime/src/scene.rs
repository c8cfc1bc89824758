//! A baked scene ready to trace: a thin layer over the format crate's file.

use std::path::Path;

use octrace_format::topology::EdgeCensus;
use octrace_format::{BakedScene, SceneFile, SceneView};

use crate::cpu::{BatchCrossings, ClosestPoint, Crossing, CrossingCount, LocateGrid, Solid, Tracer, TriangleTest};
use crate::error::{Error, Result};
use crate::ray::{Hit, Ray};
use crate::winding::{Accuracy, Winding, WindingTree};

enum Source {
    File(Box<SceneFile>),
    Baked(Box<BakedScene>),
}

/// A baked scene, from a file or from memory.
///
/// # Memory maps and files that change
/// [`Scene::open`] reads the file into memory and validates it: safe whatever happens
/// to the file afterwards. [`Scene::map`] memory-maps it instead (no copy, pages
/// loaded on demand) and is `unsafe` because the map is only sound while nobody
/// modifies or truncates the file: a change shows through the map after validation,
/// and a truncation makes reads past the new end raise `SIGBUS`. `octrace bake`
/// replaces files by renaming a new one over the old, which never changes an open
/// map; use [`Scene::open`] for files that other programs may rewrite in place.
///
/// Which to use:
/// * files that may change while open (a shared folder, a download in progress, a
///   file deployed with `cp`, which rewrites in place): [`Scene::open`];
/// * files this pipeline deploys by rename (`mv`, `octrace bake`) and never edits:
///   [`Scene::map`] (validated, about 0.1 s for a 100 MB file) or, for files baked or
///   validated earlier by the same pipeline, [`Scene::map_unchecked`] (microseconds);
/// * zstd-compressed files (`.oct.zst`) cannot be mapped: [`Scene::open`] reads them.
pub struct Scene {
    /// The tracer the one-ray calls use, made on the first: it borrows from `*inner`.
    /// Declared first, so that it is dropped before what it borrows.
    shared: std::sync::OnceLock<Tracer<'static>>,
    /// Boxed, so that what the shared tracer borrows stays put when the scene moves.
    inner: Box<Inner>,
}

/// What a scene owns.
struct Inner {
    source: Source,
    /// Point location's top levels, built on the first tracer.
    grid: std::sync::OnceLock<LocateGrid>,
    /// The fans of the crowded leaves, found with the first tracer.
    fans: std::sync::OnceLock<crate::cpu::FanIndex>,
    /// The tracers' frame, computed once.
    frame: std::sync::OnceLock<crate::cpu::TreeFrame>,
    /// The leaves' inside and outside labels, made on the first query that needs
    /// them (or why not: the scene is open).
    solid: std::sync::OnceLock<std::result::Result<crate::cpu::Solid, (u64, u64)>>,
    /// The stored triangles' edge census, counted on first use.
    edges: std::sync::OnceLock<EdgeCensus>,
    /// The closest-point search's bounds, made on its first query.
    bounds: std::sync::OnceLock<crate::cpu::SurfaceBounds>,
    /// The winding numbers' clusters, made on their first query.
    winding: std::sync::OnceLock<std::result::Result<crate::winding::WindingTree, octrace_format::memory::AllocError>>,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.view();
        f.debug_struct("Scene").field("leaves", &v.leaf_count()).field("triangles", &v.triangle_count()).finish()
    }
}

impl Scene {
    /// Reads and validates a `.oct` file into memory. On Linux the memory is backed by
    /// transparent huge pages where the kernel allows: for a scene larger than the
    /// processor's TLB reaches (tens of megabytes), walks run faster than on a
    /// [`Scene::map`] of the same file (the dragon's incoherent rays one a call:
    /// 0.76-0.86 against 0.64-0.74 Mrays/s here), at the cost of a private copy.
    ///
    /// # Errors
    /// The format crate's errors: I/O, bad magic, unsupported version, checksum,
    /// corrupt contents.
    pub fn open(path: impl AsRef<Path>) -> Result<Scene> {
        Ok(Scene::with(Source::File(Box::new(SceneFile::read(path)?))))
    }

    /// Memory-maps and validates a `.oct` file.
    ///
    /// # Safety
    /// The file must not be modified or truncated while the scene is alive; see the
    /// type's docs.
    ///
    /// # Errors
    /// As [`Scene::open`].
    pub unsafe fn map(path: impl AsRef<Path>) -> Result<Scene> {
        // SAFETY: forwarded to our caller.
        let file = unsafe { SceneFile::map(path)? };
        Ok(Scene::with(Source::File(Box::new(file))))
    }

    /// Memory-maps a `.oct` file checking its header and the archive's structure only,
    /// not its checksums or semantic rules: microseconds whatever the size. The trusted
    /// path, for files this pipeline baked. A file that breaks the semantic rules gives
    /// wrong answers or misses through it, never a panic, a hang or a read out of
    /// bounds (see `octrace_format::SceneFile::map_unchecked`).
    ///
    /// # Safety
    /// As [`Scene::map`]: the file must not be modified or truncated while the scene is
    /// alive.
    ///
    /// # Errors
    /// I/O, header and archive-structure errors.
    pub unsafe fn map_unchecked(path: impl AsRef<Path>) -> Result<Scene> {
        // SAFETY: forwarded to our caller.
        let file = unsafe { SceneFile::map_unchecked(path)? };
        Ok(Scene::with(Source::File(Box::new(file))))
    }

    /// Validates a whole file held in memory.
    ///
    /// # Errors
    /// As [`Scene::open`].
    pub fn from_bytes(bytes: &[u8]) -> Result<Scene> {
        Ok(Scene::with(Source::File(Box::new(SceneFile::from_bytes(bytes)?))))
    }

    /// The trusted path on a file held in memory: the header and the archive's
    /// structure are checked, not the checksums or the semantic rules (see
    /// [`Scene::map_unchecked`] for what that guarantees).
    ///
    /// # Errors
    /// Header and archive-structure errors.
    pub fn from_bytes_unchecked(bytes: &[u8]) -> Result<Scene> {
        Ok(Scene::with(Source::File(Box::new(SceneFile::from_bytes_unchecked(bytes)?))))
    }

    /// Wraps a scene baked in this process (it is validated first).
    ///
    /// # Errors
    /// [`crate::Error::Format`] if the scene breaks the format's rules.
    pub fn from_baked(scene: BakedScene) -> Result<Scene> {
        scene.view().validate()?;
        Ok(Scene::with(Source::Baked(Box::new(scene))))
    }

    /// A scene over an opened file (an instanced file's embedded scene).
    pub(crate) fn from_scene_file(file: SceneFile) -> Scene {
        Scene::with(Source::File(Box::new(file)))
    }

    fn with(source: Source) -> Scene {
        let inner = Inner {
            source,
            grid: std::sync::OnceLock::new(),
            fans: std::sync::OnceLock::new(),
            frame: std::sync::OnceLock::new(),
            solid: std::sync::OnceLock::new(),
            edges: std::sync::OnceLock::new(),
            bounds: std::sync::OnceLock::new(),
            winding: std::sync::OnceLock::new(),
        };
        Scene { shared: std::sync::OnceLock::new(), inner: Box::new(inner) }
    }

    /// The scene's arrays.
    #[inline]
    pub fn view(&self) -> SceneView<'_> {
        match &self.inner.source {
            Source::File(f) => f.view(),
            Source::Baked(b) => b.view(),
        }
    }

    /// Decodes the images of the textures the file keeps encoded (PNGs and JPEGs;
    /// once, on the first call or the first texture lookup, whichever comes first) and
    /// says whether they decoded to the texels the bake saw. Renders call it first;
    /// where it fails, a texture reads as white.
    ///
    /// # Example
    /// ```
    /// let scene = octrace_runtime::Scene::from_baked(octrace_bake::bake(
    ///     &octrace_bake::procedural::shaded_torus(8, 4),
    ///     &octrace_bake::BuildParams::auto(),
    /// )?)?;
    /// assert!(scene.view().texels.has_encoded()); // its occlusion texture is a PNG
    /// scene.decode_textures()?;
    /// assert!(scene.view().texels.is_decoded());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`crate::Error::Format`] naming the first texture whose image is damaged or
    /// decodes to other texels than at bake.
    pub fn decode_textures(&self) -> Result<()> {
        self.view().texels.check()?;
        Ok(())
    }

    /// The scene's materials, lights, cameras and effects.
    pub fn shading(&self) -> &octrace_format::Shading {
        match &self.inner.source {
            Source::File(f) => f.shading(),
            Source::Baked(b) => &b.shading,
        }
    }

    /// The file behind the scene, when it came from one.
    pub fn file(&self) -> Option<&SceneFile> {
        match &self.inner.source {
            Source::File(f) => Some(f),
            Source::Baked(_) => None,
        }
    }

    /// A CPU tracer over the scene; build one per batch of rays. (The first one also
    /// builds the scene's point-location grid, a few milliseconds.)
    ///
    /// Its triangle test is the exact one ([`TriangleTest::Exact`]), except in a scene
    /// with crowded fans ([`Scene::fans`]: a leaf of 256+ references with 24+
    /// triangles around one vertex, which `octrace inspect` reports), where it is the
    /// watertight one: the exact test tests such leaves whole, and a ray aimed near the
    /// fan's vertex runs up to 70x slower than through the fan's hierarchy
    /// (BENCHMARKS.md, "Fans"). Ask for the exact test there with
    /// [`Tracer::with_triangle_test`].
    #[inline]
    pub fn tracer(&self) -> Tracer<'_> {
        let view = self.view();
        let grid = self.inner.grid.get_or_init(|| LocateGrid::build(&view));
        let frame = *self.inner.frame.get_or_init(|| crate::cpu::TreeFrame::of(&view));
        let fans = self.fans();
        let test = if fans.is_empty() { TriangleTest::Exact } else { TriangleTest::Watertight };
        Tracer::with_frame(view, frame)
            .with_locate_grid(grid)
            .with_fans((!fans.is_empty()).then_some(fans))
            .with_triangle_test(test)
    }

    /// The scene's crowded leaves, whose fans the walks use ([`crate::cpu::FanIndex`]):
    /// found on the first call (or tracer), reading every leaf record once.
    pub fn fans(&self) -> &crate::cpu::FanIndex {
        self.inner.fans.get_or_init(|| crate::cpu::FanIndex::new(&self.view()))
    }

    /// The scene's own tracer, made once: the one-ray calls pay no setup.
    fn shared_tracer(&self) -> &Tracer<'_> {
        self.shared.get_or_init(|| {
            let tracer = self.tracer();
            // SAFETY: the tracer borrows only from `*self.inner` (the source's arrays
            // and shading data, the grid): heap memory (or a map) owned by the box,
            // which no method changes and which does not move when the scene does.
            // `shared` is dropped before `inner` (field order), and it is only handed
            // out as `&Tracer<'_>` tied to `&self`, so no borrow outlives the data.
            unsafe { std::mem::transmute::<Tracer<'_>, Tracer<'static>>(tracer) }
        })
    }

    /// The nearest hit of `ray` in `[tmin, tmax]`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.shared_tracer().intersect(ray)
    }

    /// Whether anything lies on `ray` in `[tmin, tmax]`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.shared_tracer().occluded(ray)
    }

    /// A hit that occludes `ray` ([`Tracer::occluder`]), on the scene's own tracer.
    pub(crate) fn shared_occluder(&self, ray: &Ray) -> Option<Hit> {
        self.shared_tracer().occluder(ray)
    }

    /// Nearest hits of many rays, on all cores: each core walks sixteen rays at a time
    /// (eight a vector where the processor has AVX2), so that their loads overlap:
    /// faster than [`Scene::intersect`] ray by ray, with the same answers. (The calls
    /// on many rays or points end in `_batch`; "all" is for every hit along one ray,
    /// [`Scene::crossings`], as in other tracers.)
    pub fn intersect_batch(&self, rays: &[Ray]) -> Vec<Option<Hit>> {
        let mut out = vec![None; rays.len()];
        self.tracer().par_intersect_batch(rays, &mut out);
        out
    }

    /// Occlusion of many rays, on all cores.
    pub fn occluded_batch(&self, rays: &[Ray]) -> Vec<bool> {
        let mut out = vec![false; rays.len()];
        self.tracer().par_occluded_batch(rays, &mut out);
        out
    }

    /// Every crossing of `ray` with the scene, in order along it, each once
    /// ([`Tracer::crossings`]: edges that triangles share crossed once).
    pub fn crossings(&self, ray: &Ray) -> Vec<Crossing> {
        self.shared_tracer().all_crossings(ray)
    }

    /// Every crossing of many rays, on all cores, in one flat list with each ray's
    /// offsets (at most `limit` a ray, the first ones).
    pub fn crossings_batch(&self, rays: &[Ray], limit: usize) -> BatchCrossings {
        self.tracer().par_crossings_batch(rays, limit)
    }

    /// [`Scene::crossings_batch`] whose lists may take at most `max_bytes`
    /// ([`Tracer::par_crossings_batch_within`]): past it, [`crate::Error::Budget`].
    pub fn crossings_batch_within(&self, rays: &[Ray], limit: usize, max_bytes: u64) -> crate::Result<BatchCrossings> {
        self.tracer().par_crossings_batch_within(rays, limit, max_bytes)
    }

    /// How many times each ray crosses the scene, on all cores.
    pub fn count_crossings_batch(&self, rays: &[Ray]) -> Vec<CrossingCount> {
        let mut out = vec![CrossingCount::default(); rays.len()];
        self.tracer().par_count_crossings_batch(rays, &mut out);
        out
    }

    /// The edge census of the scene's triangles (whether it is closed, manifold,
    /// consistently oriented), counted from the stored triangles on the first call
    /// (the dragon's 871,000: about 0.2 s), not read from the file: a file whose
    /// stored census was altered (its checksums made again) cannot make an open mesh
    /// look closed. `degenerate` is the file's count (degenerate triangles are not
    /// stored).
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::Scene;
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// assert!(scene.edges().is_closed());
    /// assert_eq!(*scene.edges(), scene.view().stats.edges);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn edges(&self) -> &EdgeCensus {
        self.inner.edges.get_or_init(|| self.view().count_edges())
    }

    /// The leaves' inside and outside labels ([`Solid::of`]), made on the first call
    /// (a crossing count a group of empty leaves, all cores: milliseconds for the
    /// bunny's size).
    ///
    /// # Errors
    /// [`Error::NotClosed`] when the scene is not closed.
    pub fn solid(&self) -> Result<&Solid> {
        let made = self.inner.solid.get_or_init(|| {
            Solid::of(&self.tracer()).map_err(|e| match e {
                Error::NotClosed { boundary_edges, edges } => (boundary_edges, edges),
                _ => (0, 0),
            })
        });
        made.as_ref().map_err(|&(boundary_edges, edges)| Error::NotClosed { boundary_edges, edges })
    }

    /// Whether `p` lies inside the scene, a closed mesh: point location alone for a
    /// point in an empty leaf ([`Tracer::contains`], which says how a point on the
    /// surface is answered).
    ///
    /// # Errors
    /// [`Error::NotClosed`] when the scene is not closed (see [`Scene::solid`]).
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::Scene;
    /// let ball = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// assert!(ball.contains([0.2, 0.1, 0.3])?);
    /// assert_eq!(ball.contains_batch(&[[0.0; 3], [2.0, 0.0, 0.0]])?, [true, false]);
    /// let plane = Scene::from_baked(bake(&procedural::grid(4, 1.0), &BuildParams::auto())?)?;
    /// assert!(plane.contains([0.5, 0.5, 0.1]).is_err()); // open: no inside
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn contains(&self, p: [f32; 3]) -> Result<bool> {
        let solid = self.solid()?;
        Ok(self.shared_tracer().contains(solid, p))
    }

    /// [`Scene::contains`] for many points, on all cores.
    ///
    /// # Errors
    /// As [`Scene::contains`]; [`Error::Alloc`] where the answers' memory cannot be had.
    pub fn contains_batch(&self, points: &[[f32; 3]]) -> Result<Vec<bool>> {
        let solid = self.solid()?;
        let mut out = octrace_format::memory::try_vec(points.len(), "inside answers")?;
        self.tracer().par_contains_batch(solid, points, &mut out);
        Ok(out)
    }

    /// The length of each ray inside the scene, a closed mesh ([`Tracer::length_inside`]),
    /// on all cores.
    ///
    /// # Errors
    /// As [`Scene::contains`].
    pub fn length_inside_batch(&self, rays: &[Ray]) -> Result<Vec<f32>> {
        let solid = self.solid()?;
        let mut out = vec![0.0; rays.len()];
        self.tracer().par_length_inside(solid, rays, &mut out);
        Ok(out)
    }
}

impl Scene {
    /// The point of the surface nearest `p`: the distance exact, correctly rounded to
    /// `f32`, the triangle the nearest (of equally near ones, the lowest input index),
    /// the point and its barycentrics rounded from `f64` ([`Tracer::closest_point`]).
    /// `None` for a scene without triangles or a point that is not finite (or where the
    /// search's tree is to be made and its memory cannot be had: [`Scene::surface_bounds`]
    /// says so, and [`Scene::closest_points_batch`] returns it as an error).
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::Scene;
    /// let ball = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let near = ball.closest_point([0.0, 0.0, 3.0]).expect("a surface");
    /// assert!((near.distance - 2.0).abs() < 1e-6); // the pole, a vertex
    /// assert_eq!(near.point[2], 1.0);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn closest_point(&self, p: [f32; 3]) -> Option<ClosestPoint> {
        self.shared_tracer().closest_point(self.surface_bounds().ok()?, p, f32::INFINITY)
    }

    /// The closest-point search's tree ([`crate::cpu::SurfaceBounds`]: the triangles in
    /// clusters, bounded): the scene's `distance` section where it was baked with one
    /// (`bake --distance`: nothing to make), else made on the first call (about 24 bytes
    /// a triangle; tens of milliseconds for the bunny, 0.3-0.4 s for the dragon's 871k
    /// triangles).
    ///
    /// # Errors
    /// [`Error::Alloc`] where the memory for a tree to be made cannot be had.
    pub fn surface_bounds(&self) -> Result<&crate::cpu::SurfaceBounds> {
        if let Some(made) = self.inner.bounds.get() {
            return Ok(made);
        }
        let made = crate::cpu::SurfaceBounds::of(self.shared_tracer())?;
        Ok(self.inner.bounds.get_or_init(|| made))
    }

    /// [`Scene::closest_point`] if it lies at most `max_distance` from `p` (the rounded
    /// distance compared): a band around the surface, whose far points are answered
    /// `None` sooner.
    pub fn closest_point_within(&self, p: [f32; 3], max_distance: f32) -> Option<ClosestPoint> {
        self.closest_point_checked(p, max_distance).ok().flatten()
    }

    /// [`Scene::closest_point_within`], its search tree's allocation failure said.
    pub(crate) fn closest_point_checked(&self, p: [f32; 3], max_distance: f32) -> Result<Option<ClosestPoint>> {
        Ok(self.shared_tracer().closest_point(self.surface_bounds()?, p, max_distance))
    }

    /// The closest point to `p` (in the world) of this scene's triangles as `to_world`
    /// places them (each vertex carried in `f64`, rounded to `f32`), within
    /// `max_distance`: a world's search through a placement that stretches distances
    /// unevenly (`least` and `slack` as `Tracer::closest_point_placed` takes them).
    pub(crate) fn closest_point_placed(
        &self,
        p: [f32; 3],
        to_world: &crate::world::Transform,
        to_local: &crate::world::Transform,
        least: f64,
        slack: f64,
        max_distance: f32,
    ) -> Result<Option<ClosestPoint>> {
        let bounds = self.surface_bounds()?;
        let mut scratch = crate::cpu::ClosestScratch::default();
        let tracer = self.shared_tracer();
        Ok(tracer.closest_point_placed(bounds, &mut scratch, p, to_world, to_local, least, slack, max_distance))
    }

    /// [`Scene::closest_point_within`] for many points, on all cores (`f32::INFINITY`
    /// for no limit).
    ///
    /// # Errors
    /// [`Error::Alloc`] where the answers' memory (40 bytes a point) cannot be had.
    pub fn closest_points_batch(&self, points: &[[f32; 3]], max_distance: f32) -> Result<Vec<Option<ClosestPoint>>> {
        let mut out = octrace_format::memory::try_vec(points.len(), "closest points")?;
        self.tracer().par_closest_point_batch(self.surface_bounds()?, points, max_distance, &mut out);
        Ok(out)
    }

    /// The signed distance of each point from the scene, a closed mesh, on all cores:
    /// [`Scene::closest_point`]'s distance, negative inside ([`Scene::contains`]: the
    /// sign is exact, never a vote; a point on the surface is at `0`). Past
    /// `max_distance`, infinity of the point's sign.
    ///
    /// # Errors
    /// [`Error::NotClosed`] when the scene is not closed; [`Error::Alloc`] where the
    /// answers' memory cannot be had.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::Scene;
    /// let ball = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let pole = ball.closest_point([0.0, 0.0, 3.0]).expect("a surface").point; // a vertex
    /// let d = ball.signed_distance_batch(&[[0.0; 3], [0.0, 0.0, 3.0], pole], 1.5)?;
    /// assert!(d[0] < -0.9 && d[0] > -1.0);
    /// assert_eq!(d[1], f32::INFINITY);
    /// assert_eq!(d[2], 0.0);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn signed_distance_batch(&self, points: &[[f32; 3]], max_distance: f32) -> Result<Vec<f32>> {
        let inside = self.contains_batch(points)?;
        let near = self.closest_points_batch(points, max_distance)?;
        let mut out = octrace_format::memory::try_with_capacity(points.len(), "signed distances")?;
        out.extend(
            near.iter()
                .zip(inside)
                .map(|(c, inside)| crate::cpu::signed(c.map_or(f32::INFINITY, |c| c.distance), inside)),
        );
        Ok(out)
    }
}

/// Generalized winding numbers ([`crate::winding`]).
impl Scene {
    /// The stored triangles grouped for winding numbers ([`WindingTree`]), made on the
    /// first call (a sort of the triangles: some 20 ms for the bunny, 0.3 s for the
    /// dragon; about 210 bytes a triangle). Scenes that [wind
    /// exactly](Scene::winds_exactly) make it only where a ray cannot answer.
    ///
    /// # Errors
    /// [`Error::Alloc`] where its memory cannot be had.
    pub fn winding_tree(&self) -> Result<&WindingTree> {
        let made = self.inner.winding.get_or_init(|| WindingTree::new(self.view().stored_triangles().collect()));
        made.as_ref().map_err(|e| Error::Alloc(e.clone()))
    }

    /// Whether the scene's winding numbers are integers: closed, every edge in two
    /// triangles that run it opposite ways. Its winding numbers are then answered
    /// exactly ([`Scene::winding_numbers`]).
    pub fn winds_exactly(&self) -> bool {
        let e = self.edges();
        e.is_manifold() && e.is_oriented()
    }

    /// The generalized winding number of each point (Jacobson et al.), on all cores:
    /// 1 inside a closed mesh wound counter-clockwise seen from outside, 0 outside,
    /// fractions where the surface has holes.
    ///
    /// Where the scene [winds exactly](Scene::winds_exactly) the answer is exact, an
    /// integer with [`Winding::bound`] 0: an empty leaf's inside/outside label where
    /// the point lies in one and the groups of empty leaves wind as they are labelled
    /// (no nested or inside-out shells around them), else the signed crossings of one
    /// ray from the point under the exact test ([`Tracer::winding_by_ray`]), checked
    /// against the parity of the exact inside/outside ([`Scene::contains`]). Where that cannot
    /// answer (a scene whose tracer has the watertight test, which has crowded fans)
    /// the tree's sum within 0.95 (guaranteed) rounded to the nearest integer of the
    /// inside/outside's parity: integers of one parity are 2 apart, so one lies within
    /// less than 1 of the sum. On the surface, where the number is not defined, a
    /// point's beside it. Elsewhere, as `accuracy` asks: within a tolerance,
    /// guaranteed, or by Barill et al.'s fast rule ([`Accuracy::FAST`], libigl's).
    ///
    /// # Errors
    /// [`Error::Alloc`] where the tree's or the answers' memory cannot be had.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::winding::Accuracy;
    /// use octrace_runtime::Scene;
    /// let ball = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let w = ball.winding_numbers(&[[0.1, 0.2, 0.3], [0.0, 0.0, 2.0]], Accuracy::FAST)?;
    /// assert_eq!((w[0].value, w[1].value), (1.0, 0.0)); // closed: exact
    /// let sheet = Scene::from_baked(bake(&procedural::grid(8, 1.0), &BuildParams::auto())?)?;
    /// let w = sheet.winding_numbers(&[[0.5, 0.5, 0.25]], Accuracy::Within(1e-6))?;
    /// assert!(w[0].bound <= 1e-6 && w[0].value.abs() > 0.1 && w[0].value.abs() < 0.5);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn winding_numbers(&self, points: &[[f32; 3]], accuracy: Accuracy) -> Result<Vec<Winding>> {
        let mut out: Vec<Winding> = octrace_format::memory::try_vec(points.len(), "winding numbers")?;
        if !self.winds_exactly() {
            self.winding_tree()?.winding_numbers(points, accuracy, &mut out);
            return Ok(out);
        }
        // Exact: an empty leaf's label, or the signed crossings of one ray checked
        // against the exact inside/outside's parity; points neither can answer (a
        // scene whose tracer has not the exact test) from the tree's sum.
        let solid = self.solid()?;
        let tracer = self.tracer();
        let mut exact: Vec<Option<i64>> = octrace_format::memory::try_vec(points.len(), "winding numbers")?;
        tracer.par_windings_by_label(solid, points, &mut exact);
        // The rays, along a space-filling curve: neighbours share leaves in cache.
        let pending = exact.iter().filter(|w| w.is_none()).count();
        let mut ray: Vec<u32> = octrace_format::memory::try_with_capacity(pending, "winding numbers")?;
        ray.extend((0..points.len() as u32).filter(|&i| exact[i as usize].is_none()));
        let mut near: Vec<[f32; 3]> = octrace_format::memory::try_with_capacity(pending, "winding numbers")?;
        near.extend(ray.iter().map(|&i| points[i as usize]));
        let mut found: Vec<Option<i64>> = octrace_format::memory::try_vec(pending, "winding numbers")?;
        let b = self.view().bounds;
        crate::cpu::along_curve(b.mesh_lo.map(f64::from), b.mesh_hi.map(f64::from), &near, &mut found, |p, o| {
            tracer.par_windings_by_ray(solid, p, o)
        });
        for (&i, w) in ray.iter().zip(found) {
            exact[i as usize] = w;
        }
        let mut rest: Vec<usize> =
            octrace_format::memory::try_with_capacity(exact.iter().filter(|w| w.is_none()).count(), "winding numbers")?;
        for (i, (w, n)) in out.iter_mut().zip(&exact).enumerate() {
            match *n {
                Some(n) => *w = Winding { value: n as f64, bound: 0.0 },
                None => rest.push(i),
            }
        }
        if rest.is_empty() {
            return Ok(out);
        }
        let tree = self.winding_tree()?;
        let mut left: Vec<[f32; 3]> = octrace_format::memory::try_with_capacity(rest.len(), "winding numbers")?;
        left.extend(rest.iter().map(|&i| points[i]));
        let inside = self.contains_batch(&left)?;
        let mut sums = octrace_format::memory::try_vec(left.len(), "winding numbers")?;
        tree.winding_numbers(&left, Accuracy::Within(0.95), &mut sums);
        for ((&i, w), inside) in rest.iter().zip(sums).zip(inside) {
            // The exact number is an integer of the parity `inside` says, within
            // 0.95 of the sum: the one.
            let odd = inside as i64;
            let near = w.value.round() as i64;
            let value = if (near - odd).rem_euclid(2) == 0 {
                near
            } else if w.value > near as f64 {
                near + 1
            } else {
                near - 1
            };
            out[i] = if w.value.is_nan() { w } else { Winding { value: value as f64, bound: 0.0 } };
        }
        Ok(out)
    }

    /// Whether each point is inside by its winding number: exactly [`Scene::contains`]
    /// where the scene is closed; elsewhere whether its winding number is above 1/2
    /// (libigl's rule, for meshes with holes, or non-manifold or self-intersecting
    /// ones), decided with certainty ([`WindingTree::inside_batch`]). On all cores.
    ///
    /// # Errors
    /// [`Error::Alloc`] where the tree's or the answers' memory cannot be had.
    pub fn inside_by_winding(&self, points: &[[f32; 3]]) -> Result<Vec<bool>> {
        if self.edges().is_closed() {
            return self.contains_batch(points);
        }
        let tree = self.winding_tree()?;
        let mut out = octrace_format::memory::try_vec(points.len(), "inside labels")?;
        tree.inside_batch(points, &mut out);
        Ok(out)
    }
}

/// The batch calls' former names, kept for one release: "all" now means every hit
/// along one ray, as in other tracers.
impl Scene {
    /// [`Scene::intersect_batch`].
    #[deprecated(note = "renamed intersect_batch: `all` is for every hit along one ray (Scene::crossings)")]
    pub fn intersect_all(&self, rays: &[Ray]) -> Vec<Option<Hit>> {
        self.intersect_batch(rays)
    }

    /// [`Scene::occluded_batch`].
    #[deprecated(note = "renamed occluded_batch")]
    pub fn occluded_all(&self, rays: &[Ray]) -> Vec<bool> {
        self.occluded_batch(rays)
    }

    /// [`Scene::crossings_batch`].
    #[deprecated(note = "renamed crossings_batch")]
    pub fn crossings_all(&self, rays: &[Ray], limit: usize) -> BatchCrossings {
        self.crossings_batch(rays, limit)
    }

    /// [`Scene::count_crossings_batch`].
    #[deprecated(note = "renamed count_crossings_batch")]
    pub fn count_crossings_all(&self, rays: &[Ray]) -> Vec<CrossingCount> {
        self.count_crossings_batch(rays)
    }

    /// [`Scene::contains_batch`].
    ///
    /// # Errors
    /// As [`Scene::contains`].
    #[deprecated(note = "renamed contains_batch")]
    pub fn contains_all(&self, points: &[[f32; 3]]) -> Result<Vec<bool>> {
        self.contains_batch(points)
    }

    /// [`Scene::length_inside_batch`].
    ///
    /// # Errors
    /// As [`Scene::contains`].
    #[deprecated(note = "renamed length_inside_batch")]
    pub fn length_inside_all(&self, rays: &[Ray]) -> Result<Vec<f32>> {
        self.length_inside_batch(rays)
    }
}
