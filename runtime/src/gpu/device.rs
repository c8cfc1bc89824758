//! The device and what its driver does: the Vulkan context, the loop cap some drivers
//! put on shader invocations and the budget the kernels keep under it, GPU timestamps,
//! and reading buffers back.

use super::{GpuError, GpuResult};

/// A Vulkan device and its queue.
#[derive(Debug)]
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What the adapter is (name, driver, device type).
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// Opens the first Vulkan adapter (a discrete GPU preferred), with the largest
    /// storage bindings and buffers it allows and 64-bit floats where it has them.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] without a Vulkan driver; [`GpuError::Device`] if the
    /// adapter refuses the device.
    pub fn new() -> GpuResult<GpuContext> {
        Self::open(true)
    }

    /// [`GpuContext::new`], with the batch path staging rays and answers through copies
    /// even where the device's memory is the host's (as it must on a discrete GPU):
    /// to compare the two paths on one machine.
    ///
    /// # Errors
    /// As [`GpuContext::new`].
    pub fn new_staged() -> GpuResult<GpuContext> {
        Self::open(false)
    }

    fn open(map_storage: bool) -> GpuResult<GpuContext> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::VULKAN;
        let instance = wgpu::Instance::new(desc);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let limits = adapter.limits();
        let required_limits = wgpu::Limits {
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            max_buffer_size: limits.max_buffer_size,
            max_storage_buffers_per_shader_stage: limits.max_storage_buffers_per_shader_stage,
            max_buffers_and_acceleration_structures_per_shader_stage: limits
                .max_buffers_and_acceleration_structures_per_shader_stage,
            ..wgpu::Limits::defaults()
        };
        // 64-bit floats for the exact paths; kernels compiled here (`spirv`); timestamps to
        // time kernels on the device.
        let mut wanted =
            wgpu::Features::SHADER_F64 | wgpu::Features::PASSTHROUGH_SHADERS | wgpu::Features::TIMESTAMP_QUERY;
        // Where the device's memory is the host's, rays are written into and answers
        // read from the kernel's own buffers (no staging copies: `stream`).
        let info = adapter.get_info();
        // `OCTRACE_GPU_MAPPED=1` asks it of any adapter (a discrete GPU's kernel then reads
        // the rays and writes the answers across the bus: to measure).
        let forced = std::env::var("OCTRACE_GPU_MAPPED").is_ok_and(|v| v == "1");
        if map_storage
            && (forced || matches!(info.device_type, wgpu::DeviceType::Cpu | wgpu::DeviceType::IntegratedGpu))
        {
            wanted |= wgpu::Features::MAPPABLE_PRIMARY_BUFFERS;
        }
        let required_features = adapter.features() & wanted;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("octrace"),
            required_features,
            required_limits,
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(GpuContext { device, queue, info })
    }

    /// One line about the adapter: name, driver, type.
    pub fn describe(&self) -> String {
        let i = &self.info;
        format!("{} ({} {}, {:?})", i.name, i.driver, i.driver_info, i.device_type)
    }
}

/// Threads a workgroup (`WORKGROUP_SIZE` in trace.wgsl) where the adapter runs loops
/// without a cap.
const WORKGROUP: u32 = 64;
/// Threads a workgroup where the adapter has no loop cap: [`WORKGROUP`], or
/// `OCTRACE_GPU_WORKGROUP` (32, 64, 128 or 256; WebGPU's default limit is 256) to measure
/// occupancy on a given GPU. Answers do not depend on it: every ray is walked by one
/// invocation alone.
fn uncapped_workgroup() -> u32 {
    match std::env::var("OCTRACE_GPU_WORKGROUP").ok().and_then(|v| v.parse::<u32>().ok()) {
        Some(n @ (32 | 64 | 128 | 256)) => n,
        _ => WORKGROUP,
    }
}

/// Loop iterations a pixel's ray tree may run in the render kernel on an adapter that
/// caps loops (lavapipe) before the pixel is handed back and rendered on the CPU (the
/// cap itself would allow 4,095). Such an adapter runs eight invocations in lockstep on
/// the host's own cores, so a pixel whose tree runs long (the effects scene's glass:
/// its median pixel runs 478 iterations, its 99th percentile 17,800) holds seven lanes
/// idle for every iteration past its neighbours', where the CPU would finish it alone.
/// Measured on the effects scene at 256 px (lavapipe on a 2-core Xeon, `render --gpu
/// --json`, same images): 4,095 an invocation 2.50 s (5,570 of 49,152 pixels handed
/// back), 2,048 2.0 s, 1,024 1.40 s (13,323), 512 1.10 s (21,810), the CPU alone 0.27 s.
/// 1,024 keeps three pixels in four on the device. Hardware drivers have no cap, and
/// their budget no bound.
const RENDER_LOOPS: u32 = 1024;

