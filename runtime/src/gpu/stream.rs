//! Rays up and answers back at the bus's speed: the batch path of [`GpuTracer`].
//!
//! A batch is cut into chunks of rays, each traced in a slot of its own: the slot's
//! rays are written into mapped staging memory (or, on a device whose memory is the
//! host's, into the storage buffer itself), copied to the device, traced, and the
//! answers copied into mapped read-back memory that the host copies straight into the
//! caller's slice. Two or three slots are in flight, so a chunk's upload, its
//! neighbour's kernel and another's read-back overlap. The slots' buffers are kept
//! between calls and grown, never made per call ([`GpuTracer::buffers_created`]).
//!
//! The answers come back as compact as the query needs ([`HitRecord`]): the whole
//! record, distance and triangle, distance alone, or occlusion as one bit a ray.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::{GpuError, GpuHit, GpuResult, GpuTimings, GpuTracer, Params, Ray, OVER_BUDGET};
use crate::WalkStats;

/// What the GPU sends back for each ray: the least the query needs crosses the bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HitRecord {
    /// The whole answer ([`GpuHit`], 32 bytes a ray).
    Full,
    /// Distance and triangle ([`GpuNearest`], 8 bytes a ray).
    Nearest,
    /// Distance alone (`f32`, 4 bytes a ray; `+inf` on a miss).
    Distance,
    /// Occlusion: one bit a ray (bit `i % 32` of word `i / 32`).
    Occluded,
}

impl HitRecord {
    /// The kernel's `RECORD` constant.
    pub(super) fn code(self) -> f64 {
        match self {
            HitRecord::Full => 0.0,
            HitRecord::Nearest => 1.0,
            HitRecord::Distance => 2.0,
            HitRecord::Occluded => 3.0,
        }
    }

    /// Bytes the answers of `n` rays take in the hits buffer (occlusion: the bits and
    /// as many words of over-budget bits).
    pub fn bytes(self, n: u64) -> u64 {
        match self {
            HitRecord::Full => 32 * n,
            HitRecord::Nearest => 8 * n,
            HitRecord::Distance => 4 * n,
            HitRecord::Occluded => 8 * n.div_ceil(32),
        }
    }

    /// Bytes of the answers the caller gets for `n` rays.
    fn answer_bytes(self, n: u64) -> u64 {
        match self {
            HitRecord::Occluded => 4 * n.div_ceil(32),
            other => other.bytes(n),
        }
    }
}

/// A ray's distance and triangle ([`HitRecord::Nearest`]): on a miss `t` is `+inf` and
/// `triangle` `u32::MAX`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuNearest {
    /// Distance along the ray.
    pub t: f32,
    /// The triangle's input id (`u32::MAX`: no hit).
    pub triangle: u32,
}

