//! Rigid transforms: how a registered scan's points are brought into its object's frame.

use super::TriMesh;
use glam::{DMat3, DVec3};

/// Largest deviation of `R^T R` from the identity (and of `det R` from 1) a rotation may
/// have: registration files carry six to eight digits, so a true rotation written out and
/// read back misses by about 1e-6; a scale of 1.001 or a shear does not pass.
const ROTATION_TOLERANCE: f64 = 1e-4;

/// A rigid motion `p' = rotation p + translation`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RigidTransform {
    /// The rotation (orthonormal, determinant +1).
    pub rotation: DMat3,
    /// The translation, applied after the rotation.
    pub translation: DVec3,
}

/// Why numbers do not make a rigid transform.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum RigidError {
    /// Not 16 numbers (a 4x4 matrix) or 7 (translation and quaternion).
    #[error("{found} numbers where {expected} were expected")]
    Count {
        /// Numbers wanted.
        expected: usize,
        /// Numbers given.
        found: usize,
    },
    /// A number is NaN or infinite.
    #[error("number {index} is not finite")]
    NonFinite {
        /// Its position (0-based).
        index: usize,
    },
    /// The last row of the 4x4 matrix is not `0 0 0 1`: a projective map, not a motion.
    #[error("the last row is not 0 0 0 1")]
    NotAffine,
    /// The quaternion has no length.
    #[error("the quaternion has zero length")]
    ZeroQuaternion,
    /// The 3x3 part scales, shears or mirrors.
    #[error("the 3x3 part is not a rotation (R^T R or det R off by {deviation:.2e})")]
    NotRotation {
        /// Largest deviation from the identity / from det 1.
        deviation: f64,
    },
}

impl RigidError {
    /// A stable snake_case name of the variant.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Count { .. } => "count",
            Self::NonFinite { .. } => "non_finite",
            Self::NotAffine => "not_affine",
            Self::ZeroQuaternion => "zero_quaternion",
            Self::NotRotation { .. } => "not_rotation",
        }
    }
}

impl Default for RigidTransform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl RigidTransform {
    /// The identity.
    pub const IDENTITY: Self = Self {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// A 4x4 homogeneous matrix given row by row (16 numbers: Stanford's `.xf`, the pipe's
    /// `transform`), checked to be a rotation and a translation.
    pub fn from_row_major(values: &[f64]) -> Result<Self, RigidError> {
        if values.len() != 16 {
            return Err(RigidError::Count {
                expected: 16,
                found: values.len(),
            });
        }
        check_finite(values)?;
        let last = [values[12], values[13], values[14], values[15] - 1.0];
        if last.iter().any(|x| x.abs() > ROTATION_TOLERANCE) {
            return Err(RigidError::NotAffine);
        }
        let row = |r: usize| DVec3::new(values[4 * r], values[4 * r + 1], values[4 * r + 2]);
        let rotation = DMat3::from_cols(row(0), row(1), row(2)).transpose();
        check_rotation(&rotation)?;
        Ok(Self {
            rotation,
            translation: DVec3::new(values[3], values[7], values[11]),
        })
    }

    /// The rotation of a quaternion `(x, y, z, w)` (normalised; its length must be near 1)
    /// and a translation.
    pub fn from_quaternion(translation: DVec3, xyzw: [f64; 4]) -> Result<Self, RigidError> {
        let mut all = translation.to_array().to_vec();
        all.extend(xyzw);
        check_finite(&all)?;
        let q = glam::DQuat::from_array(xyzw);
        let length = q.length();
        if length < f64::MIN_POSITIVE.sqrt() {
            return Err(RigidError::ZeroQuaternion);
        }
        if (length - 1.0).abs() > ROTATION_TOLERANCE.sqrt() {
            return Err(RigidError::NotRotation {
                deviation: (length - 1.0).abs(),
            });
        }
        Ok(Self {
            rotation: DMat3::from_quat(q / length),
            translation,
        })
    }

    /// The motion `p' = R^T p + t` (the rotation inverted, the translation kept).
    pub fn with_rotation_transposed(self) -> Self {
        Self {
            rotation: self.rotation.transpose(),
            translation: self.translation,
        }
    }

    /// The transformed point.
    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    /// The transformed direction (no translation).
    pub fn apply_vector(&self, v: DVec3) -> DVec3 {
        self.rotation * v
    }

    /// The mesh with every vertex transformed (a rotation keeps the orientation).
    pub fn apply_mesh(&self, mesh: &TriMesh) -> TriMesh {
        TriMesh::new(
            mesh.positions.iter().map(|p| self.apply(*p)).collect(),
            mesh.triangles.clone(),
        )
    }

    /// The 16 numbers of the 4x4 matrix, row by row.
    pub fn to_row_major(&self) -> [f64; 16] {
        let r = self.rotation.transpose();
        let t = self.translation;
        [
            r.x_axis.x, r.x_axis.y, r.x_axis.z, t.x, r.y_axis.x, r.y_axis.y, r.y_axis.z, t.y,
            r.z_axis.x, r.z_axis.y, r.z_axis.z, t.z, 0.0, 0.0, 0.0, 1.0,
        ]
    }
}

fn check_finite(values: &[f64]) -> Result<(), RigidError> {
    match values.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(RigidError::NonFinite { index }),
        None => Ok(()),
    }
}

