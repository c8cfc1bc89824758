//! The constrained octree of Portalez & Duguet, *Lancer de rayons dans un octree*
//! (2016): build, 2:1 balance, face links, cube map, point location.

mod balance;
mod build;
mod flatten;
pub mod overlap;
mod params;

#[cfg(test)]
mod tests;

pub use params::{
    default_max_tree_bytes, BuildParams, ResolvedParams, AUTO_DEPTH_LIMIT, DEFAULT_LEAF_SIZE, DEFAULT_MARGIN,
    DEFAULT_MAX_TREE_BYTES, DEFAULT_TREE_BYTES_PER_TRIANGLE, MAX_MARGIN,
};

use octrace_format::{BakeParams, BakeStats, BakedScene, Bounds};

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use build::{Builder, Growth, Limits, Node};
use flatten::FlatTree;
use octrace_format::topology::EdgeCensus;

/// The stages of a bake, reported in order to a progress callback.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BakeStage {
    /// Sorting out degenerate triangles and bounds.
    Prepare,
    /// Recursive subdivision.
    Build,
    /// The 2:1 constraint.
    Balance,
    /// Face links, cube map, arrays.
    Link,
    /// The closest-point search's tree ([`BuildParams::distance`]).
    Distance,
}

impl BakeStage {
    /// A short human name.
    pub fn name(self) -> &'static str {
        match self {
            BakeStage::Prepare => "preparing",
            BakeStage::Build => "subdividing",
            BakeStage::Balance => "balancing 2:1",
            BakeStage::Link => "linking neighbours",
            BakeStage::Distance => "grouping triangles for closest points",
        }
    }
}

/// Whether a triangle has zero area: its edge cross product is exactly zero. Products
/// of `f32` values are exact in `f64`, so this is exact collinearity up to the single
/// rounding of each difference.
pub fn is_degenerate(t: &[[f32; 3]; 3]) -> bool {
    octrace_format::topology::is_degenerate(t)
}

/// The smallest root edge the tracer serves: `2^-60` (8.7e-19). The watertight test
/// multiplies coordinates relative to a ray's origin in pairs (its edge functions), and
/// the walk multiplies cell offsets by direction components; below this edge those
/// products leave `f32`'s normal range (`2^-126`), lose their precision and then their
/// signs: every ray from inside a sphere 1e-22 across leaked. Cells at the deepest level
/// the format allows stay normal too. A smaller scene is refused at bake
/// ([`Error::Scale`]): scale it up.
pub const MIN_ROOT_EDGE: f64 = 8.673617379884035e-19; // 2^-60

/// The largest root edge and coordinate magnitude the tracer serves: `2^60` (1.2e18).
/// Above, the same products overflow `f32` (`2^128`) for rays whose direction is as
/// long as the scene (rays aimed at points of it): 40 % of the rays aimed at a sphere
/// 1e20 across leaked. A larger or farther scene is refused at bake ([`Error::Scale`]).
pub const MAX_COORDINATE: f64 = 1.152921504606847e18; // 2^60

/// The root cube: a power-of-two edge at least the mesh's largest extent, centred on
/// the mesh, its low corner rounded down to `f32`; doubled until it holds the mesh.
///
/// # Errors
/// [`Error::Scale`] when the scene is smaller or larger, or farther from the origin,
/// than the tracer serves ([`MIN_ROOT_EDGE`], [`MAX_COORDINATE`]).
pub fn root_cube(lo: [f32; 3], hi: [f32; 3]) -> Result<([f32; 3], f32)> {
    let extent = (0..3).map(|a| hi[a] as f64 - lo[a] as f64).fold(0.0, f64::max);
    let largest = (0..3).map(|a| (lo[a] as f64).abs().max((hi[a] as f64).abs())).fold(0.0, f64::max);
    // A single point (every vertex the same, all degenerate) gets a unit root.
    let mut size = if extent > 0.0 { extent.log2().ceil().exp2() } else { 1.0 };
    if !(MIN_ROOT_EDGE..=MAX_COORDINATE).contains(&size) || largest > MAX_COORDINATE {
        return Err(Error::Scale { extent, largest });
    }
    loop {
        if size > 2.0 * MAX_COORDINATE {
            return Err(Error::Scale { extent, largest });
        }
        let root_lo = [0, 1, 2].map(|a| {
            let exact = 0.5 * (lo[a] as f64 + hi[a] as f64) - 0.5 * size;
            let r = exact as f32;
            if r as f64 > exact {
                r.next_down()
            } else {
                r
            }
        });
        if (0..3).all(|a| root_lo[a] <= lo[a] && root_lo[a] as f64 + size >= hi[a] as f64) {
            return Ok((root_lo, size as f32));
        }
        size *= 2.0;
    }
}