/// Where [`GpuTracer::trace_into`] writes the answers, one of each record a ray (for
/// [`HitRecord::Occluded`], one word for each 32 rays).
#[derive(Debug)]
pub enum Answers<'a> {
    /// Whole records.
    Full(&'a mut [GpuHit]),
    /// Distance and triangle.
    Nearest(&'a mut [GpuNearest]),
    /// Distances (`+inf` on a miss).
    Distance(&'a mut [f32]),
    /// Occlusion bits: ray `i` is bit `i % 32` of word `i / 32`.
    Occluded(&'a mut [u32]),
}

impl Answers<'_> {
    /// The record these answers take.
    pub fn record(&self) -> HitRecord {
        match self {
            Answers::Full(_) => HitRecord::Full,
            Answers::Nearest(_) => HitRecord::Nearest,
            Answers::Distance(_) => HitRecord::Distance,
            Answers::Occluded(_) => HitRecord::Occluded,
        }
    }

    fn len(&self) -> usize {
        match self {
            Answers::Full(a) => a.len(),
            Answers::Nearest(a) => a.len(),
            Answers::Distance(a) => a.len(),
            Answers::Occluded(a) => a.len(),
        }
    }

    /// The answers' bytes.
    fn bytes_mut(&mut self) -> &mut [u8] {
        match self {
            Answers::Full(a) => bytemuck::cast_slice_mut(a),
            Answers::Nearest(a) => bytemuck::cast_slice_mut(a),
            Answers::Distance(a) => bytemuck::cast_slice_mut(a),
            Answers::Occluded(a) => bytemuck::cast_slice_mut(a),
        }
    }
}

/// Camera rays made on the device: ray `(column, row)` starts at `origin` with the
/// direction `(dx (column + 1/2) + dy (row + 1/2)) + d0`, each operation rounded to
/// `f32` ([`GpuCamera::ray_at`] is the same arithmetic on the CPU, so the GPU traces the
/// CPU's rays bit for bit). Directions are not normalized: for a pinhole camera made
/// with [`GpuCamera::pinhole`] a hit's distance is its depth along the optical axis,
/// as Open3D's `create_rays_pinhole` rays give.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuCamera {
    /// The eye.
    pub origin: [f32; 3],
    /// The direction of the image's top-left corner (column and row 0 at the pixel's
    /// corner).
    pub d0: [f32; 3],
    /// The direction's change a column.
    pub dx: [f32; 3],
    /// The direction's change a row.
    pub dy: [f32; 3],
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Each ray's `[tmin, tmax]`.
    pub tmin: f32,
    /// See `tmin`.
    pub tmax: f32,
}

impl GpuCamera {
    /// Pixels a side at most (rows and columns are exact in `f32`).
    pub const MAX_SIDE: u32 = 1 << 16;

    /// Open3D's pinhole camera: `intrinsic` (row major, `[[fx, 0, cx], [0, fy, cy],
    /// [0, 0, 1]]`), `extrinsic` the world-to-camera transform (row major), pixels
    /// sampled at their centres; rays with `t` in `[0, inf]`.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for a zero focal length, a skewed intrinsic matrix,
    /// non-finite numbers, or a side of 0 or more than [`GpuCamera::MAX_SIDE`].
    pub fn pinhole(intrinsic: [[f64; 3]; 3], extrinsic: [[f64; 4]; 4], width: u32, height: u32) -> GpuResult<Self> {
        let finite = intrinsic.iter().flatten().chain(extrinsic.iter().flatten()).all(|x| x.is_finite());
        let [fx, fy] = [intrinsic[0][0], intrinsic[1][1]];
        if !finite || fx == 0.0 || fy == 0.0 || intrinsic[0][1] != 0.0 {
            return Err(GpuError::Unsupported(
                "a pinhole camera needs finite matrices, non-zero focal lengths and no skew".into(),
            ));
        }
        Self::check_sides(width, height)?;
        let (cx, cy) = (intrinsic[0][2], intrinsic[1][2]);
        // The camera's axes are the rotation's rows, its centre -R^T t.
        let axis = |r: usize| glam::DVec3::new(extrinsic[r][0], extrinsic[r][1], extrinsic[r][2]);
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        let t = glam::DVec3::new(extrinsic[0][3], extrinsic[1][3], extrinsic[2][3]);
        let origin = -(ax * t.x + ay * t.y + az * t.z);
        let d0 = az - ax * (cx / fx) - ay * (cy / fy);
        Ok(GpuCamera {
            origin: origin.as_vec3().to_array(),
            d0: d0.as_vec3().to_array(),
            dx: (ax / fx).as_vec3().to_array(),
            dy: (ay / fy).as_vec3().to_array(),
            width,
            height,
            tmin: 0.0,
            tmax: f32::INFINITY,
        })
    }

    /// The perspective camera of a standard ray set ([`crate::raysets::Camera`]):
    /// the same view and pixels, its directions left unnormalized.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for an orthographic camera or a side of 0 or more
    /// than [`GpuCamera::MAX_SIDE`].
    pub fn from_camera(c: &crate::raysets::Camera) -> GpuResult<Self> {
        if c.orthographic.is_some() {
            return Err(GpuError::Unsupported("orthographic cameras are made on the host".into()));
        }
        Self::check_sides(c.width, c.height)?;
        let aspect = c.width as f64 / c.height as f64;
        let (sx, sy) = (c.tan_half_fov * aspect, c.tan_half_fov);
        // px = (column + 1/2) 2 sx / width - sx; py = sy - (row + 1/2) 2 sy / height.
        let dx = c.u * (2.0 * sx / c.width as f64);
        let dy = c.s * (-2.0 * sy / c.height as f64);
        let d0 = c.s * sy - c.u * sx - c.w;
        Ok(GpuCamera {
            origin: c.eye.as_vec3().to_array(),
            d0: d0.as_vec3().to_array(),
            dx: dx.as_vec3().to_array(),
            dy: dy.as_vec3().to_array(),
            width: c.width,
            height: c.height,
            tmin: 0.0,
            tmax: f32::INFINITY,
        })
    }

    fn check_sides(width: u32, height: u32) -> GpuResult<()> {
        if width == 0 || height == 0 || width > Self::MAX_SIDE || height > Self::MAX_SIDE {
            return Err(GpuError::Unsupported(format!(
                "a {width} x {height} camera: sides must be 1 to {}",
                Self::MAX_SIDE
            )));
        }
        Ok(())
    }

    /// Rays (pixels).
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether the camera has no pixels (never: the constructors refuse).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The ray of pixel `index` (row by row), with the kernel's arithmetic.
    pub fn ray_at(&self, index: usize) -> Ray {
        let (x, y) = ((index % self.width as usize) as f32 + 0.5, (index / self.width as usize) as f32 + 0.5);
        let d = std::array::from_fn(|k| self.dx[k] * x + self.dy[k] * y + self.d0[k]);
        Ray { origin: self.origin.into(), tmin: self.tmin, dir: d.into(), tmax: self.tmax }
    }

    /// Every ray, row by row.
    pub fn rays(&self) -> Vec<Ray> {
        (0..self.len()).map(|i| self.ray_at(i)).collect()
    }

    /// The kernel's four vec4s for the chunk starting at pixel `first`.
    fn words(&self, first: u32) -> [f32; 16] {
        let o = self.origin;
        let [d0, dx, dy] = [self.d0, self.dx, self.dy];
        [
            o[0],
            o[1],
            o[2],
            self.tmin,
            d0[0],
            d0[1],
            d0[2],
            self.tmax,
            dx[0],
            dx[1],
            dx[2],
            f32::from_bits(self.width),
            dy[0],
            dy[1],
            dy[2],
            f32::from_bits(first),
        ]
    }
}

/// Where a batch's rays come from.
#[derive(Clone, Copy)]
pub(super) enum Source<'a> {
    Rays(&'a [Ray]),
    Camera(&'a GpuCamera),
}

impl Source<'_> {
    fn len(&self) -> usize {
        match self {
            Source::Rays(r) => r.len(),
            Source::Camera(c) => c.len(),
        }
    }

    fn ray(&self, i: usize) -> Ray {
        match self {
            Source::Rays(r) => r[i],
            Source::Camera(c) => c.ray_at(i),
        }
    }
}

/// Which kernel a batch runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kernel {
    /// The nearest hit, or with `any` any hit; walks out of loop budget are traced
    /// again on the CPU.
    Trace { any: bool },
    /// Crossing counts (full records; the caller finishes walks out of budget).
    Counts,
}