fn check_rotation(r: &DMat3) -> Result<(), RigidError> {
    let gram = r.transpose() * *r - DMat3::IDENTITY;
    let off = gram
        .to_cols_array()
        .iter()
        .fold((r.determinant() - 1.0).abs(), |m, x| m.max(x.abs()));
    if off > ROTATION_TOLERANCE {
        return Err(RigidError::NotRotation { deviation: off });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_major_matrix_round_trips_and_moves_points() {
        let t = RigidTransform::from_quaternion(
            DVec3::new(0.1, -0.2, 0.3),
            [0.0, 0.0, (0.25f64).sin(), (0.25f64).cos()],
        )
        .expect("unit quaternion");
        let back = RigidTransform::from_row_major(&t.to_row_major()).expect("rigid");
        let p = DVec3::new(1.0, 2.0, 3.0);
        assert!((back.apply(p) - t.apply(p)).length() < 1e-12);
        // Half a turn of 0.5 rad about z: x goes to (cos 0.5, sin 0.5).
        let x = t.apply_vector(DVec3::X);
        assert!((x - DVec3::new(0.5f64.cos(), 0.5f64.sin(), 0.0)).length() < 1e-12);
    }

    #[test]
    fn scales_shears_projections_and_bad_numbers_are_refused() {
        let mut m = RigidTransform::IDENTITY.to_row_major();
        m[0] = 1.01;
        assert_eq!(
            RigidTransform::from_row_major(&m).map_err(|e| e.kind()),
            Err("not_rotation")
        );
        let mut m = RigidTransform::IDENTITY.to_row_major();
        m[14] = 0.5;
        assert_eq!(
            RigidTransform::from_row_major(&m),
            Err(RigidError::NotAffine)
        );
        let mut m = RigidTransform::IDENTITY.to_row_major();
        m[5] = f64::NAN;
        assert_eq!(
            RigidTransform::from_row_major(&m),
            Err(RigidError::NonFinite { index: 5 })
        );
        // A mirror is orthonormal but not a motion.
        let mut m = RigidTransform::IDENTITY.to_row_major();
        m[10] = -1.0;
        assert!(RigidTransform::from_row_major(&m).is_err());
        assert_eq!(
            RigidTransform::from_row_major(&[1.0; 15]).map_err(|e| e.kind()),
            Err("count")
        );
        assert_eq!(
            RigidTransform::from_quaternion(DVec3::ZERO, [0.0; 4]),
            Err(RigidError::ZeroQuaternion)
        );
        assert!(RigidTransform::from_quaternion(DVec3::ZERO, [0.0, 0.0, 0.0, 2.0]).is_err());
    }
}