/// Spacings of `f32` a cell must span at least: `MIN_CELL_ULPS` times the spacing of the
/// scene's largest coordinate. Narrower cells would have planes that round together
/// (zero-width boxes), and the walk's exit tests would compare nothing.
pub const MIN_CELL_ULPS: f64 = 4.0;

/// The deepest level whose cells still span [`MIN_CELL_ULPS`] spacings of the largest
/// coordinate of the root cube: it limits the depth of scenes far from the origin
/// (a unit object at 1e6 gets 3 levels, one at 1e7 a single leaf) and nothing else.
pub fn precision_depth(root_lo: [f32; 3], root_size: f32) -> u32 {
    let magnitude =
        (0..3).map(|a| (root_lo[a] as f64).abs().max((root_lo[a] as f64 + root_size as f64).abs())).fold(0.0, f64::max);
    let spacing = magnitude * f64::from(f32::EPSILON); // an upper bound of the ulp there
    if spacing == 0.0 {
        return octrace_format::layout::MAX_LEVEL;
    }
    (root_size as f64 / (MIN_CELL_ULPS * spacing)).log2().floor().max(0.0) as u32
}

/// The cube map's level: texels about one per six leaves, so its size stays in
/// proportion to the octree (`6 * 4^k` texels), never deeper than the tree.
pub fn cube_level(leaves: usize, max_depth: u32) -> u32 {
    let k = ((leaves as f64 / 6.0).max(1.0).log2() / 2.0).floor() as u32;
    k.min(max_depth)
}

/// The share of degenerate triangles past which a bake is worth a warning
/// ([`degenerate_warning`]): real meshes carry a few (the dragon 108 of 871,414).
pub const DEGENERATE_WARNING_SHARE: f64 = 0.01;

/// How a mesh's box compares with `f32`'s spacing where it lies.
struct Collapse {
    extent: f64,
    largest: f64,
    spacing: f64,
}

impl Collapse {
    fn of(lo: [f32; 3], hi: [f32; 3]) -> Collapse {
        let extent = (0..3).map(|a| hi[a] as f64 - lo[a] as f64).fold(0.0, f64::max);
        let largest = (0..3).map(|a| (lo[a] as f64).abs().max((hi[a] as f64).abs())).fold(0.0, f64::max);
        let spacing = (largest as f32).next_up() as f64 - largest as f32 as f64;
        Collapse { extent, largest, spacing }
    }
}