/// How a batch is cut and pipelined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Pipelining {
    /// Rays a chunk (a multiple of 64).
    pub chunk: usize,
    /// Chunks in flight.
    pub in_flight: usize,
}

/// Rays a chunk by default: the most a dispatch takes. On an H200 the dragon's primary
/// rays run at 499 Mrays/s (GPU clock) in chunks of 2^18, 866 in chunks of 2^20 and
/// 1,006 in chunks of 2^21: a dispatch's last wave leaves the GPU part idle, and wgpu's
/// barriers keep the next chunk's copies from overlapping the kernel (BENCHMARKS).
pub(super) const DEFAULT_CHUNK: usize = 1 << 21;
/// Chunks in flight by default: one being traced while the host fills the next.
pub(super) const DEFAULT_IN_FLIGHT: usize = 2;

/// The slots' buffers, kept between calls.
#[derive(Debug, Default)]
pub(super) struct Streams {
    slots: Vec<Slot>,
    created: u64,
}

impl Streams {
    pub(super) fn created(&self) -> u64 {
        self.created
    }
}

#[derive(Debug)]
enum MapState {
    Mapped,
    Pending(mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>),
}

#[derive(Debug)]
struct Slot {
    /// Rays the slot's buffers hold.
    capacity: u64,
    /// The kernel's rays (written straight when `upload` is `None`).
    rays: wgpu::Buffer,
    /// Staging for the rays, mapped for writing between uses.
    upload: Option<wgpu::Buffer>,
    /// Whether the buffer written on the host (`upload`, else `rays`) is mapped.
    writable: MapState,
    /// The kernel's answers (read straight when `readback` is `None`).
    hits: wgpu::Buffer,
    /// Read-back memory: 16 bytes of timestamps, then the answers.
    readback: Option<wgpu::Buffer>,
    params: wgpu::Buffer,
    group: wgpu::BindGroup,
    /// Timestamps around the slot's pass.
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    pending: Option<Pending>,
}

