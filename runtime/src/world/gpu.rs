//! A world's nearest and any hits, crossing counts and lists with the instances'
//! walks on the GPU.
//!
//! The host walks the top level and carries each ray into the instances it enters
//! (in `f64`, as [`World::intersect`] does: `f64` is not an arithmetic every
//! adapter has, and the carried rays must be the CPU's bit for bit); the GPU walks
//! each instance's octree, a scene's rays of every instance in one batch a round.
//! The answers are [`World::intersect_batch`]'s and [`World::occluded_batch`]'s, bit
//! for bit (instance, triangle, part, distance, barycentrics; the leaf a walk found a
//! hit in may differ, as for a scene's [`GpuTracer`]): each scene's GPU tracer runs
//! its CPU tracer's triangle test (the exact one, unless the scene has fans).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::rounds::{Boxes, Walker};
use super::{carried, Carried, Placed, World, WorldCrossing, WorldHit};
use crate::cpu::{Crossing, CrossingCount};
use crate::gpu::{GpuError, GpuOptions, GpuResult, GpuTracer};
use crate::ray::{Hit, Ray};
use crate::Scene;

/// The rays a round of the GPU's takes at most: their boxes, carried rays and hits
/// take about 100 bytes a ray plus 8 a box.
const PIECE: usize = 1 << 18;

/// The boxes a ray's rounds take at most on the GPU; a ray whose walk enters more is
/// finished on the CPU (by the one-ray walk, within its nearest hit).
const GPU_BOXES: usize = 64;

/// A scene's tracer on the device, and the scene it borrows.
struct OnDevice {
    /// Borrows `_scene`'s value, which lives on the heap behind the `Arc`: it neither
    /// moves nor drops while this struct lives, and this field, declared first, is
    /// dropped first.
    tracer: GpuTracer<'static>,
    _scene: Arc<Scene>,
}

/// The scenes of worlds uploaded to a GPU, each once, and the batch queries of a
/// [`World`] on it ([`GpuWorld::intersect`], [`GpuWorld::occluded`]).
///
/// A world's scenes are uploaded on first use and kept, so that a world whose
/// instances move between frames (`set_transform`, `commit`) is traced again with
/// nothing uploaded but the rays.
///
/// # Example
/// ```no_run
/// use std::sync::Arc;
/// use octrace_runtime::gpu::GpuContext;
/// use octrace_runtime::world::{GpuWorld, Transform, World};
/// use octrace_runtime::{glam::Vec3, Ray, Scene};
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let bunny = Arc::new(Scene::open("bunny.oct")?);
/// let mut world = World::new();
/// for k in 0..10 {
///     world.add(&bunny, Transform::translation([0.3 * f64::from(k), 0.0, 0.0]))?;
/// }
/// world.commit();
/// let gpu = GpuContext::new()?;
/// let mut on_gpu = GpuWorld::new(&gpu.device, &gpu.queue);
/// let rays = [Ray::new(Vec3::new(0.0, 0.1, 1.0), Vec3::NEG_Z)];
/// let hits = on_gpu.intersect(&world, &rays)?;
/// let cpu = world.intersect_batch(&rays);
/// assert_eq!(hits[0].map(|h| (h.instance, h.hit.t)), cpu[0].map(|h| (h.instance, h.hit.t)));
/// # Ok(()) }
/// ```
pub struct GpuWorld {
    device: crate::gpu::wgpu::Device,
    queue: crate::gpu::wgpu::Queue,
    on_device: Vec<OnDevice>,
    /// Each uploaded scene's index in `on_device`, by its address.
    by_scene: HashMap<usize, usize>,
    /// The last batch's timings.
    timings: GpuWorldTimings,
}

/// Where the time of a [`GpuWorld`] batch went: the host's parts and the GPU's.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuWorldTimings {
    /// Walking the top level for each ray's first boxes (all cores).
    pub top: Duration,
    /// The GPU tracers' calls, transfers included, as the host waits for them.
    pub device: Duration,
    /// The rays' carrying into the instances, their grouping by scene and the merging
    /// of the answers, on one thread.
    pub rounds: Duration,
    /// The rays whose walks enter more boxes than the rounds take, finished on the
    /// CPU (all cores).
    pub finish: Duration,
    /// The whole call.
    pub total: Duration,
    /// Rounds the batch took (a box of each ray a round), over its pieces.
    pub round_count: u32,
    /// Rays finished on the CPU.
    pub finished_on_cpu: u64,
}

impl std::fmt::Debug for GpuWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuWorld").field("scenes", &self.on_device.len()).finish()
    }
}

impl GpuWorld {
    /// Nothing uploaded yet, on `device`.
    pub fn new(device: &crate::gpu::wgpu::Device, queue: &crate::gpu::wgpu::Queue) -> GpuWorld {
        GpuWorld {
            device: device.clone(),
            queue: queue.clone(),
            on_device: Vec::new(),
            by_scene: HashMap::new(),
            timings: GpuWorldTimings::default(),
        }
    }