/// Workgroups a dispatch dimension may hold (WebGPU's limit).
const MAX_WORKGROUPS: u32 = 65_535;

/// How the kernels bound their loops on this adapter (see [`loop_cap`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Budget {
    /// Invocations a workgroup.
    pub workgroup: u32,
    /// Loop iterations an invocation may run (`u32::MAX`: no bound).
    pub loops: u32,
}

impl Budget {
    /// The budget for an adapter that caps the loop iterations of a group of `lanes`
    /// invocations run in lockstep at `cap` (`None`: no cap). The driver counts an
    /// iteration of a loop whenever one lane of the group runs it, over all loops
    /// together, so the group's count is at most the sum of its lanes' own: a lane gets
    /// `cap / (2 lanes)`, and workgroups stay full. Half, because the driver's count
    /// runs ahead of the kernel's own (lavapipe cut the render kernel short when the
    /// kernel had counted 58,000 to 61,300 iterations alone: loops of its own making,
    /// about 10 %). A lane that spends its budget stops, and the host finishes its ray
    /// or pixel on the CPU. Where the group is the whole workgroup (`lanes` =
    /// [`WORKGROUP`]), each invocation gets a workgroup of its own instead, and half the
    /// cap.
    pub(super) fn for_cap(cap: Option<u32>, lanes: u32) -> Budget {
        match cap {
            Some(cap) if lanes < WORKGROUP => Budget { workgroup: WORKGROUP, loops: cap / (2 * lanes.max(1)) },
            Some(cap) => Budget { workgroup: 1, loops: cap / 2 },
            None => Budget { workgroup: uncapped_workgroup(), loops: u32::MAX },
        }
    }

    /// The render kernel's budget: where loops are bounded (a capped adapter), at most
    /// [`RENDER_LOOPS`] an invocation; unbounded elsewhere, as the walks'.
    pub(super) fn for_render(self) -> Budget {
        match self.loops {
            u32::MAX => self,
            loops => Budget { loops: loops.min(RENDER_LOOPS), ..self },
        }
    }

    /// Items (rays, pixels) a dispatch takes at most, given a preferred batch.
    pub(super) fn per_dispatch(&self, preferred: u32) -> u32 {
        preferred.min(MAX_WORKGROUPS * self.workgroup)
    }
}

/// Loop iterations a probe kernel asks one invocation for.
const PROBE_ITERATIONS: u32 = 1 << 20;

/// The cap the adapter puts on the loop iterations of one shader invocation, if it has
/// one: one invocation asked for 2^20 iterations of a loop reports how many it ran.
/// Mesa's llvmpipe (lavapipe) stops every loop of an invocation once their iterations
/// together reach 65,535 (its guard against infinite loops), without an error: a walk
/// or a ray tree that needs more is cut short. Hardware drivers have no such cap.
pub fn loop_cap(device: &wgpu::Device, queue: &wgpu::Queue) -> GpuResult<Option<u32>> {
    let source = format!(
        "@group(0) @binding(0) var<storage, read_write> out: array<u32>;\n\
         @compute @workgroup_size(1)\n\
         fn main() {{\n    var n = 0u;\n    for (var i = 0u; i < {PROBE_ITERATIONS}u; i++) {{\n        n += 1u;\n    }}\n    out[0] = n;\n}}\n"
    );
    let ran = run_probe(device, queue, &source, "octrace loop probe", 1)?[0];
    Ok((ran < PROBE_ITERATIONS).then_some(ran))
}

