//! The GPU's batch path: compact records, chunks in flight, buffers kept between
//! calls, camera rays made on the device, and rays already in the application's
//! buffers; every answer the CPU's, bit for bit.

use octrace_runtime::gpu::{
    wgpu, Answers, GpuCamera, GpuContext, GpuHit, GpuNearest, GpuOptions, GpuTracer, HitRecord,
};
use octrace_runtime::raysets::{self, Camera, Frame};
use octrace_runtime::{Hit, Ray, Scene};
use octrace_tests::{bunny_mesh, bunny_scene, gpu, gpu_default_hits, gpu_default_occluded};

/// A hit's bits: (triangle, t, u, v).
fn bits(h: &Option<Hit>) -> Option<[u32; 4]> {
    h.map(|h| [h.triangle, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()])
}

/// Every record the batch path sends back equals the CPU's answer for the same ray.
fn check_records(tracer: &GpuTracer<'_>, scene: &Scene, rays: &[Ray], what: &str) {
    let cpu = gpu_default_hits(scene, rays);
    let occluded = gpu_default_occluded(scene, rays);
    let mut full = vec![GpuHit::default(); rays.len()];
    tracer.trace_into(rays, false, Answers::Full(&mut full)).unwrap();
    let mut nearest = vec![GpuNearest::default(); rays.len()];
    tracer.trace_into(rays, false, Answers::Nearest(&mut nearest)).unwrap();
    let mut distance = vec![0f32; rays.len()];
    tracer.trace_into(rays, false, Answers::Distance(&mut distance)).unwrap();
    let mut words = vec![0xDEAD_BEEFu32; rays.len().div_ceil(32)];
    tracer.trace_into(rays, true, Answers::Occluded(&mut words)).unwrap();
    let mut wrong = 0;
    for (i, c) in cpu.iter().enumerate() {
        let (t, triangle) = c.map_or((f32::INFINITY, u32::MAX), |h| (h.t, h.triangle));
        let ok = bits(c) == bits(&full[i].hit())
            && nearest[i].t.to_bits() == t.to_bits()
            && nearest[i].triangle == triangle
            && distance[i].to_bits() == t.to_bits()
            && (words[i / 32] >> (i % 32) & 1 != 0) == occluded[i];
        if !ok && wrong < 5 {
            eprintln!(
                "{what}: ray {i}: CPU {c:?}, occluded {}; GPU {:?}, {:?}, {}, bit {}",
                occluded[i],
                full[i].hit(),
                nearest[i],
                distance[i],
                words[i / 32] >> (i % 32) & 1
            );
        }
        wrong += usize::from(!ok);
    }
    // The bits past the last ray are zero.
    if !rays.len().is_multiple_of(32) {
        assert_eq!(words[words.len() - 1] >> (rays.len() % 32), 0, "{what}: bits past the last ray");
    }
    assert_eq!(wrong, 0, "{what}: {wrong} of {} rays answered otherwise than on the CPU", rays.len());
}

/// The bunny's primary and incoherent rays, a count that is no multiple of 32 or of a
/// chunk.
fn bunny_rays() -> Vec<Ray> {
    let frame = Frame::from_triangles(&bunny_mesh().triangles);
    let mut rays: Vec<Ray> = Camera::standard_sized(&frame, 96, 80).rays();
    rays.extend(raysets::incoherent(&frame, 6_001));
    rays
}