    /// Uploads the scenes of `world`'s committed instances not yet on the device.
    ///
    /// # Errors
    /// As [`GpuTracer::with_options`]: a scene too large for the device, or whose
    /// triangle test the adapter cannot run (the exact test without `f64`).
    pub fn upload(&mut self, world: &World) -> GpuResult<()> {
        for (_, index) in world.placed_scenes() {
            let scene = &world.scenes()[index as usize];
            let key = Arc::as_ptr(scene) as usize;
            if self.by_scene.contains_key(&key) {
                continue;
            }
            let options = GpuOptions { triangle_test: scene.tracer().triangle_test(), ..GpuOptions::default() };
            // SAFETY: the reference is to the value the `Arc` kept in `_scene` owns; it
            // is neither moved nor dropped before `tracer`, which the struct drops
            // first, and the tracers are lent out only while `self` is borrowed.
            let borrowed: &'static Scene = unsafe { &*Arc::as_ptr(scene) };
            let tracer = GpuTracer::with_options(&self.device, &self.queue, borrowed, options)?;
            self.by_scene.insert(key, self.on_device.len());
            self.on_device.push(OnDevice { tracer, _scene: Arc::clone(scene) });
        }
        Ok(())
    }

    /// The scenes on the device.
    pub fn scenes(&self) -> usize {
        self.on_device.len()
    }

    /// Where the last batch's time went ([`GpuWorld::intersect`], `occluded`,
    /// `count_crossings`, `crossings`; the uploads not counted).
    pub fn timings(&self) -> GpuWorldTimings {
        self.timings
    }

    /// Forgets the scenes no committed instance of `world` places (their memory on
    /// the device is freed).
    pub fn retain(&mut self, world: &World) {
        let live: std::collections::HashSet<usize> =
            world.placed_scenes().map(|(_, i)| Arc::as_ptr(&world.scenes()[i as usize]) as usize).collect();
        let kept: Vec<OnDevice> =
            self.on_device.drain(..).filter(|d| live.contains(&(Arc::as_ptr(&d._scene) as usize))).collect();
        self.by_scene = kept.iter().enumerate().map(|(i, d)| (Arc::as_ptr(&d._scene) as usize, i)).collect();
        self.on_device = kept;
    }

    /// [`World::intersect_batch`] with the instances' walks on the GPU: the same
    /// answers, bit for bit (the leaf aside, see the module's text). Uploads the world's scenes not yet on the device.
    ///
    /// # Errors
    /// As [`GpuWorld::upload`]; [`GpuError::Device`] if the device is lost.
    pub fn intersect(&mut self, world: &World, rays: &[Ray]) -> GpuResult<Vec<Option<WorldHit>>> {
        self.batch(world, false, rays)
    }

    /// [`World::occluded_batch`] with the instances' walks on the GPU: the same
    /// answers.
    ///
    /// # Errors
    /// As [`GpuWorld::intersect`].
    pub fn occluded(&mut self, world: &World, rays: &[Ray]) -> GpuResult<Vec<bool>> {
        Ok(self.batch(world, true, rays)?.iter().map(Option::is_some).collect())
    }

    /// [`World::count_crossings_batch`] with the instances' walks on the GPU: the same
    /// counts. Each ray's crossings of the instances its first 64 boxes hold are
    /// counted on the GPU (listed there, where a moved origin's reach has a margin past
    /// a finite `tmax`), those of further instances on the CPU.
    ///
    /// # Errors
    /// As [`GpuWorld::intersect`].
    pub fn count_crossings(&mut self, world: &World, rays: &[Ray]) -> GpuResult<Vec<CrossingCount>> {
        self.upload(world)?;
        let start = Instant::now();
        let mut timings = GpuWorldTimings::default();
        let mut out: Vec<CrossingCount> = answers(rays.len())?;
        for (rays, out) in rays.chunks(PIECE).zip(out.chunks_mut(PIECE)) {
            let boxes = boxes_of(world, rays, &mut timings);
            self.along(world, rays, &boxes, false, &mut timings, |i, _, p, local, found| {
                let c = match found {
                    Found::Count(c) => c,
                    Found::List(list) => local.count_of_list(rays[i].tmax, list),
                };
                let c = p.placed_count(c);
                out[i].total += c.total;
                out[i].entries += c.entries;
            })?;
            let t = Instant::now();
            out.par_iter_mut().enumerate().filter(|(i, _)| boxes.more(*i)).for_each(|(i, o)| {
                let rest = world.count_crossings_from(&rays[i], &asked(&boxes, i));
                o.total += rest.total;
                o.entries += rest.entries;
            });
            timings.finish += t.elapsed();
            timings.finished_on_cpu += (0..rays.len()).filter(|&i| boxes.more(i)).count() as u64;
        }
        self.timings = GpuWorldTimings { total: start.elapsed(), ..timings };
        Ok(out)
    }

