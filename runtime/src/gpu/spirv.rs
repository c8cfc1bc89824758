//! Kernels as the CPU computes them: WGSL compiled to SPIR-V here (naga), every float
//! operation marked `NoContraction`, and f32 subnormals kept where the driver can.
//!
//! WGSL lets a compiler fuse a multiply into an add, and hardware compilers do: on an
//! NVIDIA H200 a hit's barycentrics came out up to 10 % apart from the CPU's (a fused
//! shear turned one rounding into another, then a cancelling edge function magnified
//! it), and rays leaked through shared edges. SPIR-V's `NoContraction` forbids that
//! fusing operation by operation; naga does not emit it, so where the device takes
//! SPIR-V as it is (wgpu's `PASSTHROUGH_SHADERS`, every Vulkan device) the kernels are
//! compiled here and marked. Drivers may also flush f32 subnormals to zero (NVIDIA's do
//! by default), which the CPU never does: where a probe shows that the `DenormPreserve`
//! execution mode keeps them, every kernel asks for it.

use super::{GpuError, GpuResult};

/// How this device's kernels are compiled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Compiler {
    /// Compiled here and passed through (else WGSL to wgpu, fusing allowed).
    pub passthrough: bool,
    /// f32 subnormals kept by `DenormPreserve` (only with `passthrough`).
    pub denormals: bool,
}

impl Compiler {
    /// The compiler for `device`: passthrough where the device has it, subnormals kept
    /// where the probe shows the mode works. The environment can turn either off, for a
    /// driver that mishandles them: `OCTRACE_GPU_PASSTHROUGH=0` (wgpu compiles the WGSL,
    /// fusing allowed), `OCTRACE_GPU_SUBNORMALS=0` (the driver's default).
    pub(super) fn for_device(device: &wgpu::Device, queue: &wgpu::Queue) -> GpuResult<Compiler> {
        let off = |name: &str| std::env::var(name).is_ok_and(|v| v == "0");
        if !device.features().contains(wgpu::Features::PASSTHROUGH_SHADERS) || off("OCTRACE_GPU_PASSTHROUGH") {
            return Ok(Compiler { passthrough: false, denormals: false });
        }
        let denormals = !off("OCTRACE_GPU_SUBNORMALS") && keeps_subnormals(device, queue)?;
        Ok(Compiler { passthrough: true, denormals })
    }

    /// A compute pipeline of `source`'s entry point `entry` with override `constants`.
    ///
    /// # Errors
    /// [`GpuError::Device`] where naga cannot compile the source.
    pub(super) fn pipeline(
        &self,
        device: &wgpu::Device,
        layout: &wgpu::PipelineLayout,
        source: &str,
        entry: &str,
        constants: &[(&str, f64)],
        label: &str,
    ) -> GpuResult<wgpu::ComputePipeline> {
        let module = if self.passthrough {
            let words = compile(source, entry, constants, self.denormals)?;
            // SAFETY: the words are naga's SPIR-V of a module naga validated, with
            // bounds checks on every index and buffer access (Restrict), plus
            // decorations that only constrain the driver (`NoContraction`) and an
            // execution mode the probe showed this driver honours (or, in the probe,
            // inside an error scope that catches a driver refusing it).
            unsafe {
                device.create_shader_module_passthrough(wgpu::ShaderModuleDescriptorPassthrough {
                    label: Some(label),
                    entry_points: std::borrow::Cow::Owned(vec![wgpu::PassthroughShaderEntryPoint {
                        name: entry.to_string().into(),
                        workgroup_size: (1, 1, 1),
                    }]),
                    spirv: Some(std::borrow::Cow::Owned(words)),
                    ..Default::default()
                })
            }
        } else {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        };
        let constants = if self.passthrough { &[][..] } else { constants };
        Ok(device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            cache: None,
        }))
    }
}