/// Every record layout, for chunk sizes from one workgroup to the whole batch and one
/// to three chunks in flight, through the kernel's own mapped buffers (lavapipe's
/// memory is the host's) and through staging copies (as on a discrete GPU): the CPU's
/// answers, bit for bit.
#[test]
fn every_record_layout_chunk_size_and_depth_gives_the_cpus_answers() {
    let Some(shared) = gpu("every_record_layout_chunk_size_and_depth_gives_the_cpus_answers") else { return };
    let staged = GpuContext::new_staged().unwrap();
    let scene = bunny_scene();
    let rays = bunny_rays();
    for (name, ctx) in [("mapped", shared), ("staged", &staged)] {
        for (chunk, in_flight) in [(64, 1), (64, 3), (1000, 2), (4096, 3), (1 << 18, 3)] {
            let options = GpuOptions { chunk_rays: Some(chunk), in_flight: Some(in_flight), ..GpuOptions::default() };
            let tracer = GpuTracer::with_options(&ctx.device, &ctx.queue, scene, options).unwrap();
            check_records(&tracer, scene, &rays, &format!("{name}, chunks of {chunk}, {in_flight} in flight"));
        }
    }
}

/// Buffers are made by the first call and reused by the next ones (a larger batch
/// than any before may grow them; the same batch never does).
#[test]
fn the_batch_path_makes_no_buffer_after_the_first_call() {
    let Some(ctx) = gpu("the_batch_path_makes_no_buffer_after_the_first_call") else { return };
    let scene = bunny_scene();
    let rays = bunny_rays();
    let options = GpuOptions { chunk_rays: Some(2048), ..GpuOptions::default() };
    let tracer = GpuTracer::with_options(&ctx.device, &ctx.queue, scene, options).unwrap();
    let mut hits = vec![GpuHit::default(); rays.len()];
    tracer.trace_into(&rays, false, Answers::Full(&mut hits)).unwrap();
    let first = tracer.buffers_created();
    assert!(first > 0);
    let mut nearest = vec![GpuNearest::default(); rays.len()];
    for _ in 0..3 {
        tracer.trace_into(&rays, false, Answers::Full(&mut hits)).unwrap();
        tracer.trace_into(&rays, false, Answers::Nearest(&mut nearest)).unwrap();
        tracer.intersect(&rays[..100]).unwrap();
        tracer.occluded(&rays).unwrap();
    }
    assert_eq!(tracer.buffers_created(), first, "buffers made after the first call");
}

/// Camera rays made on the device are `GpuCamera::rays`, bit for bit: the GPU's
/// answers for them equal the CPU's for the host's rays, for the standard camera and
/// an Open3D pinhole camera, in every record.
#[test]
fn camera_rays_made_on_the_device_are_the_hosts() {
    let Some(ctx) = gpu("camera_rays_made_on_the_device_are_the_hosts") else { return };
    let scene = bunny_scene();
    let frame = Frame::from_triangles(&bunny_mesh().triangles);
    let standard = GpuCamera::from_camera(&Camera::standard_sized(&frame, 160, 90)).unwrap();
    // An Open3D camera on the axis of the standard view, 2.7 radii away.
    let eye = frame.c + glam::DVec3::new(0.0, 0.0, 2.7 * frame.r);
    let mut extrinsic = [[0.0; 4]; 4];
    (extrinsic[0][0], extrinsic[1][1], extrinsic[2][2], extrinsic[3][3]) = (1.0, -1.0, -1.0, 1.0);
    (extrinsic[0][3], extrinsic[1][3], extrinsic[2][3]) = (-eye.x, eye.y, eye.z);
    let pinhole =
        GpuCamera::pinhole([[120.0, 0.0, 64.0], [0.0, 120.0, 40.5], [0.0, 0.0, 1.0]], extrinsic, 127, 81).unwrap();
    let options = GpuOptions { chunk_rays: Some(3000), ..GpuOptions::default() };
    let tracer = GpuTracer::with_options(&ctx.device, &ctx.queue, scene, options).unwrap();
    for (name, camera) in [("standard", standard), ("pinhole", pinhole)] {
        let rays = camera.rays();
        let cpu = gpu_default_hits(scene, &rays);
        let hits = cpu.iter().filter(|h| h.is_some()).count();
        assert!(hits > rays.len() / 10, "{name}: the camera sees the bunny ({hits} hits)");
        let mut full = vec![GpuHit::default(); camera.len()];
        tracer.trace_camera_into(&camera, false, Answers::Full(&mut full)).unwrap();
        let mut distance = vec![0f32; camera.len()];
        tracer.trace_camera_into(&camera, false, Answers::Distance(&mut distance)).unwrap();
        let mut words = vec![0u32; camera.len().div_ceil(32)];
        tracer.trace_camera_into(&camera, true, Answers::Occluded(&mut words)).unwrap();
        for (i, c) in cpu.iter().enumerate() {
            assert_eq!(bits(c), bits(&full[i].hit()), "{name}: pixel {i}");
            assert_eq!(c.map_or(f32::INFINITY, |h| h.t).to_bits(), distance[i].to_bits(), "{name}: pixel {i}");
            assert_eq!(c.is_some(), words[i / 32] >> (i % 32) & 1 != 0, "{name}: pixel {i}");
        }
    }
    // Pinhole depth: a pixel's distance is its depth along the optical axis.
    let centre = (40 * 127 + 63) as usize;
    let ray = pinhole.ray_at(centre);
    assert!((ray.dir.z + 1.0).abs() < 1e-2, "the optical axis is -z: {:?}", ray.dir);
}