    /// [`World::crossings`] of each ray with the instances' walks on the GPU: the same
    /// lists, in order. Each ray's crossings of the instances its first 64 boxes hold
    /// are listed on the GPU, those of further instances on the CPU.
    ///
    /// # Errors
    /// As [`GpuWorld::intersect`]; [`GpuError::Memory`] where the lists' memory
    /// cannot be had.
    pub fn crossings(&mut self, world: &World, rays: &[Ray]) -> GpuResult<Vec<Vec<WorldCrossing>>> {
        self.upload(world)?;
        let start = Instant::now();
        let mut timings = GpuWorldTimings::default();
        let mut out: Vec<Vec<WorldCrossing>> = answers(rays.len())?;
        for (rays, out) in rays.chunks(PIECE).zip(out.chunks_mut(PIECE)) {
            let boxes = boxes_of(world, rays, &mut timings);
            self.along(world, rays, &boxes, true, &mut timings, |i, id, p, local, found| {
                if let Found::List(list) = found {
                    p.placed_crossings(id, local, rays[i].tmax, list, &mut out[i]);
                }
            })?;
            let t = Instant::now();
            out.par_iter_mut().enumerate().for_each(|(i, o)| {
                if boxes.more(i) {
                    world.crossings_from(&rays[i], &asked(&boxes, i), o);
                }
                // Stable: an instance's own crossings keep their order.
                o.sort_by(|a, b| a.crossing.t.total_cmp(&b.crossing.t).then(a.instance.cmp(&b.instance)));
            });
            timings.finish += t.elapsed();
            timings.finished_on_cpu += (0..rays.len()).filter(|&i| boxes.more(i)).count() as u64;
        }
        self.timings = GpuWorldTimings { total: start.elapsed(), ..timings };
        Ok(out)
    }

    fn batch(&mut self, world: &World, any: bool, rays: &[Ray]) -> GpuResult<Vec<Option<WorldHit>>> {
        self.upload(world)?;
        let start = Instant::now();
        let mut timings = GpuWorldTimings::default();
        let mut out = answers(rays.len())?;
        for (rays, out) in rays.chunks(PIECE).zip(out.chunks_mut(PIECE)) {
            let boxes = boxes_of(world, rays, &mut timings);
            let devices = self.devices(world);
            let mut walker =
                OnGpu { gpu: self, devices, by_scene: Vec::new(), rays: Vec::new(), at: Vec::new(), timings };
            let t = Instant::now();
            world.rounds(any, rays, &boxes, out, &mut walker)?;
            timings = walker.timings;
            timings.rounds += t.elapsed();
            let t = Instant::now();
            out.par_iter_mut().enumerate().filter(|(i, _)| boxes.more(*i)).for_each(|(i, o)| {
                world.finish(any, &rays[i], boxes.of_ray(i), o);
            });
            timings.finish += t.elapsed();
            timings.finished_on_cpu += (0..rays.len()).filter(|&i| boxes.more(i)).count() as u64;
        }
        self.timings = GpuWorldTimings {
            total: start.elapsed(),
            rounds: timings.rounds.saturating_sub(timings.device),
            ..timings
        };
        Ok(out)
    }

    /// Each of `world`'s scenes' tracer, its index in `on_device` (`usize::MAX` for a
    /// scene not uploaded), by the world's scene index.
    fn devices(&self, world: &World) -> Vec<usize> {
        world
            .scenes()
            .iter()
            .map(|s| self.by_scene.get(&(Arc::as_ptr(s) as usize)).copied().unwrap_or(usize::MAX))
            .collect()
    }

