//! Embree 3 (Debian's `libembree-dev`) on the scene's triangles: a peer of `report`
//! and `bench`, behind the `embree` cargo feature. Hand-written bindings to the twelve
//! calls used, from Embree 3.13's headers (`rtcore_ray.h`, `rtcore_common.h`).
//!
//! Scenes are built with Embree's default (medium) quality on all cores, in its fast
//! mode or with `RTC_SCENE_FLAG_ROBUST` ("avoid optimizations that reduce arithmetic
//! accuracy": its watertight mode); rays are traced one at a time (`rtcIntersect1`,
//! `rtcOccluded1`) with an incoherent context, on the calling thread, as the octree
//! traces them, or sixteen at a time (`rtcIntersect16`, a coherent context) for
//! camera rays in 4 x 4 pixel packets.

use std::ffi::{c_char, c_void, CStr};
use std::time::{Duration, Instant};

use octrace_runtime::Ray;

type Device = *mut c_void;
type Scene = *mut c_void;
type Geometry = *mut c_void;

/// `RTC_GEOMETRY_TYPE_TRIANGLE`, `RTC_BUFFER_TYPE_INDEX` / `_VERTEX`,
/// `RTC_FORMAT_UINT3` / `_FLOAT3`, `RTC_INVALID_GEOMETRY_ID`.
const GEOMETRY_TRIANGLE: u32 = 0;
/// `RTC_GEOMETRY_TYPE_INSTANCE`, `RTC_FORMAT_FLOAT3X4_ROW_MAJOR`.
const GEOMETRY_INSTANCE: u32 = 121;
const FORMAT_FLOAT3X4_ROW_MAJOR: u32 = 0x9134;
const BUFFER_INDEX: u32 = 0;
const BUFFER_VERTEX: u32 = 1;
const FORMAT_UINT3: u32 = 0x5003;
const FORMAT_FLOAT3: u32 = 0x9003;
const INVALID_ID: u32 = u32::MAX;
/// `RTC_SCENE_FLAG_ROBUST`, `RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION`.
const SCENE_FLAG_ROBUST: u32 = 1 << 2;
const SCENE_FLAG_CONTEXT_FILTER: u32 = 1 << 3;

/// `RTCIntersectContext` with `RTC_MAX_INSTANCE_LEVEL_COUNT` 1 and no minimum width
/// (Debian's build, `rtcore_config.h`).
#[repr(C)]
struct IntersectContext {
    flags: u32,
    filter: Option<unsafe extern "C" fn(*const FilterArguments)>,
    inst_id: [u32; 1],
}

/// `RTCFilterFunctionNArguments`: the rays and hits are `RTCRayN` / `RTCHitN`, arrays
/// of `n` lanes a field (`rtcore_ray.h`'s accessors give the offsets used below).
#[repr(C)]
struct FilterArguments {
    valid: *mut i32,
    geometry_user_ptr: *mut c_void,
    context: *mut IntersectContext,
    ray: *mut f32,
    hit: *mut f32,
    n: u32,
}

/// An intersection context with the collector its filter function fills (Embree hands
/// the filter the context pointer it was given: the pattern of its `next_hit`
/// tutorial).
#[repr(C)]
struct CollectingContext {
    base: IntersectContext,
    hits: *mut Vec<EmbreeHit>,
}

/// A hit Embree's filter sees: distance, triangle (view order), barycentrics, and
/// whether the ray arrives on the front (`Ng . dir < 0`, Embree's `Ng` being
/// `(v1 - v0) x (v2 - v0)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct EmbreeHit {
    pub t: f32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
    pub enters: bool,
}

/// The filter that keeps every hit: records it and rejects it, so the traversal goes
/// on to the next (and `tfar` stays where it was).
///
/// # Safety
/// Called by Embree with valid arguments whose context is a [`CollectingContext`].
unsafe extern "C" fn collect_every_hit(args: *const FilterArguments) {
    // SAFETY: Embree's arguments; the context is the CollectingContext the caller made
    // (its first field is the IntersectContext Embree was given).
    unsafe {
        let a = &*args;
        let n = a.n as usize;
        let hits = &mut *(*(a.context as *mut CollectingContext)).hits;
        for i in 0..n {
            if *a.valid.add(i) == 0 {
                continue;
            }
            let ray = |field: usize| *a.ray.add(field * n + i);
            let hit = |field: usize| *a.hit.add(field * n + i);
            let ng = [hit(0), hit(1), hit(2)];
            let dir = [ray(4), ray(5), ray(6)];
            let facing = ng[0] * dir[0] + ng[1] * dir[1] + ng[2] * dir[2];
            hits.push(EmbreeHit { t: ray(8), prim: (hit(5)).to_bits(), u: hit(3), v: hit(4), enters: facing < 0.0 });
            *a.valid.add(i) = 0;
        }
    }
}

