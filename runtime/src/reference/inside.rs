//! The oracle for inside and outside: exact, for closed meshes, independent of the
//! octree.
//!
//! A point's side is the parity of the crossings of a ray from it along a coordinate
//! axis. Along an axis every question the count asks is the sign of a determinant of
//! the `f32` coordinates, which Shewchuk's adaptive predicates (the `robust` crate)
//! answer exactly: whether the point's projection lies inside a triangle's projection
//! (three `orient2d`), and whether the crossing lies ahead of the point (`orient3d`
//! against the sign of the projected area). A projection exactly on a projected edge
//! or vertex leaves that axis undecided (the parity would depend on which of two
//! triangles owns the edge), and the next axis is asked; a point in a triangle is on
//! the surface. Candidate triangles come from a uniform grid over the two other
//! coordinates, one grid an axis, so a point costs the triangles of its grid column.
//! A point all three axes leave undecided (on a line of a grid-like mesh's vertices)
//! is counted along a segment from it to a point `q` outside the mesh's box in a
//! skew direction, over every triangle: the segment crosses a triangle where `p` and
//! `q` lie strictly on either side of its plane and the line passes strictly inside
//! its three edges (`orient3d` on the `f64` coordinates of `p` and `q`, exact).

use robust::{orient2d, orient3d, Coord, Coord3D};

/// Where a point lies against a closed mesh, by [`InsideReference::side`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Inside: an odd number of crossings.
    Inside,
    /// Outside: an even number.
    Outside,
    /// On a triangle (its plane and its closed area).
    Surface,
}

/// Exact inside/outside of points for a closed mesh (see the module's text).
///
/// # Example
/// ```
/// use octrace_bake::procedural;
/// use octrace_runtime::reference::{InsideReference, Side};
/// let cube = procedural::cube([0.0; 3], [1.0; 3], 2);
/// let oracle = InsideReference::new(&cube.triangles);
/// assert_eq!(oracle.side([0.3, 0.2, 0.7]), Some(Side::Inside));
/// assert_eq!(oracle.side([1.3, 0.2, 0.7]), Some(Side::Outside));
/// assert_eq!(oracle.side([1.0, 0.2, 0.7]), Some(Side::Surface));
/// ```
#[derive(Clone, Debug)]
pub struct InsideReference {
    triangles: Vec<[[f32; 3]; 3]>,
    lo: [f32; 3],
    hi: [f32; 3],
    grids: [Columns; 3],
}

/// The triangles whose projection along one axis meets each cell of a uniform grid
/// over the other two coordinates.
#[derive(Clone, Debug)]
struct Columns {
    /// The two coordinates the grid spans (the axis's cyclic successors).
    b: usize,
    c: usize,
    lo: [f64; 2],
    scale: [f64; 2],
    cells: [usize; 2],
    /// `items[start[k]..start[k + 1]]` are the triangles of cell `k`.
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Columns {
    fn new(triangles: &[[[f32; 3]; 3]], axis: usize, lo: [f32; 3], hi: [f32; 3]) -> Columns {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        // About two triangles a cell where they spread evenly; at most 2^11 a side.
        let side = ((triangles.len() as f64 / 2.0).sqrt().ceil() as usize).clamp(1, 1 << 11);
        let lo2 = [lo[b] as f64, lo[c] as f64];
        let extent = [(hi[b] as f64 - lo2[0]).max(f64::MIN_POSITIVE), (hi[c] as f64 - lo2[1]).max(f64::MIN_POSITIVE)];
        let mut grid = Columns {
            b,
            c,
            lo: lo2,
            scale: [side as f64 / extent[0], side as f64 / extent[1]],
            cells: [side, side],
            start: vec![0; side * side + 1],
            items: Vec::new(),
        };
        // Counting sort by cell: each triangle in every cell its projected box meets.
        // The cell of a coordinate is monotonic in it, so a point between a box's
        // corners lies in a cell between theirs.
        let range = |g: &Columns, t: &[[f32; 3]; 3]| {
            let min = |k: usize| t.iter().map(|v| v[k]).fold(f32::INFINITY, f32::min);
            let max = |k: usize| t.iter().map(|v| v[k]).fold(f32::NEG_INFINITY, f32::max);
            (g.cell(0, min(b)), g.cell(0, max(b)), g.cell(1, min(c)), g.cell(1, max(c)))
        };
        for t in triangles {
            let (i0, i1, j0, j1) = range(&grid, t);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    grid.start[j * side + i + 1] += 1;
                }
            }
        }
        for k in 1..grid.start.len() {
            grid.start[k] += grid.start[k - 1];
        }
        let mut fill = grid.start.clone();
        grid.items = vec![0; *grid.start.last().unwrap_or(&0) as usize];
        for (n, t) in triangles.iter().enumerate() {
            let (i0, i1, j0, j1) = range(&grid, t);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let slot = &mut fill[j * side + i];
                    grid.items[*slot as usize] = n as u32;
                    *slot += 1;
                }
            }
        }
        grid
    }

    /// The grid column of coordinate `x` along the grid's `k`-th coordinate.
    fn cell(&self, k: usize, x: f32) -> usize {
        let f = ((x as f64 - self.lo[k]) * self.scale[k]).floor();
        (f.max(0.0) as usize).min(self.cells[k] - 1)
    }

    fn column(&self, p: [f32; 3]) -> &[u32] {
        let k = self.cell(1, p[self.c]) * self.cells[0] + self.cell(0, p[self.b]);
        &self.items[self.start[k] as usize..self.start[k + 1] as usize]
    }
}

/// What one axis says of a point.
enum Count {
    Parity(bool),
    Surface,
    Undecided,
}