/// `source`'s entry point `entry` as SPIR-V, overrides set, every float operation
/// `NoContraction` and, with `denormals`, f32 subnormals preserved.
pub(super) fn compile(source: &str, entry: &str, constants: &[(&str, f64)], denormals: bool) -> GpuResult<Vec<u32>> {
    use naga::back::spv;
    let fail = |what: &str, e: String| GpuError::Device(format!("compiling the kernel to SPIR-V: {what}: {e}"));
    let module = naga::front::wgsl::parse_str(source).map_err(|e| fail("parse", e.emit_to_string(source)))?;
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .map_err(|e| fail("validation", e.emit_to_string(source)))?;
    let constants: naga::back::PipelineConstants = constants.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    let (module, info) = naga::back::pipeline_constants::process_overrides(
        &module,
        &info,
        Some((naga::ShaderStage::Compute, entry)),
        &constants,
    )
    .map_err(|e| fail("override constants", e.to_string()))?;
    let restrict = naga::proc::BoundsCheckPolicy::Restrict;
    let options = spv::Options {
        lang_version: (1, 3),
        // No debug names (naga adds them in debug builds): the same words in every build.
        flags: spv::WriterFlags::empty(),
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: restrict,
            buffer: restrict,
            image_load: restrict,
            binding_array: naga::proc::BoundsCheckPolicy::Unchecked,
        },
        ..spv::Options::default()
    };
    let pipeline = spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: entry.to_string() };
    let words = spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| fail("SPIR-V", e.to_string()))?;
    Ok(exact(&words, denormals))
}

// SPIR-V opcodes and operands this module reads or writes.
const OP_EXTENSION: u32 = 10;
const OP_ENTRY_POINT: u32 = 15;
const OP_EXECUTION_MODE: u32 = 16;
const OP_CAPABILITY: u32 = 17;
const OP_TYPE_VOID: u32 = 19;
const OP_TYPE_FORWARD_POINTER: u32 = 39;
const OP_DECORATE: u32 = 71;
const DECORATION_NO_CONTRACTION: u32 = 42;
const CAPABILITY_DENORM_PRESERVE: u32 = 4464;
const EXECUTION_MODE_DENORM_PRESERVE: u32 = 4459;
/// Float arithmetic a compiler could fuse: OpFNegate, OpFAdd, OpFSub, OpFMul, OpFDiv,
/// OpFRem, OpFMod, OpVectorTimesScalar, OpMatrixTimesScalar, OpVectorTimesMatrix,
/// OpMatrixTimesVector, OpMatrixTimesMatrix, OpDot (result id in the second operand).
const FLOAT_ARITHMETIC: [u32; 13] = [127, 129, 131, 133, 136, 140, 141, 142, 143, 144, 145, 146, 148];

/// `words` (a SPIR-V module) with `NoContraction` on every float operation and, with
/// `denormals`, the `DenormPreserve` mode for 32-bit floats on its entry points.
fn exact(words: &[u32], denormals: bool) -> Vec<u32> {
    let mut instructions = Vec::new();
    let mut at = 5;
    while at < words.len() {
        let count = ((words[at] >> 16) as usize).max(1);
        instructions.push(&words[at..(at + count).min(words.len())]);
        at += count;
    }
    let opcode = |i: &[u32]| i[0] & 0xFFFF;
    let fused: Vec<u32> =
        instructions.iter().filter(|i| FLOAT_ARITHMETIC.contains(&opcode(i)) && i.len() > 2).map(|i| i[2]).collect();
    let entries: Vec<u32> =
        instructions.iter().filter(|i| opcode(i) == OP_ENTRY_POINT && i.len() > 2).map(|i| i[2]).collect();
    let first_type = instructions
        .iter()
        .position(|i| (OP_TYPE_VOID..=OP_TYPE_FORWARD_POINTER).contains(&opcode(i)))
        .unwrap_or(instructions.len());
    let first_past_capabilities =
        instructions.iter().position(|i| opcode(i) != OP_CAPABILITY).unwrap_or(instructions.len());
    let last_entry = instructions.iter().rposition(|i| opcode(i) == OP_ENTRY_POINT);

    let mut out = words[..5].to_vec();
    for (k, i) in instructions.iter().enumerate() {
        if denormals && k == first_past_capabilities {
            out.extend([2 << 16 | OP_CAPABILITY, CAPABILITY_DENORM_PRESERVE]);
            let name = string_words("SPV_KHR_float_controls");
            out.push(((1 + name.len()) as u32) << 16 | OP_EXTENSION);
            out.extend(name);
        }
        if k == first_type {
            for &id in &fused {
                out.extend([3 << 16 | OP_DECORATE, id, DECORATION_NO_CONTRACTION]);
            }
        }
        out.extend_from_slice(i);
        if denormals && Some(k) == last_entry {
            for &entry in &entries {
                out.extend([4 << 16 | OP_EXECUTION_MODE, entry, EXECUTION_MODE_DENORM_PRESERVE, 32]);
            }
        }
    }
    out
}