/// `RTCRay`.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RtcRay {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
}

/// `RTCHit`.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RtcHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst_id: [u32; 1],
}

/// `RTCRayHit`.
#[repr(C)]
struct RtcRayHit {
    ray: RtcRay,
    hit: RtcHit,
}

/// `RTCRayHit16`: sixteen rays and hits, structure of arrays.
#[repr(C, align(64))]
struct RtcRayHit16 {
    org: [[f32; 16]; 3],
    tnear: [f32; 16],
    dir: [[f32; 16]; 3],
    time: [f32; 16],
    tfar: [f32; 16],
    mask: [u32; 16],
    id: [u32; 16],
    flags: [u32; 16],
    ng: [[f32; 16]; 3],
    u: [f32; 16],
    v: [f32; 16],
    prim_id: [u32; 16],
    geom_id: [u32; 16],
    inst_id: [u32; 16],
}

/// The `valid` mask of `rtcIntersect16`: -1 for a lane to trace, 0 for one to skip.
#[repr(C, align(64))]
struct Valid16([i32; 16]);

/// `RTC_INTERSECT_CONTEXT_FLAG_COHERENT`.
const CONTEXT_COHERENT: u32 = 1;

#[link(name = "embree3")]
extern "C" {
    fn rtcNewDevice(config: *const c_char) -> Device;
    fn rtcReleaseDevice(device: Device);
    fn rtcGetDeviceError(device: Device) -> u32;
    fn rtcNewScene(device: Device) -> Scene;
    fn rtcReleaseScene(scene: Scene);
    fn rtcSetSceneFlags(scene: Scene, flags: u32);
    fn rtcNewGeometry(device: Device, kind: u32) -> Geometry;
    fn rtcSetNewGeometryBuffer(
        geometry: Geometry,
        kind: u32,
        slot: u32,
        format: u32,
        stride: usize,
        count: usize,
    ) -> *mut c_void;
    fn rtcCommitGeometry(geometry: Geometry);
    fn rtcAttachGeometry(scene: Scene, geometry: Geometry) -> u32;
    fn rtcReleaseGeometry(geometry: Geometry);
    fn rtcCommitScene(scene: Scene);
    fn rtcSetGeometryInstancedScene(geometry: Geometry, scene: Scene);
    fn rtcSetGeometryTransform(geometry: Geometry, time_step: u32, format: u32, xfm: *const c_void);
    fn rtcIntersect1(scene: Scene, context: *mut IntersectContext, rayhit: *mut RtcRayHit);
    fn rtcOccluded1(scene: Scene, context: *mut IntersectContext, ray: *mut RtcRay);
    fn rtcIntersect16(valid: *const Valid16, scene: Scene, context: *mut IntersectContext, rayhit: *mut RtcRayHit16);
}

/// An Embree device and a committed scene of one triangle mesh.
pub(crate) struct Embree {
    device: Device,
    scene: Scene,
    /// For a scene of instances ([`Embree::instanced`]): the scene they place.
    placed: Option<Scene>,
    pub build_time: Duration,
}

// SAFETY: Embree's documentation allows rtcIntersect1 / rtcOccluded1 on a committed
// scene from any number of threads at once; nothing else is called after the build
// but the releases in `drop`, which takes the value.
unsafe impl Send for Embree {}
// SAFETY: as for Send: queries on a committed scene are thread-safe.
unsafe impl Sync for Embree {}

impl Embree {
    /// Builds Embree's BVH over the view's stored triangles (primitive ids are the
    /// view's triangle indices), in robust mode if `robust`.
    pub(crate) fn build(view: &octrace_format::SceneView<'_>, robust: bool) -> anyhow::Result<Embree> {
        Self::build_with(view, if robust { SCENE_FLAG_ROBUST } else { 0 })
    }

    /// [`Embree::build`] for [`Embree::every_hit`]: the scene takes a filter function
    /// from the intersection context (`RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION`).
    pub(crate) fn build_collecting(view: &octrace_format::SceneView<'_>) -> anyhow::Result<Embree> {
        Self::build_with(view, SCENE_FLAG_CONTEXT_FILTER)
    }