/// A warning for a baked scene that left out more than [`DEGENERATE_WARNING_SHARE`] of
/// its triangles as degenerate, naming the count and the share, and the likely cause
/// when the mesh is small against `f32`'s spacing where it lies (its vertices round
/// together). A bake that leaves out every triangle fails instead
/// ([`Error::Collapsed`]).
///
/// # Example
/// ```
/// use octrace_bake::{bake, octree::degenerate_warning, procedural, Mesh};
/// let mut mesh = procedural::sphere([0.0; 3], 1.0, 8, 12);
/// assert!(degenerate_warning(&bake(&mesh, &Default::default())?).is_none());
/// // A third of the triangles with all three vertices on one point.
/// let n = mesh.triangles.len();
/// mesh.triangles.extend(vec![[[0.5; 3]; 3]; n / 2]);
/// let warning = degenerate_warning(&bake(&mesh, &Default::default())?).unwrap();
/// assert!(warning.contains("33.3 %"), "{warning}");
/// # Ok::<(), octrace_bake::Error>(())
/// ```
pub fn degenerate_warning(scene: &BakedScene) -> Option<String> {
    let (n, bad) = (scene.stats.input_triangles, scene.stats.degenerate_triangles);
    let share = bad as f64 / n.max(1) as f64;
    if share <= DEGENERATE_WARNING_SHARE {
        return None;
    }
    let c = Collapse::of(scene.bounds.mesh_lo, scene.bounds.mesh_hi);
    let cause = if c.spacing * 1e4 > c.extent {
        format!(
            ": the mesh spans {} at coordinates up to {}, where f32's spacing is {}, so vertices round together; \
             move it towards the origin (or scale it up)",
            crate::error::number(c.extent),
            crate::error::number(c.largest),
            crate::error::number(c.spacing)
        )
    } else {
        " (zero area: repeated or collinear vertices in the input)".to_string()
    };
    Some(format!("{bad} of {n} triangles ({:.1} %) are degenerate and left out{cause}", 100.0 * share))
}

/// Puts the stored triangles in the order of the closest-point tree `words` made over
/// them (its clusters' triangles side by side): `order` (input indices, by stored
/// index) and the leaves' references `refs` follow, and the tree's own indices become
/// `0, 1, 2, ...`. The leaves' lists keep their order (by input index).
fn in_distance_order(words: &mut [u32], order: &mut Vec<u32>, refs: &mut [u32]) -> Result<()> {
    use octrace_format::memory::try_vec;
    let n = order.len();
    if octrace_format::distance::Tree::parse(words).map(|t| t.prims.len()) != Some(n) {
        return Ok(());
    }
    let prims_at = words.len() - n;
    let mut now: Vec<u32> = try_vec(n, "triangles in the distance tree's order")?;
    let mut moved: Vec<u32> = try_vec(n, "triangles in the distance tree's order")?;
    for (new, prim) in words[prims_at..].iter_mut().enumerate() {
        now[new] = order[*prim as usize];
        moved[*prim as usize] = new as u32;
        *prim = new as u32;
    }
    for r in refs {
        *r = moved[*r as usize];
    }
    *order = now;
    Ok(())
}

/// Bakes a mesh into a scene, reporting stages to `progress`.
///
/// Runs on the current rayon pool; the result does not depend on its thread count.
///
/// # Errors
/// [`Error::NonFinite`] for a NaN or infinite coordinate, [`Error::EmptyScene`] for
/// no triangles, [`Error::Collapsed`] when every triangle is degenerate at `f32`, [`Error::Scale`] for a scene smaller, larger or farther from the origin
/// than the tracer serves, [`Error::TooLarge`] for 2^32 - 1 triangles or more, and
/// [`Error::Limit`] for an octree past the format's indices: its non-degenerate
/// triangles alone past 2^32 - 1 references before the build starts, else as soon
/// as the tree being built passes 2^32 - 1 references or 2^31 words of leaf records
/// (the build stops there).
///
/// # Example
/// ```
/// use octrace_bake::{bake, BuildParams, Mesh};
/// let mesh = Mesh::from_triangles(vec![[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
/// let scene = bake(&mesh, &BuildParams::auto())?;
/// assert_eq!(scene.triangle_ids, vec![0]);
/// scene.view().validate()?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn bake(mesh: &Mesh, params: &BuildParams) -> Result<BakedScene> {
    bake_with_progress(mesh, params, &|_| {})
}

/// [`bake`], calling `progress` as each stage starts.
///
/// # Errors
/// As [`bake`].
pub fn bake_with_progress(
    mesh: &Mesh,
    params: &BuildParams,
    progress: &(dyn Fn(BakeStage) + Sync),
) -> Result<BakedScene> {
    bake_within(mesh, params, progress, Limits { bytes: params.tree_budget(mesh), ..Limits::FORMAT })
}