impl InsideReference {
    /// An oracle over `triangles`, which should form a closed mesh (the answers of an
    /// open one are the parity along an axis, which means nothing).
    pub fn new(triangles: &[[[f32; 3]; 3]]) -> InsideReference {
        let (lo, hi) = triangles.iter().flatten().fold(([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]), |(l, h), p| {
            ([0, 1, 2].map(|k| l[k].min(p[k])), [0, 1, 2].map(|k| h[k].max(p[k])))
        });
        let (lo, hi) = if triangles.is_empty() { ([0.0; 3], [0.0; 3]) } else { (lo, hi) };
        InsideReference {
            triangles: triangles.to_vec(),
            lo,
            hi,
            grids: [0, 1, 2].map(|axis| Columns::new(triangles, axis, lo, hi)),
        }
    }

    /// The side of `p`: `None` only where its projection lies exactly on a projected
    /// edge or vertex along all three axes (a point on an axis-aligned edge of the
    /// mesh, say), or for a point that is not finite.
    pub fn side(&self, p: [f32; 3]) -> Option<Side> {
        if !p.iter().all(|x| x.is_finite()) {
            return None;
        }
        if !(0..3).all(|k| self.lo[k] <= p[k] && p[k] <= self.hi[k]) {
            return Some(Side::Outside);
        }
        for axis in 0..3 {
            match self.count(axis, p) {
                Count::Parity(odd) => return Some(if odd { Side::Inside } else { Side::Outside }),
                Count::Surface => return Some(Side::Surface),
                Count::Undecided => {}
            }
        }
        let extent = (0..3).map(|k| self.hi[k] as f64 - self.lo[k] as f64 + (p[k] as f64).abs()).sum::<f64>();
        for d in [[1.0, 0.618034, 0.414214], [-0.302775, 1.0, 0.732051], [0.236068, -0.645751, 1.0]] {
            let q = [0, 1, 2].map(|k| p[k] as f64 + 4.0 * extent * d[k]);
            match self.count_towards(p, q) {
                Count::Parity(odd) => return Some(if odd { Side::Inside } else { Side::Outside }),
                Count::Surface => return Some(Side::Surface),
                Count::Undecided => {}
            }
        }
        None
    }

    /// The parity of the crossings of the segment from `p` to `q` (outside the mesh's
    /// box), over every triangle.
    fn count_towards(&self, p: [f32; 3], q: [f64; 3]) -> Count {
        let c = |v: [f64; 3]| Coord3D { x: v[0], y: v[1], z: v[2] };
        let w = |v: &[f32; 3]| c(v.map(f64::from));
        let (cp, cq) = (w(&p), c(q));
        let mut odd = false;
        for t in &self.triangles {
            let edges = [
                orient3d(cp, cq, w(&t[0]), w(&t[1])),
                orient3d(cp, cq, w(&t[1]), w(&t[2])),
                orient3d(cp, cq, w(&t[2]), w(&t[0])),
            ];
            if edges.iter().any(|&e| e > 0.0) && edges.iter().any(|&e| e < 0.0) {
                continue; // the line misses
            }
            let (hp, hq) = (orient3d(w(&t[0]), w(&t[1]), w(&t[2]), cp), orient3d(w(&t[0]), w(&t[1]), w(&t[2]), cq));
            if hp == 0.0 {
                if edges.iter().all(|&e| e == 0.0) {
                    return Count::Undecided; // the segment lies in the plane
                }
                return Count::Surface;
            }
            if (hp > 0.0) == (hq > 0.0) {
                continue; // both ends on one side
            }
            if edges.contains(&0.0) {
                return Count::Undecided;
            }
            odd = !odd;
        }
        Count::Parity(odd)
    }

    /// The parity of the crossings of the ray from `p` along `+axis`.
    fn count(&self, axis: usize, p: [f32; 3]) -> Count {
        let grid = &self.grids[axis];
        let (b, c) = (grid.b, grid.c);
        let flat = |v: &[f32; 3]| Coord { x: v[b], y: v[c] };
        let point = |v: &[f32; 3]| Coord3D { x: v[0], y: v[1], z: v[2] };
        let q = flat(&p);
        let mut odd = false;
        let mut undecided = false;
        for &n in grid.column(p) {
            let t = &self.triangles[n as usize];
            if t.iter().all(|v| v[axis] < p[axis]) {
                continue; // wholly behind the point
            }
            // The projected triangle's doubled signed area: e_axis . n.
            let area = orient2d(flat(&t[0]), flat(&t[1]), flat(&t[2]));
            let edges = [
                orient2d(flat(&t[1]), flat(&t[2]), q),
                orient2d(flat(&t[2]), flat(&t[0]), q),
                orient2d(flat(&t[0]), flat(&t[1]), q),
            ];
            let positive = edges.iter().any(|&e| e > 0.0);
            let negative = edges.iter().any(|&e| e < 0.0);
            if positive && negative {
                continue; // the projection misses
            }
            // (v0 - p) . n: zero in the triangle's plane; the crossing is ahead where
            // it has the sign of e_axis . n.
            let height = orient3d(point(&t[0]), point(&t[1]), point(&t[2]), point(&p));
            let boundary = edges.contains(&0.0);
            if area == 0.0 {
                // Edge-on along the axis: the ray meets it only along its projection,
                // in its plane.
                if boundary || height == 0.0 {
                    undecided = true;
                }
                continue;
            }
            if height == 0.0 {
                return Count::Surface;
            }
            if (height > 0.0) != (area > 0.0) {
                continue; // the crossing is behind
            }
            if boundary {
                undecided = true;
            } else {
                odd = !odd;
            }
        }
        if undecided {
            Count::Undecided
        } else {
            Count::Parity(odd)
        }
    }
}