    fn build_with(view: &octrace_format::SceneView<'_>, flags: u32) -> anyhow::Result<Embree> {
        let n = view.triangle_count();
        anyhow::ensure!(n > 0 && n <= u32::MAX as usize / 3, "Embree: {n} triangles");
        let config: &CStr = c"verbose=0";
        // SAFETY: a valid C string; a null device is checked.
        let device = unsafe { rtcNewDevice(config.as_ptr()) };
        anyhow::ensure!(!device.is_null(), "Embree: no device (libembree3 could not start)");
        let t = Instant::now();
        // SAFETY: the device is valid; every pointer returned is checked before use,
        // and the buffers Embree allocates hold `n` items of the strides given.
        let scene = unsafe {
            let scene = rtcNewScene(device);
            if !scene.is_null() && flags != 0 {
                rtcSetSceneFlags(scene, flags);
            }
            let geometry = rtcNewGeometry(device, GEOMETRY_TRIANGLE);
            let vertices = rtcSetNewGeometryBuffer(geometry, BUFFER_VERTEX, 0, FORMAT_FLOAT3, 12, 3 * n) as *mut f32;
            let indices = rtcSetNewGeometryBuffer(geometry, BUFFER_INDEX, 0, FORMAT_UINT3, 12, n) as *mut u32;
            if scene.is_null() || geometry.is_null() || vertices.is_null() || indices.is_null() {
                let error = rtcGetDeviceError(device);
                rtcReleaseDevice(device);
                anyhow::bail!("Embree: cannot make the scene (error {error})");
            }
            let vertices = std::slice::from_raw_parts_mut(vertices, 9 * n);
            let indices = std::slice::from_raw_parts_mut(indices, 3 * n);
            for (t, tri) in view.stored_triangles().enumerate().take(n) {
                vertices[9 * t..9 * t + 9].copy_from_slice(&tri.concat());
                indices[3 * t..3 * t + 3].copy_from_slice(&[3 * t as u32, 3 * t as u32 + 1, 3 * t as u32 + 2]);
            }
            rtcCommitGeometry(geometry);
            rtcAttachGeometry(scene, geometry);
            rtcReleaseGeometry(geometry);
            rtcCommitScene(scene);
            scene
        };
        let build_time = t.elapsed();
        // SAFETY: the device is valid.
        let error = unsafe { rtcGetDeviceError(device) };
        let embree = Embree { device, scene, placed: None, build_time };
        anyhow::ensure!(error == 0, "Embree: the build failed (error {error})");
        Ok(embree)
    }

    /// A scene of instances of this one (Embree's one level of instancing: an
    /// `RTC_GEOMETRY_TYPE_INSTANCE` a placement, each with its 3x4 row-major
    /// transform), built with the default quality; `build_time` is the instances'
    /// build alone. Hits' `prim_id` are then the placed scene's triangles.
    pub(crate) fn instanced(mut self, transforms: &[[[f32; 4]; 3]]) -> anyhow::Result<Embree> {
        let t = Instant::now();
        // SAFETY: the device and the scene to place are valid; every geometry is
        // checked; the transform is read during the call (12 floats, row-major).
        let top = unsafe {
            let top = rtcNewScene(self.device);
            anyhow::ensure!(!top.is_null(), "Embree: cannot make the scene of instances");
            for m in transforms {
                let geometry = rtcNewGeometry(self.device, GEOMETRY_INSTANCE);
                if geometry.is_null() {
                    rtcReleaseScene(top);
                    anyhow::bail!("Embree: cannot make an instance (error {})", rtcGetDeviceError(self.device));
                }
                rtcSetGeometryInstancedScene(geometry, self.scene);
                rtcSetGeometryTransform(geometry, 0, FORMAT_FLOAT3X4_ROW_MAJOR, m.as_ptr().cast());
                rtcCommitGeometry(geometry);
                rtcAttachGeometry(top, geometry);
                rtcReleaseGeometry(geometry);
            }
            rtcCommitScene(top);
            top
        };
        let build_time = t.elapsed();
        // SAFETY: the device is valid.
        let error = unsafe { rtcGetDeviceError(self.device) };
        let placed = std::mem::replace(&mut self.scene, top);
        self.placed = Some(placed);
        self.build_time = build_time;
        anyhow::ensure!(error == 0, "Embree: the instances' build failed (error {error})");
        Ok(self)
    }

    /// Whether Embree takes `r`: a ray octrace traces, whose origin and direction
    /// components are at most `FLT_LARGE` (1.844e18) in magnitude, as Embree's
    /// `RayK::valid` asks (Debian's build asserts it and aborts on any other). Embree
    /// answers the others with no hit here (the report counts that against it).
    fn takes(r: &Ray) -> bool {
        const FLT_LARGE: f32 = 1.844e18;
        let within = |v: glam::Vec3| v.abs().max_element() <= FLT_LARGE;
        r.is_traceable() && within(r.origin) && within(r.dir)
    }

    fn ray(r: &Ray) -> RtcRay {
        RtcRay {
            org: r.origin.to_array(),
            tnear: r.tmin,
            dir: r.dir.to_array(),
            time: 0.0,
            tfar: r.tmax,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        }
    }

    fn context() -> IntersectContext {
        IntersectContext { flags: 0, filter: None, inst_id: [INVALID_ID] }
    }

