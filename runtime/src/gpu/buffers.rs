//! The scene's words on the device: split into bindings within the device's limits,
//! uploaded straight from the mapped file, and the tracing bind group's layout.

use super::{GpuError, GpuResult};

/// Word offsets of the scene's arrays in the uploaded words, in the kernel's order.
#[derive(Clone, Copy, Debug)]
pub(super) struct Offsets {
    pub(super) octree: u32,
    pub(super) refs: u32,
    pub(super) tris: u32,
    pub(super) ids: u32,
    pub(super) boxes: u32,
    pub(super) cube: u32,
    pub(super) nodes: u32,
    pub(super) fans: u32,
    pub(super) total: u64,
}

/// The arrays the kernel walks: octree, tri_refs, triangles, triangle_ids, boxes,
/// cube_map, nodes (the file's), and the fans' hierarchies (made at upload:
/// `cpu::FanIndex::gpu_words`).
pub(super) const TRACE_ARRAYS: usize = 8;

pub(super) fn offsets_of(arrays: &[&[u32]; TRACE_ARRAYS]) -> GpuResult<Offsets> {
    let mut at = [0u64; TRACE_ARRAYS + 1];
    for (i, a) in arrays.iter().enumerate() {
        at[i + 1] = at[i] + a.len() as u64;
    }
    let word = |i: usize| {
        u32::try_from(at[i])
            .map_err(|_| GpuError::TooLarge(format!("{} scene words, more than 2^32", at[TRACE_ARRAYS])))
    };
    Ok(Offsets {
        octree: word(0)?,
        refs: word(1)?,
        tris: word(2)?,
        ids: word(3)?,
        boxes: word(4)?,
        cube: word(5)?,
        nodes: word(6)?,
        fans: word(7)?,
        total: at[TRACE_ARRAYS],
    })
}

/// Uploads the arrays back to back into buffers of `chunk_words` words (the last one
/// shorter), each array copied straight from its slice (the mapped file).
pub(super) fn upload(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    arrays: &[&[u32]; TRACE_ARRAYS],
    total: u64,
    chunk_words: u64,
) -> Vec<wgpu::Buffer> {
    let chunks = total.div_ceil(chunk_words).max(1);
    let buffers: Vec<wgpu::Buffer> = (0..chunks)
        .map(|k| {
            let words = (total - k * chunk_words).min(chunk_words).max(1);
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("octrace scene"),
                size: 4 * words,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    let mut at = 0u64;
    for array in arrays {
        let mut rest: &[u32] = array;
        while !rest.is_empty() {
            let (k, within) = (at / chunk_words, at % chunk_words);
            let n = rest.len().min((chunk_words - within) as usize);
            queue.write_buffer(&buffers[k as usize], 4 * within, bytemuck::cast_slice(&rest[..n]));
            rest = &rest[n..];
            at += n as u64;
        }
    }
    queue.submit([]);
    buffers
}

pub(super) fn bind_group_layout(device: &wgpu::Device, chunks: usize) -> wgpu::BindGroupLayout {
    let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let mut entries = vec![
        wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        },
        storage(1, true),
        storage(2, false),
    ];
    entries.extend((0..chunks).map(|k| storage(3 + k as u32, true)));
    device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("octrace trace"), entries: &entries })
}

/// Bindings a kernel has besides the scene's chunks: (storage, all buffers). Tracing:
/// rays and hits, and the parameters.
pub(super) const TRACE_EXTRA_BINDINGS: (u64, u64) = (2, 3);

/// Scene bindings a kernel takes at most: each is a case of the `word` accessor's
/// switch, and a driver's compile time grows with them (NVIDIA's ran past five minutes
/// on 850). A device binds gigabytes a binding: 64 is far past any scene that fits.
pub const MAX_SCENE_BINDINGS: u64 = 64;

/// Whether `chunks` scene bindings plus `extra` (storage, all buffers) fit the device's
/// limits on buffers per shader stage; a scene that needs more is
/// [`GpuError::TooLarge`], naming the limit, before wgpu is asked (it would panic).
pub(super) fn check_bindings(
    limits: &wgpu::Limits,
    chunks: u64,
    (storage, buffers): (u64, u64),
    scene_bytes: u64,
    chunk_bytes: u64,
) -> GpuResult<()> {
    let storage_limit = u64::from(limits.max_storage_buffers_per_shader_stage);
    let buffer_limit = u64::from(limits.max_buffers_and_acceleration_structures_per_shader_stage);
    // The scene's group holds the chunks and the tracing kernel's own three bindings
    // (on NVIDIA the stage limits are in the millions: this one binds first).
    let group_limit = u64::from(limits.max_bindings_per_bind_group);
    let in_group = chunks + TRACE_EXTRA_BINDINGS.1;
    if chunks + storage > storage_limit
        || chunks + buffers > buffer_limit
        || in_group > group_limit
        || chunks > MAX_SCENE_BINDINGS
    {
        return Err(GpuError::TooLarge(format!(
            "{} MB of scene words need {chunks} bindings of {} MB, {} in all with the kernel's own; the device \
             allows {storage_limit} storage buffers and {buffer_limit} buffers a shader stage, {group_limit} \
             bindings a group, and the kernels take at most {MAX_SCENE_BINDINGS} scene bindings",
            scene_bytes / 1_000_000,
            chunk_bytes / 1_000_000,
            chunks + buffers
        )));
    }
    Ok(())
}