/// Rays already in the application's buffer, traced into its own buffer on its own
/// device and queue: the CPU's answers.
#[test]
fn rays_in_the_applications_buffers_trace_without_the_host() {
    let Some(ctx) = gpu("rays_in_the_applications_buffers_trace_without_the_host") else { return };
    let scene = bunny_scene();
    let rays = bunny_rays();
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, scene).unwrap();
    use wgpu::util::DeviceExt;
    let ray_buffer = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("application rays"),
        contents: bytemuck::cast_slice(&rays),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bytes = HitRecord::Nearest.bytes(rays.len() as u64);
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
    let answers = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage,
        mapped_at_creation: false,
    });
    let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    tracer.encode_trace(&mut encoder, &ray_buffer, &answers, rays.len() as u32, false, HitRecord::Nearest).unwrap();
    encoder.copy_buffer_to_buffer(&answers, 0, &readback, 0, bytes);
    ctx.queue.submit([encoder.finish()]);
    readback.slice(..).map_async(wgpu::MapMode::Read, |r| r.unwrap());
    ctx.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None }).unwrap();
    let got: Vec<GpuNearest> = bytemuck::cast_slice(&readback.slice(..).get_mapped_range().unwrap()).to_vec();
    let cpu = gpu_default_hits(scene, &rays);
    for (i, (c, g)) in cpu.iter().zip(&got).enumerate() {
        let want = c.map_or(GpuNearest { t: f32::INFINITY, triangle: u32::MAX }, |h| GpuNearest {
            t: h.t,
            triangle: h.triangle,
        });
        assert_eq!((want.t.to_bits(), want.triangle), (g.t.to_bits(), g.triangle), "ray {i}");
    }
    // Too small a buffer is an error, not a panic in wgpu.
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let err = tracer.encode_trace(&mut encoder, &ray_buffer, &answers, rays.len() as u32, false, HitRecord::Full);
    assert!(err.unwrap_err().to_string().contains("bytes"));
}

/// Answers of the wrong length are an error naming both lengths.
#[test]
fn answers_of_the_wrong_length_are_refused() {
    let Some(ctx) = gpu("answers_of_the_wrong_length_are_refused") else { return };
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, bunny_scene()).unwrap();
    let rays = bunny_rays();
    let mut short = vec![0f32; rays.len() - 1];
    let e = tracer.trace_into(&rays, false, Answers::Distance(&mut short)).unwrap_err().to_string();
    assert!(e.contains(&format!("{} answers given for {} rays", rays.len() - 1, rays.len())), "{e}");
    let mut words = vec![0u32; rays.len() / 32];
    assert!(tracer.trace_into(&rays, true, Answers::Occluded(&mut words)).is_err());
}