impl Slot {
    /// The buffer the host reads answers from, and where in it: (that buffer, the
    /// answers' offset, the timestamps' offset, the end of the range to map) for
    /// `out_bytes` of answers. Read-back memory holds the timestamps first; the hits
    /// buffer, read straight, holds them in its last 16 bytes.
    fn read_layout(&self, out_bytes: u64) -> (&wgpu::Buffer, u64, u64, u64) {
        match &self.readback {
            Some(readback) => (readback, 16, 0, 16 + out_bytes),
            None => (&self.hits, 0, self.hits.size() - 16, self.hits.size()),
        }
    }
}

#[derive(Debug)]
struct Pending {
    submission: wgpu::SubmissionIndex,
    start: usize,
    count: usize,
    /// Whether the chunk's pass was timed (the timestamps come back with its answers).
    timed: bool,
    readable: mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

/// Bytes copied by one thread at a time (larger copies are split across threads).
const COPY_PIECE: usize = 1 << 20;

/// `src` into the mapped `dst`, in pieces on the thread pool when large.
fn copy_to_mapped(mut dst: wgpu::WriteOnly<'_, [u8]>, src: &[u8]) {
    if src.len() <= 2 * COPY_PIECE {
        dst.copy_from_slice(src);
        return;
    }
    assert_eq!(dst.len(), src.len(), "a mapped range the size of its source");
    /// The mapped range's start, shared by the threads that write its pieces.
    #[derive(Clone, Copy)]
    struct Dst(std::ptr::NonNull<u8>);
    // SAFETY: the threads write disjoint pieces of the one mapped range, which outlives
    // the scope (`dst` is borrowed until this function returns).
    unsafe impl Send for Dst {}
    // SAFETY: as for Send: shared only to compute disjoint pieces' addresses.
    unsafe impl Sync for Dst {}
    let base = Dst(dst.as_raw_element_ptr());
    src.par_chunks(COPY_PIECE).enumerate().for_each(|(k, piece)| {
        let at = base;
        // SAFETY: piece k is `src[k * COPY_PIECE..][..piece.len()]`, inside the mapped
        // range of `src.len()` bytes (checked above); pieces do not overlap.
        unsafe { std::ptr::copy_nonoverlapping(piece.as_ptr(), at.0.as_ptr().add(k * COPY_PIECE), piece.len()) }
    });
}

/// The mapped `src` into `dst`, in pieces on the thread pool when large.
fn copy_from_mapped(dst: &mut [u8], src: &[u8]) {
    if src.len() <= 2 * COPY_PIECE {
        dst.copy_from_slice(src);
        return;
    }
    dst.par_chunks_mut(COPY_PIECE).zip(src.par_chunks(COPY_PIECE)).for_each(|(d, s)| d.copy_from_slice(s));
}

fn map_error(e: impl std::fmt::Display) -> GpuError {
    GpuError::Device(e.to_string())
}

/// Maps `buffer`'s `range` for `mode`; the receiver says when it is done.
fn map(
    buffer: &wgpu::Buffer,
    range: std::ops::Range<u64>,
    mode: wgpu::MapMode,
) -> mpsc::Receiver<Result<(), wgpu::BufferAsyncError>> {
    let (send, receive) = mpsc::channel();
    buffer.slice(range).map_async(mode, move |r| {
        let _ = send.send(r);
    });
    receive
}

/// Waits for a map asked with [`map`].
fn mapped(device: &wgpu::Device, receive: &mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>) -> GpuResult<()> {
    loop {
        match receive.try_recv() {
            Ok(r) => return r.map_err(map_error),
            Err(mpsc::TryRecvError::Empty) => super::device::wait(device)?,
            Err(mpsc::TryRecvError::Disconnected) => return Err(GpuError::Device("a buffer map was dropped".into())),
        }
    }
}

impl GpuTracer<'_> {
    /// Traces `source` with the kernel for (`any`, the answers' record) into `answers`,
    /// pipelined; `skip_kernel` leaves the kernel out (the transfers alone, for
    /// [`GpuTracer::time_transfers`]).
    pub(super) fn stream(
        &self,
        source: Source<'_>,
        kernel: Kernel,
        mut answers: Answers<'_>,
        skip_kernel: bool,
    ) -> GpuResult<GpuTimings> {
        let started = Instant::now();
        let n = source.len();
        let record = answers.record();
        let expected = match record {
            HitRecord::Occluded => n.div_ceil(32),
            _ => n,
        };
        if answers.len() != expected {
            return Err(GpuError::Mismatch(format!(
                "{} answers given for {n} rays, where {record:?} records need {expected}",
                answers.len()
            )));
        }
        let mut timings = GpuTimings::default();
        if n == 0 {
            return Ok(timings);
        }
        let camera = matches!(source, Source::Camera(_));
        // Bits need workgroups of whole words; a workgroup of one (a driver whose loop
        // cap the whole workgroup shares) gets the triangles, packed here.
        if record == HitRecord::Occluded && !self.budget.workgroup.is_multiple_of(32) {
            return self.occlusion_packed_here(source, answers, skip_kernel);
        }
        let pipeline = match kernel {
            Kernel::Trace { any } => self.pipeline(any || record == HitRecord::Occluded, record, camera)?,
            Kernel::Counts => self.crossing_kernels()?[0].clone(),
        };
        let plan = self.pipelining;
        let chunk = plan.chunk.min(self.budget.per_dispatch(super::RAYS_PER_DISPATCH as u32) as usize);
        let chunks = n.div_ceil(chunk);
        let mut streams = self.streams.lock().unwrap_or_else(|e| e.into_inner());
        let result = (|| {
            let slots = plan.in_flight.min(chunks);
            self.prepare_slots(&mut streams, slots, chunk.min(n) as u64);
            let Streams { slots: slot_list, .. } = &mut *streams;
            for k in 0..chunks {
                let start = k * chunk;
                let count = chunk.min(n - start);
                let slot = &mut slot_list[k % slots];
                if let Some(p) = slot.pending.take() {
                    self.finish(slot, p, source, kernel, &mut answers, &mut timings)?;
                }
                self.launch(slot, &pipeline, source, start, count, record, skip_kernel, &mut timings)?;
            }
            for k in chunks..chunks + slots {
                let slot = &mut slot_list[k % slots];
                if let Some(p) = slot.pending.take() {
                    self.finish(slot, p, source, kernel, &mut answers, &mut timings)?;
                }
            }
            Ok(())
        })();
        if result.is_err() {
            // Buffers in an unknown state of mapping: made again at the next call.
            streams.slots.clear();
        }
        result?;
        timings.total = started.elapsed();
        Ok(timings)
    }

