//! What the effects renderer traces and reads: one baked scene, or a world of
//! instances (each hit's geometry carried to the world, its materials and textures
//! its own scene's).

use glam::Vec3;
use octrace_format::{Light, Material, SceneView, StoredIndex};

use super::lighting::Emitters;
use crate::error::{Error, Result};
use crate::world::{Transform, World, WorldHit};
use crate::{Hit, Ray, Tracer};

/// The renderer's view of what it draws. A hit names an instance (`0` in a scene)
/// and a stored triangle of that instance's scene; geometry comes back in the
/// stage's space, materials and textures from the instance's scene.
pub(crate) trait Stage: Sync {
    /// A hit as the stage's walk answers it.
    type Hit: Copy + Send + Sync;

    /// The hit in its scene's terms (`t` along the stage's ray).
    fn hit(h: &Self::Hit) -> Hit;
    /// The hit's instance (`0` in a scene).
    fn instance(h: &Self::Hit) -> u32;
    /// The nearest hits of `rays`.
    fn intersect_batch(&self, rays: &[Ray]) -> Vec<Option<Self::Hit>>;
    /// The nearest hit of `ray`.
    fn intersect(&self, ray: &Ray) -> Option<Self::Hit>;
    /// Whether something blocks each ray.
    fn occluded_batch(&self, rays: &[Ray]) -> Vec<bool>;
    /// The arrays of instance `instance`'s scene.
    fn view(&self, instance: u32) -> &SceneView<'_>;
    /// The material `instance` draws stored triangle `prim` with (its scene's, through
    /// the instance's material map in a world).
    fn material(&self, instance: u32, prim: StoredIndex) -> Option<&Material>;
    /// Stored triangle `prim` of `instance`, its corners in the stage's space.
    fn triangle(&self, instance: u32, prim: StoredIndex) -> [[f32; 3]; 3];
    /// Whether `instance`'s placement mirrors (its triangles' corners then turn the
    /// other way round their front).
    fn mirrored(&self, instance: u32) -> bool;
    /// The corners' normals of `prim`, in the stage's space.
    fn corner_normals(&self, instance: u32, prim: StoredIndex) -> Option<[[f32; 3]; 3]>;
    /// The corners' tangents of `prim` (`x y z` in the stage's space, `w` the sign).
    fn corner_tangents(&self, instance: u32, prim: StoredIndex) -> Option<[[f32; 4]; 3]>;
    /// The punctual lights.
    fn lights(&self) -> &[Light];
    /// The emissive triangles.
    fn emitters(&self) -> Emitters;
    /// Whether some material is single-sided.
    fn culls(&self) -> bool;
}

/// One scene, traced by the renderers' tracer.
pub(crate) struct SceneStage<'a> {
    pub view: SceneView<'a>,
    pub tracer: Tracer<'a>,
}

impl Stage for SceneStage<'_> {
    type Hit = Hit;

    #[inline]
    fn hit(h: &Hit) -> Hit {
        *h
    }

    #[inline]
    fn instance(_: &Hit) -> u32 {
        0
    }

    fn intersect_batch(&self, rays: &[Ray]) -> Vec<Option<Hit>> {
        let mut out = vec![None; rays.len()];
        self.tracer.intersect_batch(rays, &mut out);
        out
    }

    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.tracer.intersect(ray)
    }

    fn occluded_batch(&self, rays: &[Ray]) -> Vec<bool> {
        let mut blocked = vec![false; rays.len()];
        self.tracer.occluded_batch(rays, &mut blocked);
        blocked
    }

    #[inline]
    fn view(&self, _: u32) -> &SceneView<'_> {
        &self.view
    }

    #[inline]
    fn material(&self, _: u32, prim: StoredIndex) -> Option<&Material> {
        self.view.material(prim)
    }

    #[inline]
    fn triangle(&self, _: u32, prim: StoredIndex) -> [[f32; 3]; 3] {
        self.view.triangle(prim)
    }

    #[inline]
    fn mirrored(&self, _: u32) -> bool {
        false
    }

    #[inline]
    fn corner_normals(&self, _: u32, prim: StoredIndex) -> Option<[[f32; 3]; 3]> {
        self.view.corner_normals(prim)
    }

    #[inline]
    fn corner_tangents(&self, _: u32, prim: StoredIndex) -> Option<[[f32; 4]; 3]> {
        self.view.corner_tangents(prim)
    }

    fn lights(&self) -> &[Light] {
        &self.view.shading.lights
    }

    fn emitters(&self) -> Emitters {
        Emitters::of(&self.view)
    }

    fn culls(&self) -> bool {
        super::effects::culls(self.view.shading)
    }
}