/// [`bake_with_progress`] against `limits` (the format's, or lower ones in tests).
fn bake_within(
    mesh: &Mesh,
    params: &BuildParams,
    progress: &(dyn Fn(BakeStage) + Sync),
    limits: Limits,
) -> Result<BakedScene> {
    progress(BakeStage::Prepare);
    let Prepared { lo, hi, ids, root_lo, root_size, resolved } = prepare(mesh, params)?;
    // Closed and consistently oriented, or not: each part, and the whole scene. Counted
    // before the tree is built, so that the census's sort never shares the peak with
    // the tree or the scene's arrays.
    let edges = EdgeCensus::of(&mesh.triangles);
    let mut parts = mesh.parts.clone();
    for p in &mut parts {
        let range = p.first as usize..(p.first as usize + p.count as usize).min(mesh.triangles.len());
        // A part that is the whole mesh (an OBJ without objects) has its census.
        p.edges = if range == (0..mesh.triangles.len()) { edges } else { EdgeCensus::of(&mesh.triangles[range]) };
    }
    // Every kept triangle is referenced by one leaf at least.
    if ids.len() as u64 > limits.refs {
        return Err(Error::Limit { what: "triangle references", needed: ids.len() as u64, limit: limits.refs });
    }
    // The build reads the mesh's own triangles by input index: no copy of them.
    let builder = builder(&mesh.triangles, root_lo, root_size, &resolved, limits);
    let kept = ids.len();

    progress(BakeStage::Build);
    let mut root: Node = builder.build((0, [0; 3]), ids);
    let leaves_before_balance = root.leaf_count() as u64;

    progress(BakeStage::Balance);
    balance::balance(&mut root, &builder);
    if builder.growth.passed() {
        return Err(builder.growth.error());
    }

    progress(BakeStage::Link);
    let flat = FlatTree::new(root);
    let cube = cube_level(flat.leaf_cells.len(), resolved.max_depth);
    let mut arrays = flatten::arrays(&flat, mesh.triangles.len(), root_lo, root_size, cube, limits)?;
    drop(flat);
    debug_assert_eq!(arrays.tri_order.len(), kept, "every triangle lies in some leaf");
    let stored_triangles = |order: &[u32]| {
        // Sized up front (a flat_map's collect grows by doubling: a copy and a quarter
        // more at the peak).
        let mut triangles = Vec::with_capacity(9 * order.len());
        triangles.extend(order.iter().flat_map(|&t| mesh.triangles[t as usize].concat()));
        triangles
    };
    let mut distance = Vec::new();
    if params.distance {
        progress(BakeStage::Distance);
        // Made over the triangles in the leaves' order (a copy dropped before they are
        // put in its own), then stored in its order.
        distance = octrace_format::distance::build(&stored_triangles(&arrays.tri_order), |_| true)?;
        in_distance_order(&mut distance, &mut arrays.tri_order, &mut arrays.tri_refs)?;
    }
    let triangles = stored_triangles(&arrays.tri_order);
    // The stored order, as input indices.
    let triangle_ids: Vec<u32> = arrays.tri_order;
    // Per-triangle attributes follow the stored order, when the mesh has them.
    fn stored<T: Copy, U>(attr: &[T], ids: &[u32], f: impl Fn(T) -> U) -> Vec<U> {
        if attr.is_empty() {
            return Vec::new();
        }
        ids.iter().map(|&i| f(attr[i as usize])).collect()
    }
    let material_ids = stored(&mesh.material_ids, &triangle_ids, |m| m);
    let normals = stored(&mesh.normals, &triangle_ids, |n| n.concat()).concat();
    // Texture coordinates, channel after channel: as many as the data or a material
    // asks for (a channel no primitive had is zeros), none without any coordinates.
    let mut materials = mesh.materials.clone();
    let with_data =
        mesh.more_uvs.iter().rposition(|c| !c.is_empty()).map_or(usize::from(!mesh.uvs.is_empty()), |c| c + 2);
    let asked = materials.iter().flat_map(|m| m.uv_channels).max().map_or(0, |c| c as usize + 1);
    let channels = if with_data == 0 { 0 } else { with_data.max(asked) };
    if channels == 0 {
        materials.iter_mut().for_each(|m| m.uv_channels = [0; 5]);
    }
    let zeros = vec![[[0.0f32; 2]; 3]; mesh.triangles.len()];
    let uvs = (0..channels)
        .flat_map(|c| {
            let data = if c == 0 { &mesh.uvs } else { mesh.more_uvs.get(c - 1).unwrap_or(&zeros) };
            stored(if data.is_empty() { &zeros } else { data }, &triangle_ids, |t| t.concat()).concat()
        })
        .collect();
    let tangents = stored(&mesh.tangents, &triangle_ids, |t| {
        t.map(|c| octrace_format::layout::encode_tangent(unit_tangent(c))).concat()
    })
    .concat();
    let colors = stored(&mesh.colors, &triangle_ids, |c| {
        c.map(|[r, g, b, a]| [r as u32 | (g as u32) << 16, b as u32 | (a as u32) << 16]).concat()
    })
    .concat();
    let (textures, texels, images) = mesh.texel_sections();
    let shading = octrace_format::Shading {
        materials,
        lights: mesh.lights.clone(),
        cameras: mesh.cameras.clone(),
        textures,
        parts,
        effects: crate::effects::decide(mesh, &triangle_ids),
    };
    Ok(BakedScene {
        params: BakeParams {
            max_depth: resolved.max_depth,
            leaf_size: resolved.leaf_size,
            margin: resolved.margin,
            cube_level: cube,
        },
        bounds: Bounds { mesh_lo: lo, mesh_hi: hi, root_lo, root_size },
        stats: BakeStats {
            input_triangles: mesh.triangles.len() as u64,
            degenerate_triangles: (mesh.triangles.len() - kept) as u64,
            leaves_before_balance,
            edges,
        },
        octree: arrays.octree,
        tri_refs: arrays.tri_refs,
        triangles,
        triangle_ids,
        boxes: arrays.boxes,
        cube_map: arrays.cube_map,
        nodes: arrays.nodes,
        material_ids,
        normals,
        uvs,
        colors,
        tangents,
        texels,
        images,
        distance,
        root: arrays.root,
        shading,
        decoded: Default::default(),
    })
}

