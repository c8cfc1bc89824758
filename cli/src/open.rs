//! Opening baked scenes: the CLI's one use of `unsafe`.

use std::path::Path;

use anyhow::Context;
use octrace_runtime::Scene;

/// Scenes of this size are read into memory on Linux rather than mapped: the copy is
/// backed by transparent huge pages, and walks over a scene past the TLB's reach run
/// faster on them (the dragon, 61 MB: incoherent rays one a call 1.17x, in a batch
/// 1.05x; BENCHMARKS.md). Validating reads every byte either way. Past 2 GiB the map
/// stays, sparing the machine a private copy of a file that large.
const READ_SIZES: std::ops::RangeInclusive<u64> = (16 << 20)..=(2 << 30);

/// Opens and fully validates a scene: memory-mapped, or read into memory where that
/// is faster to trace ([`READ_SIZES`]) or the file is zstd-compressed (it cannot be
/// mapped).
pub(crate) fn open_scene(path: &Path) -> anyhow::Result<Scene> {
    // A mesh given where a baked scene is wanted: say what to do.
    if let Some((format, _)) = octrace_bake::MeshFormat::from_path(path) {
        anyhow::bail!(
            "{} is a mesh ({}), not a baked scene: bake it first (octrace bake {} -o scene.oct), then \
             use scene.oct",
            path.display(),
            format.name(),
            path.display()
        );
    }
    let read = std::fs::metadata(path).is_ok_and(|m| reads_into_memory(m.len()));
    if read || octrace_format::is_compressed_file(path)? {
        return Scene::open(path).with_context(|| format!("cannot open scene {}", path.display()));
    }
    map_scene(path, Trust::Validate)
}

/// Whether [`open_scene`] reads an uncompressed file of `len` bytes into memory
/// rather than mapping it.
fn reads_into_memory(len: u64) -> bool {
    cfg!(target_os = "linux") && READ_SIZES.contains(&len)
}

/// How much of a file to check when opening it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Trust {
    /// Header, checksum, archive structure and every semantic rule.
    Validate,
    /// The header only: for a file this very command just baked and validated.
    HeaderOnly,
}

/// Memory-maps a scene.
///
/// Mapping is `unsafe` because the map is only sound while the file does not change.
/// The CLI maps files for the duration of one command; octrace itself never writes a
/// file in place (bakes rename a finished file over the old one, which leaves an
/// existing map intact), and a user who truncates an input while a command reads it
/// gets the same SIGBUS as with any tool that maps files (ripgrep, for one). In
/// exchange, opening costs no copy of a file that can be hundreds of megabytes.
/// `Trust::HeaderOnly` additionally relies on the file being valid: callers use it
/// only on files they baked and validated in the same process.
#[allow(unsafe_code)]
pub(crate) fn map_scene(path: &Path, trust: Trust) -> anyhow::Result<Scene> {
    let scene = match trust {
        // SAFETY: see above; the file is not modified by this process while mapped.
        Trust::Validate => unsafe { Scene::map(path) },
        // SAFETY: as above, and header-only opens are used only on files validated
        // earlier in this process.
        Trust::HeaderOnly => unsafe { Scene::map_unchecked(path) },
    };
    scene.with_context(|| format!("cannot open scene {}", path.display()))
}

/// Memory-maps an instanced file's scenes, each validated (see [`map_scene`] for why
/// mapping is sound here), and places its instances.
#[allow(unsafe_code)]
pub(crate) fn map_world(path: &Path) -> anyhow::Result<octrace_runtime::world::World> {
    // SAFETY: as `map_scene`'s: the file is not modified by this process while mapped.
    unsafe { octrace_runtime::world::World::map(path) }.with_context(|| format!("cannot open {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Files of 16 MiB to 2 GiB are read into memory on Linux, the rest mapped; a
    /// small scene opens mapped.
    #[test]
    fn large_scenes_are_read_and_small_ones_mapped() {
        let linux = cfg!(target_os = "linux");
        for (len, read) in
            [(0, false), ((16 << 20) - 1, false), (16 << 20, linux), (2 << 30, linux), ((2 << 30) + 1, false)]
        {
            assert_eq!(reads_into_memory(len), read, "{len} bytes");
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("small.oct");
        let mesh = octrace_bake::procedural::sphere([0.0; 3], 1.0, 8, 12);
        octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap().write(&path, 0).unwrap();
        let scene = open_scene(&path).unwrap();
        assert!(scene.file().is_some_and(|f| f.is_mapped()));
    }
}