/// A world of instances: rays traced through it, each hit's corners carried to the
/// world in `f64` (rounded once), normals by the inverse transpose, tangents by the
/// linear part; each instance's punctual lights placed with it (positions,
/// directions, and ranges scaled; intensities as they are).
pub(crate) struct WorldStage<'a> {
    pub world: &'a World,
    /// The world's scenes' arrays, by scene index.
    pub views: Vec<SceneView<'a>>,
    /// The emissive triangles of each look (a scene drawn through a material map).
    pub own_emitters: Vec<Emitters>,
    /// Each instance's look (its index in `own_emitters`), by instance id.
    pub look: Vec<u32>,
    /// The instances' lights, placed.
    lights: Vec<Light>,
}

/// The most memory a world's placed lights and emissive triangles may take (each
/// instance's copies of its scene's): 1 GiB.
pub(crate) const WORLD_LIGHTS_BUDGET: u64 = 1 << 30;

/// Bytes an emissive triangle of a world takes in [`Emitters`].
const EMITTER_BYTES: u64 = (std::mem::size_of::<(u32, Vec3)>() + 2 * std::mem::size_of::<u32>()) as u64;

impl<'a> WorldStage<'a> {
    /// The stage of `world`.
    ///
    /// # Errors
    /// [`Error::Budget`] where the instances' placed lights and emissive triangles
    /// would take more than [`WORLD_LIGHTS_BUDGET`] (a scene with many lights placed
    /// many times); [`Error::Alloc`] where their memory cannot be had.
    pub fn new(world: &'a World) -> Result<WorldStage<'a>> {
        let views: Vec<SceneView<'a>> = world.scenes().iter().map(|s| s.view()).collect();
        // Each distinct look (a scene drawn through one material map) finds its
        // emissive triangles once.
        let mut looks: std::collections::HashMap<(u32, &[u32]), u32> = Default::default();
        let mut own_emitters = Vec::new();
        let mut look = Vec::new();
        for (id, scene) in world.placed_scenes() {
            let map = world.materials(id).unwrap_or(&[]);
            let index = *looks.entry((scene, map)).or_insert_with(|| {
                own_emitters.push(Emitters::of_mapped(&views[scene as usize], map));
                own_emitters.len() as u32 - 1
            });
            if look.len() <= id as usize {
                look.resize(id as usize + 1, 0);
            }
            look[id as usize] = index;
        }
        // What the placed copies take, counted before any is made.
        let (mut lights_count, mut bytes) = (0u64, 0u64);
        for (id, scene) in world.placed_scenes() {
            let own = &views[scene as usize].shading.lights;
            lights_count += own.len() as u64;
            bytes += own.iter().map(|l| (std::mem::size_of::<Light>() + l.name.len()) as u64).sum::<u64>();
            bytes += own_emitters[look[id as usize] as usize].len() as u64 * EMITTER_BYTES;
        }
        if bytes > WORLD_LIGHTS_BUDGET {
            return Err(Error::Budget {
                what: "world's placed lights and emissive triangles",
                needed: bytes,
                limit: WORLD_LIGHTS_BUDGET,
                advice: "each instance of a scene with lights or emissive triangles places its own copies: \
                         place fewer instances of those scenes, or render without them",
            });
        }
        let mut lights = octrace_format::memory::try_with_capacity(lights_count as usize, "placed lights")?;
        for (id, scene) in world.placed_scenes() {
            let Some((_, to_world, _)) = world.placement(id) else { continue };
            // A range scales with the placement (by its longest axis where it stretches).
            let r = &to_world.rows;
            let scale = (0..3).map(|j| (0..3).map(|i| r[i][j] * r[i][j]).sum::<f64>().sqrt()).fold(0.0, f64::max);
            for l in &views[scene as usize].shading.lights {
                let position = to_world.point(l.position.map(f64::from)).map(|c| c as f32);
                let direction = carry(&to_world, l.direction, false).normalize_or_zero().to_array();
                let range = (f64::from(l.range) * scale) as f32;
                lights.push(Light { position, direction, range, ..l.clone() });
            }
        }
        Ok(WorldStage { world, views, own_emitters, look, lights })
    }
}

/// `v` through `t`'s linear part (`inverse_transpose`: through the transpose of
/// `t`'s own, which for `to_local` is the inverse transpose of `to_world`'s).
fn carry(t: &Transform, v: [f32; 3], inverse_transpose: bool) -> Vec3 {
    let v = v.map(f64::from);
    let r = &t.rows;
    let w: [f64; 3] = if inverse_transpose {
        std::array::from_fn(|i| r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2])
    } else {
        std::array::from_fn(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    };
    Vec3::from_array(w.map(|c| c as f32))
}

impl WorldStage<'_> {
    /// A live instance's scene arrays and placement both ways.
    fn placement(&self, instance: u32) -> (&SceneView<'_>, Transform, Transform) {
        let (scene, to_world, to_local) = self.world.placement(instance).expect("a hit's instance is live");
        (&self.views[scene as usize], to_world, to_local)
    }
}