    /// The nearest hit of `r`: distance, stored triangle (view order), barycentrics of
    /// the second and third vertices.
    pub(crate) fn nearest(&self, r: &Ray) -> Option<(f32, u32, f32, f32)> {
        if !Self::takes(r) {
            return None;
        }
        let hit =
            RtcHit { ng: [0.0; 3], u: 0.0, v: 0.0, prim_id: INVALID_ID, geom_id: INVALID_ID, inst_id: [INVALID_ID] };
        let mut rayhit = RtcRayHit { ray: Self::ray(r), hit };
        let mut context = Self::context();
        // SAFETY: a committed scene, a valid context and an aligned ray/hit record.
        unsafe { rtcIntersect1(self.scene, &mut context, &mut rayhit) };
        let h = rayhit.hit;
        (h.geom_id != INVALID_ID).then_some((rayhit.ray.tfar, h.prim_id, h.u, h.v))
    }

    /// The nearest hits of up to sixteen rays traced as one packet (`rtcIntersect16`,
    /// coherent context), as [`Embree::nearest`] gives them, into `out`.
    pub(crate) fn nearest16(&self, rays: &[Ray], out: &mut [Option<(f32, u32, f32, f32)>]) {
        assert!(rays.len() <= 16 && out.len() == rays.len());
        let mut valid = Valid16([0; 16]);
        // SAFETY: RtcRayHit16 is plain numbers, for which all zeros is a valid value.
        let mut p: RtcRayHit16 = unsafe { std::mem::zeroed() };
        for (k, r) in rays.iter().enumerate() {
            if !Self::takes(r) {
                continue;
            }
            valid.0[k] = -1;
            for a in 0..3 {
                p.org[a][k] = r.origin[a];
                p.dir[a][k] = r.dir[a];
            }
            (p.tnear[k], p.tfar[k], p.mask[k]) = (r.tmin, r.tmax, u32::MAX);
            (p.geom_id[k], p.prim_id[k], p.inst_id[k]) = (INVALID_ID, INVALID_ID, INVALID_ID);
        }
        let mut context = IntersectContext { flags: CONTEXT_COHERENT, ..Self::context() };
        // SAFETY: a committed scene, a valid context, 64-byte aligned mask and packet.
        unsafe { rtcIntersect16(&valid, self.scene, &mut context, &mut p) };
        for (k, o) in out.iter_mut().enumerate() {
            *o = (valid.0[k] != 0 && p.geom_id[k] != INVALID_ID).then(|| (p.tfar[k], p.prim_id[k], p.u[k], p.v[k]));
        }
    }

    /// Every hit of `r` in `[tmin, tmax]`, into `hits` (cleared first), sorted by
    /// distance: one `rtcIntersect1` whose context filter records each hit Embree finds
    /// and rejects it (Embree's `next_hit` pattern, in one pass), on a scene from
    /// [`Embree::build_collecting`]. Embree finds hits out of order; a ray through an
    /// edge two triangles share may find both, or neither. Unsorted where `sort` is
    /// false (for counts).
    pub(crate) fn every_hit(&self, r: &Ray, hits: &mut Vec<EmbreeHit>, sort: bool) {
        hits.clear();
        if !Self::takes(r) {
            return;
        }
        let hit =
            RtcHit { ng: [0.0; 3], u: 0.0, v: 0.0, prim_id: INVALID_ID, geom_id: INVALID_ID, inst_id: [INVALID_ID] };
        let mut rayhit = RtcRayHit { ray: Self::ray(r), hit };
        let mut context = CollectingContext {
            base: IntersectContext { filter: Some(collect_every_hit), ..Self::context() },
            hits: hits as *mut Vec<EmbreeHit>,
        };
        // SAFETY: a committed scene built with context filters, a context whose filter
        // reads the collector beside it (alive for the call), an aligned ray/hit record.
        unsafe { rtcIntersect1(self.scene, &mut context.base, &mut rayhit) };
        if sort && hits.len() > 1 {
            hits.sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.prim.cmp(&b.prim)));
        }
    }

    /// Whether anything blocks `r`.
    pub(crate) fn occluded(&self, r: &Ray) -> bool {
        if !Self::takes(r) {
            return false;
        }
        let mut ray = Self::ray(r);
        let mut context = Self::context();
        // SAFETY: a committed scene, a valid context and an aligned ray.
        unsafe { rtcOccluded1(self.scene, &mut context, &mut ray) };
        ray.tfar == f32::NEG_INFINITY
    }
}

impl Drop for Embree {
    fn drop(&mut self) {
        // SAFETY: all were made by `build` (and `instanced`) and are released once,
        // the scene of instances before the scene it places.
        unsafe {
            rtcReleaseScene(self.scene);
            if let Some(placed) = self.placed {
                rtcReleaseScene(placed);
            }
            rtcReleaseDevice(self.device);
        }
    }
}