/// A corner's tangent as the format stores it: a unit `x y z` and a sign of 1 or -1,
/// or zeros where it has none (a zero sign or a direction that does not normalise).
fn unit_tangent(t: [f32; 4]) -> [f32; 4] {
    let v = glam::Vec3::new(t[0], t[1], t[2]).normalize_or_zero();
    if t[3] == 0.0 || !t[3].is_finite() || v == glam::Vec3::ZERO {
        return [0.0; 4];
    }
    [v.x, v.y, v.z, if t[3] > 0.0 { 1.0 } else { -1.0 }]
}

/// What every build starts from.
struct Prepared {
    /// The mesh's bounds.
    lo: [f32; 3],
    hi: [f32; 3],
    /// Input index of each kept (non-degenerate) triangle.
    ids: Vec<u32>,
    root_lo: [f32; 3],
    root_size: f32,
    resolved: ResolvedParams,
}

/// Checks the mesh, sorts out degenerate triangles, finds the root cube and resolves
/// the parameters.
fn prepare(mesh: &Mesh, params: &BuildParams) -> Result<Prepared> {
    let name = std::path::Path::new("mesh");
    params.check()?;
    mesh.check_bakeable(name)?;
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for (i, t) in mesh.triangles.iter().enumerate() {
        for v in t {
            crate::mesh::check_finite(*v, name, || format!("triangle {i}"))?;
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
    }
    let ids: Vec<u32> =
        (0..mesh.triangles.len() as u32).filter(|&i| !is_degenerate(&mesh.triangles[i as usize])).collect();
    if ids.is_empty() {
        let collapse = Collapse::of(lo, hi);
        return Err(Error::Collapsed {
            triangles: mesh.triangles.len() as u64,
            extent: collapse.extent,
            largest: collapse.largest,
            spacing: collapse.spacing,
        });
    }
    let (root_lo, root_size) = root_cube(lo, hi)?;
    let mut resolved = params.resolve(ids.len());
    resolved.max_depth = resolved.max_depth.min(precision_depth(root_lo, root_size));
    Ok(Prepared { lo, hi, ids, root_lo, root_size, resolved })
}

fn builder<'a>(
    kept: &'a [[[f32; 3]; 3]],
    root_lo: [f32; 3],
    root_size: f32,
    resolved: &ResolvedParams,
    limits: Limits,
) -> Builder<'a> {
    Builder {
        growth: Growth::new(limits),
        triangles: kept,
        root_lo,
        root_size,
        margin: resolved.margin as f64 * root_size as f64,
        max_depth: resolved.max_depth,
        leaf_size: resolved.leaf_size as usize,
    }
}