    /// Each ray of `rays` carried (over its whole `[tmin, tmax]`) into every instance
    /// of its `boxes`, a box a round, and walked on the GPU by the instance's scene:
    /// its crossings counted, or listed (every ray with `list`, else where a moved
    /// origin's reach has a margin past a finite `tmax`); `visit(ray, instance,
    /// placement, carried ray, found)` for each.
    fn along(
        &self,
        world: &World,
        rays: &[Ray],
        boxes: &Boxes,
        list: bool,
        timings: &mut GpuWorldTimings,
        mut visit: impl FnMut(usize, u32, &Placed, &Carried, Found<'_>),
    ) -> GpuResult<()> {
        let mut jobs: Vec<(u32, u32)> = Vec::new();
        let devices = self.devices(world);
        let start = Instant::now();
        let device_before = timings.device;
        for round in 0.. {
            jobs.clear();
            jobs.extend((0..rays.len()).filter_map(|i| boxes.of_ray(i).get(round).map(|b| (b.1, i as u32))));
            if jobs.is_empty() {
                timings.rounds += start.elapsed().saturating_sub(timings.device - device_before);
                return Ok(());
            }
            timings.round_count += 1;
            let placed: Vec<&Placed> =
                jobs.iter().map(|&(id, _)| world.placed[id as usize].as_ref().expect("a committed instance")).collect();
            let local: Vec<Carried> = jobs
                .iter()
                .zip(&placed)
                .map(|(&(_, i), p)| carried(p, &rays[i as usize], rays[i as usize].tmax))
                .collect();
            // Each job's tracer.
            let device: Vec<usize> = placed.iter().map(|p| devices[p.scene as usize]).collect();
            for (d, on_device) in self.on_device.iter().enumerate() {
                let (listed, counted): (Vec<usize>, Vec<usize>) = (0..jobs.len())
                    .filter(|&k| device[k] == d)
                    .partition(|&k| list || local[k].counted_by_list(rays[jobs[k].1 as usize].tmax));
                let carried_rays = |ks: &[usize]| ks.iter().map(|&k| local[k].ray).collect::<Vec<Ray>>();
                if !counted.is_empty() {
                    let t = Instant::now();
                    let counts = on_device.tracer.count_crossings(&carried_rays(&counted))?;
                    timings.device += t.elapsed();
                    for (&k, c) in counted.iter().zip(counts) {
                        visit(jobs[k].1 as usize, jobs[k].0, placed[k], &local[k], Found::Count(c));
                    }
                }
                if !listed.is_empty() {
                    let t = Instant::now();
                    let lists = on_device.tracer.crossings(&carried_rays(&listed))?;
                    timings.device += t.elapsed();
                    for (n, &k) in listed.iter().enumerate() {
                        visit(jobs[k].1 as usize, jobs[k].0, placed[k], &local[k], Found::List(lists.of(n)));
                    }
                }
            }
        }
        Ok(())
    }
}

/// What the GPU found along a carried ray: its crossings counted, or listed.
enum Found<'a> {
    Count(CrossingCount),
    List(&'a [Crossing]),
}

/// `n` answers, their memory asked of the allocator first.
fn answers<T: Clone + Default>(n: usize) -> GpuResult<Vec<T>> {
    octrace_format::memory::try_vec(n, "answers").map_err(|e| GpuError::Memory(crate::Error::from(e)))
}

/// Each ray's first [`GPU_BOXES`] boxes: the top level's walks on all cores, a few
/// thousand rays a task.
fn boxes_of(world: &World, rays: &[Ray], timings: &mut GpuWorldTimings) -> Boxes {
    let t = Instant::now();
    let mut boxes = Boxes::default();
    let parts: Vec<Boxes> = rays.par_chunks(4096).map(|r| Boxes::of(world, r, GPU_BOXES)).collect();
    for part in parts {
        boxes.append(part);
    }
    timings.top += t.elapsed();
    boxes
}

/// The instances of ray `i`'s boxes.
fn asked(boxes: &Boxes, i: usize) -> Vec<u32> {
    boxes.of_ray(i).iter().map(|b| b.1).collect()
}

/// A round's walks on the GPU: the jobs split by scene, each scene's carried rays of
/// every instance traced in one batch.
struct OnGpu<'g> {
    gpu: &'g GpuWorld,
    /// Each world scene's tracer ([`GpuWorld::devices`]).
    devices: Vec<usize>,
    /// Scratch: each job's tracer, a scene's rays, their jobs.
    by_scene: Vec<u32>,
    rays: Vec<Ray>,
    at: Vec<u32>,
    timings: GpuWorldTimings,
}

impl Walker for OnGpu<'_> {
    type Error = GpuError;

    fn walk(
        &mut self,
        world: &World,
        any: bool,
        jobs: &[(u32, u32)],
        local: &[Ray],
        hits: &mut [Option<Hit>],
    ) -> GpuResult<()> {
        self.timings.round_count += 1;
        self.by_scene.clear();
        for &(id, _) in jobs {
            let (scene, _, _) = world.placement(id).expect("a job is a committed instance's");
            self.by_scene.push(self.devices[scene as usize] as u32);
        }
        for (d, on_device) in self.gpu.on_device.iter().enumerate() {
            self.at.clear();
            self.at.extend((0..jobs.len() as u32).filter(|&k| self.by_scene[k as usize] == d as u32));
            if self.at.is_empty() {
                continue;
            }
            self.rays.clear();
            self.rays.extend(self.at.iter().map(|&k| local[k as usize]));
            let t = Instant::now();
            let found = on_device.tracer.trace_timed(&self.rays, any)?.0;
            self.timings.device += t.elapsed();
            for (&k, hit) in self.at.iter().zip(found) {
                hits[k as usize] = hit;
            }
        }
        Ok(())
    }
}