/// A SPIR-V literal string: UTF-8, NUL-terminated, padded to whole words.
fn string_words(s: &str) -> Vec<u32> {
    let mut bytes = s.as_bytes().to_vec();
    bytes.push(0);
    bytes.resize(bytes.len().div_ceil(4) * 4, 0);
    bytes.chunks(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// Whether a kernel compiled with `DenormPreserve` keeps an f32 subnormal: 2^-70
/// squared (read from a buffer, so that no compiler folds it) is 2^-140, or zero where
/// the driver flushes. A driver that refuses the mode fails the probe's pipeline, which
/// counts as no.
fn keeps_subnormals(device: &wgpu::Device, queue: &wgpu::Queue) -> GpuResult<bool> {
    const PROBE: &str = "@group(0) @binding(0) var<storage, read_write> io: array<f32>;\n\
        @compute @workgroup_size(1)\nfn main() {\n    io[1] = io[0] * io[0];\n}\n";
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("octrace subnormal probe"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: false },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("octrace subnormal probe"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let probe = Compiler { passthrough: true, denormals: true };
    let pipeline = probe.pipeline(device, &pipeline_layout, PROBE, "main", &[], "octrace subnormal probe")?;
    if pollster::block_on(scope.pop()).is_some() {
        return Ok(false);
    }
    use wgpu::BufferUsages as U;
    let io = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("octrace subnormal probe"),
        size: 8,
        usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&io, 0, bytemuck::cast_slice(&[2f32.powi(-70), 0.0]));
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("octrace subnormal probe"),
        layout: &layout,
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: io.as_entire_binding() }],
    });
    super::dispatch_once(device, queue, &pipeline, &[&group]);
    let out = super::device::read_buffer::<f32>(device, queue, &io, 8)?;
    Ok(out[1] == 2f32.powi(-140))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every float operation of a compiled kernel carries `NoContraction`, and the
    /// subnormal mode comes with its capability and execution mode (the GPU tests run
    /// the compiled kernels).
    #[test]
    fn compiled_kernels_forbid_fusing_and_keep_subnormals() {
        let source = "@group(0) @binding(0) var<storage, read_write> io: array<f32>;\n\
            @compute @workgroup_size(1)\nfn main() {\n    io[2] = io[0] * io[1] + io[2];\n}\n";
        for denormals in [false, true] {
            let words = compile(source, "main", &[], denormals).unwrap();
            let mut at = 5;
            let (mut arithmetic, mut no_contraction, mut modes) = (Vec::new(), Vec::new(), 0);
            while at < words.len() {
                let i = &words[at..at + (words[at] >> 16) as usize];
                match i[0] & 0xFFFF {
                    op if FLOAT_ARITHMETIC.contains(&op) => arithmetic.push(i[2]),
                    OP_DECORATE if i[2] == DECORATION_NO_CONTRACTION => no_contraction.push(i[1]),
                    OP_EXECUTION_MODE if i[2] == EXECUTION_MODE_DENORM_PRESERVE => modes += 1,
                    _ => {}
                }
                at += i.len();
            }
            assert!(arithmetic.len() >= 2, "a multiply and an add: {arithmetic:?}");
            assert_eq!(arithmetic, no_contraction);
            assert_eq!(modes, usize::from(denormals));
            let capability = words.windows(2).any(|w| w == [2 << 16 | OP_CAPABILITY, CAPABILITY_DENORM_PRESERVE]);
            assert_eq!(capability, denormals);
        }
    }
}