    /// `slots` slots of at least `rays` rays each (grown to the next power of two, so
    /// that growing batches make buffers a few times, not every call).
    fn prepare_slots(&self, streams: &mut Streams, slots: usize, rays: u64) {
        let capacity = rays.next_power_of_two().max(1024).min(self.pipelining.chunk as u64).max(rays);
        streams.slots.retain(|s| s.capacity >= rays);
        while streams.slots.len() < slots {
            let (slot, made) = self.make_slot(capacity);
            streams.created += made;
            streams.slots.push(slot);
        }
    }

    /// A slot for `capacity` rays, and how many buffers it took.
    fn make_slot(&self, capacity: u64) -> (Slot, u64) {
        use wgpu::BufferUsages as U;
        let direct = self.device.features().contains(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS);
        let ray_bytes = 32 * capacity;
        let hit_bytes = HitRecord::Full.bytes(capacity) + 16;
        let buffer = |label: &str, size: u64, usage: U, mapped: bool| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: mapped,
            })
        };
        let mut made = 3;
        let (rays, upload) = if direct {
            (buffer("octrace rays", ray_bytes, U::STORAGE | U::MAP_WRITE, true), None)
        } else {
            made += 1;
            (
                buffer("octrace rays", ray_bytes, U::STORAGE | U::COPY_DST, false),
                Some(buffer("octrace ray staging", ray_bytes, U::MAP_WRITE | U::COPY_SRC, true)),
            )
        };
        let (hits, readback) = if direct {
            (buffer("octrace hits", hit_bytes, U::STORAGE | U::MAP_READ | U::COPY_DST, false), None)
        } else {
            made += 1;
            (
                buffer("octrace hits", hit_bytes, U::STORAGE | U::COPY_SRC, false),
                Some(buffer("octrace readback", hit_bytes, U::MAP_READ | U::COPY_DST, false)),
            )
        };
        let params = buffer("octrace params", std::mem::size_of::<Params>() as u64, U::UNIFORM | U::COPY_DST, false);
        let group = self.bind_group(&params, &rays, &hits);
        let queries = self.timestamps.map(|_| {
            made += 1;
            (
                self.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("octrace chunk time"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2,
                }),
                buffer("octrace chunk time", 16, U::QUERY_RESOLVE | U::COPY_SRC, false),
            )
        });
        let slot = Slot {
            capacity,
            rays,
            upload,
            writable: MapState::Mapped,
            hits,
            readback,
            params,
            group,
            queries,
            pending: None,
        };
        (slot, made)
    }

    /// Writes a chunk's rays and submits its kernel and read-back.
    #[allow(clippy::too_many_arguments)]
    fn launch(
        &self,
        slot: &mut Slot,
        pipeline: &wgpu::ComputePipeline,
        source: Source<'_>,
        start: usize,
        count: usize,
        record: HitRecord,
        skip_kernel: bool,
        timings: &mut GpuTimings,
    ) -> GpuResult<()> {
        let t = Instant::now();
        let params = Params { ray_count: if skip_kernel { 0 } else { count as u32 }, ..self.params };
        self.queue.write_buffer(&slot.params, 0, bytemuck::bytes_of(&params));
        let written = slot.upload.as_ref().unwrap_or(&slot.rays);
        if let MapState::Pending(receive) = &slot.writable {
            mapped(&self.device, receive)?;
        }
        let camera_words;
        let bytes: &[u8] = match source {
            Source::Rays(r) => bytemuck::cast_slice(&r[start..start + count]),
            Source::Camera(c) => {
                camera_words = c.words(start as u32);
                bytemuck::cast_slice(&camera_words)
            }
        };
        {
            let mut view = written.slice(..bytes.len() as u64).get_mapped_range_mut().map_err(map_error)?;
            copy_to_mapped(view.slice(..), bytes);
        }
        written.unmap();
        timings.upload += t.elapsed();

        let out_bytes = record.bytes(count as u64);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        if let Some(upload) = &slot.upload {
            encoder.copy_buffer_to_buffer(upload, 0, &slot.rays, 0, bytes.len() as u64);
        }
        if !skip_kernel {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("octrace trace"),
                timestamp_writes: slot.queries.as_ref().map(|(q, _)| wgpu::ComputePassTimestampWrites {
                    query_set: q,
                    beginning_of_pass_write_index: Some(0),
                    end_of_pass_write_index: Some(1),
                }),
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &slot.group, &[]);
            pass.dispatch_workgroups((count as u32).div_ceil(self.budget.workgroup), 1, 1);
        }
        let (readable, records_at, stamps_at, map_end) = slot.read_layout(out_bytes);
        if let Some(readback) = &slot.readback {
            encoder.copy_buffer_to_buffer(&slot.hits, 0, readback, records_at, out_bytes);
        }
        if let (Some((queries, resolve)), false) = (&slot.queries, skip_kernel) {
            encoder.resolve_query_set(queries, 0..2, resolve, 0);
            encoder.copy_buffer_to_buffer(resolve, 0, readable, stamps_at, 16);
        }
        let submission = self.queue.submit([encoder.finish()]);
        let readable = map(readable, 0..map_end, wgpu::MapMode::Read);
        slot.writable = MapState::Pending(map(written, 0..written.size(), wgpu::MapMode::Write));
        let timed = slot.queries.is_some() && !skip_kernel;
        slot.pending = Some(Pending { submission, start, count, timed, readable });
        Ok(())
    }

    /// Waits for a chunk, copies its answers out, and traces on the CPU the walks that
    /// ran out of loop budget.
    fn finish(
        &self,
        slot: &mut Slot,
        p: Pending,
        source: Source<'_>,
        kernel: Kernel,
        answers: &mut Answers<'_>,
        timings: &mut GpuTimings,
    ) -> GpuResult<()> {
        let t = Instant::now();
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(p.submission), timeout: None })
            .map_err(map_error)?;
        mapped(&self.device, &p.readable)?;
        timings.kernel += t.elapsed();

        let t = Instant::now();
        let record = answers.record();
        let out_bytes = record.answer_bytes(p.count as u64) as usize;
        let (readable, records_at, stamps_at, map_end) = slot.read_layout(record.bytes(p.count as u64));
        // Where the chunk's answers go (a chunk starts at a multiple of 32 rays).
        let first = record.answer_bytes(p.start as u64) as usize;
        let mut over = Vec::new();
        {
            let view = readable.slice(..map_end).get_mapped_range().map_err(map_error)?;
            let records = &view[records_at as usize..];
            copy_from_mapped(&mut answers.bytes_mut()[first..first + out_bytes], &records[..out_bytes]);
            if p.timed {
                let stamps: [u64; 2] = bytemuck::pod_read_unaligned(&view[stamps_at as usize..stamps_at as usize + 16]);
                let ticks = stamps[1].saturating_sub(stamps[0]) as f64;
                let period = self.timestamps.unwrap_or(1.0);
                timings.kernel_device =
                    Some(timings.kernel_device.unwrap_or_default() + Duration::from_nanos((ticks * period) as u64));
            }
            if record == HitRecord::Occluded && (self.cap.is_some() || self.exact()) {
                let words = p.count.div_ceil(32);
                over = bytemuck::cast_slice::<u8, u32>(&records[4 * words..8 * words]).to_vec();
            }
        }
        readable.unmap();
        timings.download += t.elapsed();
        if let Kernel::Trace { any } = kernel {
            if self.cap.is_some() || self.exact() {
                self.finish_on_cpu(source, any, answers, p.start, p.count, &over);
            }
        }
        Ok(())
    }

    /// The walks of a chunk that ran out of the adapter's loop budget, or that the exact
    /// test's filter handed back, traced on the CPU into `answers` (`over`: the chunk's
    /// handed-back bits, for occlusion).
    fn finish_on_cpu(
        &self,
        source: Source<'_>,
        any: bool,
        answers: &mut Answers<'_>,
        start: usize,
        count: usize,
        over: &[u32],
    ) {
        let tracer = self.cpu_tracer();
        let finished = std::cell::Cell::new(0usize);
        let nearest = |i: usize| {
            finished.set(finished.get() + 1);
            let r = source.ray(i);
            if any {
                (tracer.occluder(&r), WalkStats::default())
            } else {
                tracer.intersect_with_stats(&r)
            }
        };
        match answers {
            Answers::Full(a) => {
                for i in start..start + count {
                    if a[i].steps == OVER_BUDGET {
                        let (hit, stats) = nearest(i);
                        a[i] = super::from_hit(hit, stats);
                    }
                }
            }
            Answers::Nearest(a) => {
                for i in start..start + count {
                    if a[i].t.to_bits() == OVER_BUDGET_T {
                        let hit = nearest(i).0;
                        a[i] = hit.map_or(GpuNearest { t: f32::INFINITY, triangle: u32::MAX }, |h| GpuNearest {
                            t: h.t,
                            triangle: h.triangle,
                        });
                    }
                }
            }
            Answers::Distance(a) => {
                for i in start..start + count {
                    if a[i].to_bits() == OVER_BUDGET_T {
                        a[i] = nearest(i).0.map_or(f32::INFINITY, |h| h.t);
                    }
                }
            }
            Answers::Occluded(a) => {
                for (w, bits) in over.iter().enumerate() {
                    for b in (0..32).filter(|b| bits >> b & 1 != 0) {
                        let i = start + 32 * w + b;
                        finished.set(finished.get() + 1);
                        let word = &mut a[i / 32];
                        *word &= !(1 << (i % 32));
                        *word |= u32::from(tracer.occluder(&source.ray(i)).is_some()) << (i % 32);
                    }
                }
            }
        }
        self.finished_here(finished.get());
    }

    /// Occlusion bits where workgroups are not whole words: the kernel's triangles,
    /// packed on the host.
    fn occlusion_packed_here(
        &self,
        source: Source<'_>,
        answers: Answers<'_>,
        skip_kernel: bool,
    ) -> GpuResult<GpuTimings> {
        let Answers::Occluded(words) = answers else { unreachable!("only occlusion is packed here") };
        let mut nearest = vec![GpuNearest::default(); source.len()];
        let timings = self.stream(source, Kernel::Trace { any: true }, Answers::Nearest(&mut nearest), skip_kernel)?;
        words.fill(0);
        for (i, h) in nearest.iter().enumerate() {
            words[i / 32] |= u32::from(h.triangle != u32::MAX) << (i % 32);
        }
        Ok(timings)
    }
}

/// Record 1 and 2's distance for a walk that ran out of loop budget (`OVER_BUDGET_T`
/// in trace.wgsl).
const OVER_BUDGET_T: u32 = 0x7FC0_B0D6;
