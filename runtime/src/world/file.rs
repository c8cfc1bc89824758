//! Instanced files ([`octrace_format::instanced`]) opened as worlds: each embedded
//! scene opened once, each instance placed with its material map.

use std::path::Path;
use std::sync::Arc;

use octrace_format::instanced::InstancedFile;
use octrace_format::SceneFile;

use super::{Transform, World};
use crate::error::Result;
use crate::Scene;

impl World {
    /// Opens an instanced file (a glTF whose meshes are placed many times, baked with
    /// each mesh once): every embedded scene read into memory and validated as
    /// [`Scene::open`] validates a file, every instance placed, committed.
    ///
    /// # Errors
    /// The format's errors (an ordinary `.oct` is refused with
    /// `octrace_format::Error::NotInstanced`: open it with [`Scene::open`]); an instance
    /// whose transform cannot be inverted ([`crate::Error::Transform`]) or whose
    /// material map names a material its scene lacks ([`crate::Error::MaterialMap`]).
    ///
    /// # Example
    /// ```
    /// use octrace_format::instanced::{InstanceRecord, InstancedFile};
    /// use octrace_runtime::world::World;
    /// # let scene = octrace_format::testing::single_leaf_scene();
    /// let dir = tempfile::tempdir()?;
    /// let path = dir.path().join("two.oct");
    /// let shift = |x: f64| [[1.0, 0.0, 0.0, x], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
    /// let at = |x| InstanceRecord { scene: 0, rows: shift(x), map: None };
    /// let table = InstancedFile { instances: vec![at(0.0), at(2.0)], ..Default::default() };
    /// table.write(&path, &[scene.to_file_bytes(0)?])?;
    /// let world = World::open(&path)?;
    /// assert_eq!(world.len(), 2);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn open(path: impl AsRef<Path>) -> Result<World> {
        let path = path.as_ref();
        let table = InstancedFile::read(path)?;
        World::placing(&table, |i| table.read_scene(path, i))
    }

    /// [`World::open`] with each embedded scene memory-mapped and validated.
    ///
    /// # Safety
    /// As [`Scene::map`]: the file must not be modified or truncated while the world
    /// or any of its scenes is alive.
    ///
    /// # Errors
    /// As [`World::open`].
    pub unsafe fn map(path: impl AsRef<Path>) -> Result<World> {
        let path = path.as_ref();
        let table = InstancedFile::read(path)?;
        // SAFETY: forwarded to our caller.
        World::placing(&table, |i| unsafe { table.map_scene(path, i) })
    }

    /// [`World::map`] with the trusted path's checks alone on each scene (as
    /// [`Scene::map_unchecked`]); the instance table is checked whole.
    ///
    /// # Safety
    /// As [`World::map`].
    ///
    /// # Errors
    /// As [`World::open`], less the scenes' checksums and semantic rules.
    pub unsafe fn map_unchecked(path: impl AsRef<Path>) -> Result<World> {
        let path = path.as_ref();
        let table = InstancedFile::read(path)?;
        // SAFETY: forwarded to our caller.
        World::placing(&table, |i| unsafe { table.map_scene_unchecked(path, i) })
    }

    /// The world `table` places, its scenes opened by `open`: each map made once and
    /// shared by the instances drawing with it, and checked once against each scene
    /// it is used with.
    fn placing(table: &InstancedFile, open: impl Fn(usize) -> octrace_format::Result<SceneFile>) -> Result<World> {
        let scenes: Vec<Arc<Scene>> =
            (0..table.scenes.len()).map(|i| Ok(Arc::new(Scene::from_scene_file(open(i)?)))).collect::<Result<_>>()?;
        let maps: Vec<Arc<[u32]>> = table.maps.iter().map(|m| Arc::from(m.as_slice())).collect();
        let mut checked = std::collections::HashSet::new();
        let mut world = World::new();
        for instance in &table.instances {
            let scene = &scenes[instance.scene as usize];
            let map = instance.map.map(|m| &maps[m as usize]).filter(|m| !m.is_empty());
            if let Some(map) = map {
                if checked.insert((instance.scene, instance.map)) {
                    super::check_map(scene, map)?;
                }
            }
            world.insert(scene, Transform::from_rows(instance.rows), map.cloned())?;
        }
        world.commit();
        Ok(world)
    }
}
