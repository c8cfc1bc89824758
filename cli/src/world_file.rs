//! Scene descriptions: a JSON file naming baked scenes and placing them by transforms,
//! which `trace`, `render`, `contains`, `distance` and `inspect` take where they take a `.oct` (a world of instances,
//! `octrace_runtime::world`). Validated as strictly as a file: unknown keys, missing
//! scenes, transforms of the wrong size, not finite, not affine or not invertible are
//! refused, each naming where.
//!
//! ```json
//! {
//!   "scenes": { "bunny": "bunny.oct", "floor": "floor.oct" },
//!   "instances": [
//!     { "scene": "floor" },
//!     { "scene": "bunny", "transform": [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0]] },
//!     { "scene": "bunny", "transform": [1, 0, 0, -0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1] }
//!   ]
//! }
//! ```
//!
//! Paths are relative to the description's folder; a transform is 3 rows of 4 or 4
//! rows of 4 (nested, or flat, row by row; the last row `0 0 0 1`), local to world;
//! none is the identity.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use octrace_runtime::world::{Transform, World};

/// The largest description read (a million instances take about 100 MB of JSON).
const MAX_BYTES: u64 = 256 << 20;
/// The most instances a description may place (the world takes about 300 bytes an
/// instance: 300 MB at most).
const MAX_INSTANCES: usize = 1 << 20;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Description {
    scenes: BTreeMap<String, String>,
    instances: Vec<Instance>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Instance {
    scene: String,
    #[serde(default)]
    transform: Option<serde_json::Value>,
}

/// Whether `path` names a world rather than one baked scene: a scene description
/// (`.json`), or an instanced file (a glTF's meshes placed many times, baked once:
/// `octrace_format::instanced`).
pub(crate) fn is_world(path: &Path) -> bool {
    is_description(path) || octrace_format::instanced::is_instanced_file(path).unwrap_or(false)
}

/// Whether `path` names a scene description (`.json`).
pub(crate) fn is_description(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// The world a description or an instanced file places, committed, and its scenes by
/// name (an instanced file's `scene 0`, `scene 1`, ...).
pub(crate) fn open_world(path: &Path) -> anyhow::Result<(World, BTreeMap<String, Arc<octrace_runtime::Scene>>)> {
    if !is_description(path) {
        let world = crate::open::map_world(path)?;
        let names = world.scenes().iter().enumerate().map(|(i, s)| (format!("scene {i}"), Arc::clone(s))).collect();
        return Ok((world, names));
    }
    let len = std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?.len();
    anyhow::ensure!(
        len <= MAX_BYTES,
        "{}: {len} bytes, past the {MAX_BYTES} a scene description may take",
        path.display()
    );
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let d: Description = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a scene description (keys \"scenes\" and \"instances\")", path.display()))?;
    anyhow::ensure!(
        d.instances.len() <= MAX_INSTANCES,
        "{}: {} instances, past the {MAX_INSTANCES} a description may place",
        path.display(),
        d.instances.len()
    );
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut scenes = BTreeMap::new();
    for (name, file) in &d.scenes {
        let file = folder.join(file);
        anyhow::ensure!(
            !is_world(&file),
            "{}: scene \"{name}\" is a world itself ({}: a description or an instanced file): instances of instances are not supported",
            path.display(),
            file.display()
        );
        let scene = crate::open::open_scene(&file).with_context(|| format!("{}: scene \"{name}\"", path.display()))?;
        scenes.insert(name.clone(), Arc::new(scene));
    }
    let mut world = World::new();
    for (i, instance) in d.instances.iter().enumerate() {
        let scene = scenes.get(&instance.scene).with_context(|| {
            format!(
                "{}: instance {i} names scene \"{}\", which \"scenes\" does not list",
                path.display(),
                instance.scene
            )
        })?;
        let transform = match &instance.transform {
            None => Transform::IDENTITY,
            Some(v) => transform(v).with_context(|| format!("{}: instance {i}'s transform", path.display()))?,
        };
        world.add(scene, transform).with_context(|| format!("{}: instance {i}", path.display()))?;
    }
    world.commit();
    Ok((world, scenes))
}

/// A transform from 3 or 4 rows of 4 numbers, nested or flat.
fn transform(v: &serde_json::Value) -> anyhow::Result<Transform> {
    let numbers: Vec<f64> = match v {
        serde_json::Value::Array(rows) if rows.iter().all(|r| r.is_array()) => {
            anyhow::ensure!(
                rows.iter().all(|r| r.as_array().is_some_and(|r| r.len() == 4)),
                "rows of 4 numbers expected"
            );
            rows.iter().flat_map(|r| r.as_array().into_iter().flatten()).map(number).collect::<anyhow::Result<_>>()?
        }
        serde_json::Value::Array(flat) => flat.iter().map(number).collect::<anyhow::Result<_>>()?,
        _ => anyhow::bail!("an array of 12 or 16 numbers (3 or 4 rows of 4) expected"),
    };
    let row = |i: usize| [numbers[4 * i], numbers[4 * i + 1], numbers[4 * i + 2], numbers[4 * i + 3]];
    let t = match numbers.len() {
        12 => Transform::from_rows([row(0), row(1), row(2)]),
        16 => Transform::from_matrix([row(0), row(1), row(2), row(3)])?,
        n => anyhow::bail!("{n} numbers, expected 12 or 16 (3 or 4 rows of 4)"),
    };
    t.inverse()?;
    Ok(t)
}

fn number(v: &serde_json::Value) -> anyhow::Result<f64> {
    v.as_f64().filter(|x| x.is_finite()).with_context(|| format!("{v} is not a finite number"))
}