/// How many invocations of a workgroup share the adapter's loop count, under a loop
/// `cap` ([`loop_cap`]): the lanes of one SIMD group, run in lockstep (lavapipe: 8, the
/// 256-bit vectors of its LLVM build), or 64 if the whole workgroup does.
/// Lane `l` of a workgroup of 64 runs a loop of `m` iterations (more than
/// half the cap) at the `l`-th step of an outer loop: in a shared count, lane 0 runs
/// whole and its neighbours are cut short, until the lane that begins the next group
/// runs whole again.
pub fn lockstep_lanes(device: &wgpu::Device, queue: &wgpu::Queue, cap: u32) -> GpuResult<u32> {
    let m = cap / 2 + cap / 8;
    let source = format!(
        "@group(0) @binding(0) var<storage, read_write> out: array<u32>;\n\
         @compute @workgroup_size({WORKGROUP})\n\
         fn main(@builtin(local_invocation_index) l: u32) {{\n    var n = 0u;\n    \
         for (var k = 0u; k < {WORKGROUP}u; k++) {{\n        if k == l {{\n            \
         for (var j = 0u; j < {m}u; j++) {{\n                n += 1u;\n            }}\n        }}\n    }}\n    \
         out[l] = n;\n}}\n"
    );
    let ran = run_probe(device, queue, &source, "octrace lockstep probe", WORKGROUP)?;
    Ok((1..WORKGROUP).find(|&l| ran[l as usize] == m).unwrap_or(WORKGROUP))
}

/// Runs a one-workgroup probe kernel writing `words` words to its one binding, and
/// reads them back.
pub(super) fn run_probe(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    source: &str,
    label: &str,
    words: u32,
) -> GpuResult<Vec<u32>> {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: 4 * u64::from(words),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: out.as_entire_binding() }],
    });
    dispatch_once(device, queue, &pipeline, &[&group]);
    read_buffer::<u32>(device, queue, &out, 4 * u64::from(words))
}

/// Submits one workgroup of `pipeline` with `groups` bound as groups 0, 1, ... (the
/// probes', and the render kernel's first run: `GpuRenderer::new`).
pub(super) fn dispatch_once(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    pipeline: &wgpu::ComputePipeline,
    groups: &[&wgpu::BindGroup],
) {
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipeline);
        for (index, group) in (0..).zip(groups) {
            pass.set_bind_group(index, *group, &[]);
        }
        pass.dispatch_workgroups(1, 1, 1);
    }
    queue.submit([encoder.finish()]);
}

/// Nanoseconds a timestamp tick, where the device has timestamp queries (the batch
/// path times each chunk's pass: `stream`).
pub(super) fn timestamp_period(device: &wgpu::Device, queue: &wgpu::Queue) -> Option<f64> {
    device.features().contains(wgpu::Features::TIMESTAMP_QUERY).then(|| f64::from(queue.get_timestamp_period()))
}

/// Waits for the device's work.
pub(super) fn wait(device: &wgpu::Device) -> GpuResult<()> {
    device
        .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
        .map(drop)
        .map_err(|e| GpuError::Device(e.to_string()))
}

/// The first `bytes` of `buffer` (made with `COPY_SRC`), read back.
pub(super) fn read_buffer<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    bytes: u64,
) -> GpuResult<Vec<T>> {
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("octrace readback"),
        size: bytes.max(4),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut out = Vec::new();
    read_buffer_append(device, queue, buffer, &readback, bytes, &mut out)?;
    Ok(out)
}

/// The first `bytes` of `buffer`, through `readback`, appended to `out` straight from
/// the mapped range (one copy on the host).
pub(super) fn read_buffer_append<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    readback: &wgpu::Buffer,
    bytes: u64,
    out: &mut Vec<T>,
) -> GpuResult<()> {
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, 0, readback, 0, bytes);
    queue.submit([encoder.finish()]);
    let slice = readback.slice(..bytes);
    let (send, receive) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = send.send(r);
    });
    wait(device)?;
    receive.recv().map_err(|e| GpuError::Device(e.to_string()))?.map_err(|e| GpuError::Device(e.to_string()))?;
    {
        let mapped = slice.get_mapped_range().map_err(|e| GpuError::Device(e.to_string()))?;
        out.extend_from_slice(bytemuck::cast_slice(&mapped));
    }
    readback.unmap();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The render kernel's loops are bounded under the walks' where the adapter caps
    /// them, and not at all where it does not.
    #[test]
    fn the_render_budget_is_bounded_only_where_the_adapter_caps_loops() {
        let capped = Budget::for_cap(Some(65_535), 8);
        assert_eq!(capped.loops, 4095);
        assert_eq!(capped.for_render(), Budget { loops: RENDER_LOOPS, ..capped });
        let alone = Budget::for_cap(Some(65_535), WORKGROUP);
        assert_eq!(alone.for_render(), Budget { loops: RENDER_LOOPS, ..alone });
        // A cap so low that the walks' own budget is under the render's: theirs.
        let low = Budget::for_cap(Some(1_000), 8);
        assert_eq!(low.for_render(), low);
        let free = Budget::for_cap(None, 1);
        assert_eq!(free.for_render(), free);
    }
}