impl Stage for WorldStage<'_> {
    type Hit = WorldHit;

    #[inline]
    fn hit(h: &WorldHit) -> Hit {
        h.hit
    }

    #[inline]
    fn instance(h: &WorldHit) -> u32 {
        h.instance
    }

    fn intersect_batch(&self, rays: &[Ray]) -> Vec<Option<WorldHit>> {
        self.world.intersect_batch(rays)
    }

    fn intersect(&self, ray: &Ray) -> Option<WorldHit> {
        self.world.intersect(ray)
    }

    fn occluded_batch(&self, rays: &[Ray]) -> Vec<bool> {
        self.world.occluded_batch(rays)
    }

    fn view(&self, instance: u32) -> &SceneView<'_> {
        self.placement(instance).0
    }

    fn material(&self, instance: u32, prim: StoredIndex) -> Option<&Material> {
        let view = self.placement(instance).0;
        view.material_mapped(prim, self.world.materials(instance).unwrap_or(&[]))
    }

    fn triangle(&self, instance: u32, prim: StoredIndex) -> [[f32; 3]; 3] {
        let (view, to_world, _) = self.placement(instance);
        view.triangle(prim).map(|v| to_world.point(v.map(f64::from)).map(|c| c as f32))
    }

    fn mirrored(&self, instance: u32) -> bool {
        self.placement(instance).1.determinant() < 0.0
    }

    fn corner_normals(&self, instance: u32, prim: StoredIndex) -> Option<[[f32; 3]; 3]> {
        let (view, _, to_local) = self.placement(instance);
        let corners = view.corner_normals(prim)?;
        Some(corners.map(|n| carry(&to_local, n, true).normalize_or_zero().to_array()))
    }

    fn corner_tangents(&self, instance: u32, prim: StoredIndex) -> Option<[[f32; 4]; 3]> {
        let (view, to_world, _) = self.placement(instance);
        let corners = view.corner_tangents(prim)?;
        // A mirror turns the frame's handedness: the bitangent's sign with it.
        let flip = if to_world.determinant() < 0.0 { -1.0 } else { 1.0 };
        Some(corners.map(|t| {
            let v = carry(&to_world, [t[0], t[1], t[2]], false);
            [v.x, v.y, v.z, t[3] * flip]
        }))
    }

    fn lights(&self) -> &[Light] {
        &self.lights
    }

    fn emitters(&self) -> Emitters {
        Emitters::of_world(self)
    }

    fn culls(&self) -> bool {
        self.views.iter().any(|v| super::effects::culls(v.shading))
    }
}
