//! Affine transforms in `f64`: an instance's placement.

use crate::error::{Error, Result};

/// An affine transform `x -> L x + t`, in `f64`, stored as the three rows of a 3x4
/// matrix `[L | t]` (numpy's and Open3D's row-major order): where an instance's
/// triangles are placed. Points and directions are carried in `f64` and rounded once.
///
/// # Example
/// ```
/// use octrace_runtime::world::Transform;
/// let place = Transform::translation([1.0, 2.0, 3.0]).then(&Transform::scaling([2.0, 2.0, 2.0]));
/// assert_eq!(place.point([0.0, 0.0, 0.0]), [2.0, 4.0, 6.0]); // translated, then scaled
/// assert_eq!(place.inverse()?.point([2.0, 4.0, 6.0]), [0.0, 0.0, 0.0]);
/// # Ok::<(), octrace_runtime::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// The rows `[L | t]`.
    pub rows: [[f64; 4]; 3],
}

impl Default for Transform {
    fn default() -> Transform {
        Transform::IDENTITY
    }
}

impl Transform {
    /// `x -> x`.
    pub const IDENTITY: Transform =
        Transform { rows: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]] };

    /// The transform of the rows of a 3x4 matrix `[L | t]`.
    pub fn from_rows(rows: [[f64; 4]; 3]) -> Transform {
        Transform { rows }
    }

    /// The transform of a 4x4 matrix (rows), whose last row must be `0 0 0 1`.
    ///
    /// # Errors
    /// [`Error::Transform`] where the last row is anything else (a projection).
    pub fn from_matrix(m: [[f64; 4]; 4]) -> Result<Transform> {
        if m[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(Error::Transform {
                what: format!("{m:?}"),
                reason: "the last row of a 4x4 placement must be 0 0 0 1 (an affine transform)",
            });
        }
        Ok(Transform { rows: [m[0], m[1], m[2]] })
    }

    /// `x -> x + t`.
    pub fn translation(t: [f64; 3]) -> Transform {
        let mut m = Transform::IDENTITY;
        for (row, t) in m.rows.iter_mut().zip(t) {
            row[3] = t;
        }
        m
    }

    /// `x -> s x`, coordinate by coordinate.
    pub fn scaling(s: [f64; 3]) -> Transform {
        let mut m = Transform::IDENTITY;
        for (k, s) in s.into_iter().enumerate() {
            m.rows[k][k] = s;
        }
        m
    }

    /// The rotation by `angle` radians about `axis` (right-handed; the axis need not
    /// be of unit length, and a zero axis gives the identity).
    pub fn rotation(axis: [f64; 3], angle: f64) -> Transform {
        let len = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        if len.is_nan() || len <= 0.0 {
            return Transform::IDENTITY;
        }
        let [x, y, z] = axis.map(|c| c / len);
        let (s, c) = angle.sin_cos();
        let k = 1.0 - c;
        Transform {
            rows: [
                [c + x * x * k, x * y * k - z * s, x * z * k + y * s, 0.0],
                [y * x * k + z * s, c + y * y * k, y * z * k - x * s, 0.0],
                [z * x * k - y * s, z * y * k + x * s, c + z * z * k, 0.0],
            ],
        }
    }

    /// This transform, then `next`: `x -> next(self(x))`.
    pub fn then(&self, next: &Transform) -> Transform {
        let (a, b) = (&next.rows, &self.rows);
        let mut rows = [[0.0; 4]; 3];
        for (i, row) in rows.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] + if j == 3 { a[i][3] } else { 0.0 };
            }
        }
        Transform { rows }
    }

    /// `L p + t`.
    #[inline]
    pub fn point(&self, p: [f64; 3]) -> [f64; 3] {
        self.rows.map(|r| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3])
    }

    /// `L v`: a direction carried (not normalised).
    #[inline]
    pub fn vector(&self, v: [f64; 3]) -> [f64; 3] {
        self.rows.map(|r| r[0] * v[0] + r[1] * v[1] + r[2] * v[2])
    }

    /// `L`'s determinant.
    pub fn determinant(&self) -> f64 {
        let m = &self.rows;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// The inverse transform.
    ///
    /// # Errors
    /// [`Error::Transform`] where an entry is not finite, or `L` cannot be inverted
    /// in `f64` (its determinant zero, or an entry of the inverse not finite).
    pub fn inverse(&self) -> Result<Transform> {
        let bad = |reason| Err(Error::Transform { what: format!("{:?}", self.rows), reason });
        if !self.rows.iter().flatten().all(|x| x.is_finite()) {
            return bad("an entry is not finite");
        }
        let m = &self.rows;
        let det = self.determinant();
        if det == 0.0 || !det.is_finite() {
            return bad("its linear part is singular (determinant 0): it flattens the instance");
        }
        // The adjugate over the determinant.
        let c = |i: usize, j: usize| {
            let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
            let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let mut rows = [[0.0; 4]; 3];
        for (i, row) in rows.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().take(3).enumerate() {
                *x = c(j, i) / det;
            }
        }
        let t = [m[0][3], m[1][3], m[2][3]];
        for row in &mut rows {
            row[3] = -(row[0] * t[0] + row[1] * t[1] + row[2] * t[2]);
        }
        if !rows.iter().flatten().all(|x| x.is_finite()) {
            return bad("its inverse is not finite in f64 (a scale past f64's range)");
        }
        Ok(Transform { rows })
    }
}