/// The octree as subdivision leaves it: no 2:1 constraint, no face links. The paper's
/// "unconstrained" tree (its Table 1), which it left to future work to traverse;
/// `octrace_runtime::baselines::unconstrained` walks it, so that `octrace report` can measure
/// what the constraint costs and buys. Not a file format: built in memory.
#[derive(Clone, Debug)]
pub struct Unbalanced {
    /// The root cube, as [`bake`] chooses it.
    pub root_lo: [f32; 3],
    /// Its edge (a power of two).
    pub root_size: f32,
    /// The parameters used (the depth limit as resolved).
    pub params: ResolvedParams,
    /// The non-degenerate triangles, in input order.
    pub triangles: Vec<[[f32; 3]; 3]>,
    /// The input index of each of `triangles`.
    pub ids: Vec<u32>,
    /// The leaves, depth first in octant order: `(level, cell, triangles)`, the cell in
    /// integer coordinates at its level and the triangles as indices into `triangles`.
    pub leaves: Vec<(u32, [u32; 3], Vec<u32>)>,
}

/// Builds the octree [`bake`] would build, but stops before the 2:1 constraint.
///
/// # Errors
/// As [`bake`].
///
/// # Example
/// ```
/// use octrace_bake::octree::build_unbalanced;
/// use octrace_bake::{procedural, BuildParams};
/// let mesh = procedural::sphere([0.0; 3], 1.0, 16, 24);
/// let tree = build_unbalanced(&mesh, &BuildParams::auto())?;
/// let scene = octrace_bake::bake(&mesh, &BuildParams::auto())?;
/// assert_eq!(tree.leaves.len() as u64, scene.stats.leaves_before_balance);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn build_unbalanced(mesh: &Mesh, params: &BuildParams) -> Result<Unbalanced> {
    let Prepared { ids, root_lo, root_size, resolved, .. } = prepare(mesh, params)?;
    let kept: Vec<[[f32; 3]; 3]> = ids.iter().map(|&i| mesh.triangles[i as usize]).collect();
    let builder =
        builder(&kept, root_lo, root_size, &resolved, Limits { bytes: params.tree_budget(mesh), ..Limits::FORMAT });
    let root = builder.build((0, [0; 3]), (0..kept.len() as u32).collect());
    if builder.growth.passed() {
        return Err(builder.growth.error());
    }
    let mut leaves = Vec::with_capacity(root.leaf_count());
    root.for_each_leaf((0, [0; 3]), &mut |(level, cell), tris| leaves.push((level, cell, tris.to_vec())));
    drop(root);
    Ok(Unbalanced { root_lo, root_size, params: resolved, triangles: kept, ids, leaves })
}
