use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3,
};

/// Camera pose `T_world_camera`: maps points in the camera's optical frame (x right, y down,
/// z forward) into the world frame.
pub type Pose = Isometry3<f64>;

/// Pinhole intrinsics of a `width × height` image (pixel centres at integer coordinates).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Intrinsics {
    pub width: usize,
    pub height: usize,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// Whether these intrinsics can project: a non-empty image, finite positive focal lengths
    /// and a finite principal point. The error says which value is wrong.
    pub fn check(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!("image size {}x{}", self.width, self.height));
        }
        for (name, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(format!(
                    "{name} = {f} (a focal length must be finite and positive)"
                ));
            }
        }
        for (name, c) in [("cx", self.cx), ("cy", self.cy)] {
            if !c.is_finite() {
                return Err(format!("{name} = {c}"));
            }
        }
        Ok(())
    }

    /// The viewing direction through pixel `(u, v)`, scaled so that its z is 1: a point at
    /// planar depth `z` on this ray is `z × ray`.
    #[inline]
    pub fn ray(&self, u: f64, v: f64) -> Vector3<f64> {
        Vector3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// Pixel coordinates of a camera-frame point (`None` behind the camera).
    #[inline]
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        (p.z > 0.0).then(|| (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }
}

/// Why a 4×4 matrix is not a camera pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PoseError {
    /// The bottom row is not `0 0 0 1`.
    NotHomogeneous,
    /// The rotation block is not orthonormal with determinant 1 (max deviation given).
    NotRigid(f64),
}

impl std::fmt::Display for PoseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PoseError::NotHomogeneous => write!(f, "the bottom row is not 0 0 0 1"),
            PoseError::NotRigid(dev) => write!(
                f,
                "the rotation block is not a rotation (|RᵀR - I| or |det R - 1| = {dev:.2e})"
            ),
        }
    }
}

/// Tolerance for a rotation read from text files with six decimals.
const RIGID_TOLERANCE: f64 = 1e-4;

/// Converts a rigid homogeneous matrix to a pose, re-orthonormalising tiny rounding errors.
pub fn pose_from_matrix(m: &Matrix4<f64>) -> Result<Pose, PoseError> {
    let bottom = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if bottom
        .iter()
        .zip([0.0, 0.0, 0.0, 1.0])
        .any(|(a, b)| (a - b).abs() > 1e-9)
    {
        return Err(PoseError::NotHomogeneous);
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let deviation = (r.transpose() * r - Matrix3::identity())
        .abs()
        .max()
        .max((r.determinant() - 1.0).abs());
    if deviation.is_nan() || deviation > RIGID_TOLERANCE {
        return Err(PoseError::NotRigid(deviation));
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
    let translation = Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Ok(Isometry3::from_parts(translation, rotation))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_and_projection_are_inverse() {
        let k = Intrinsics {
            width: 640,
            height: 480,
            fx: 320.0,
            fy: 310.0,
            cx: 320.0,
            cy: 240.0,
        };
        let p = Point3::from(k.ray(100.5, 400.25) * 2.5);
        let (u, v) = k.project(&p).unwrap();
        assert!((u - 100.5).abs() < 1e-12 && (v - 400.25).abs() < 1e-12);
        assert!(k.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn rigid_matrices_only() {
        let mut m = Matrix4::identity();
        m[(0, 3)] = 1.5;
        assert!((pose_from_matrix(&m).unwrap().translation.vector.x - 1.5).abs() < 1e-15);
        m[(0, 0)] = 2.0;
        assert!(matches!(pose_from_matrix(&m), Err(PoseError::NotRigid(_))));
        let mut m = Matrix4::identity();
        m[(3, 0)] = 0.5;
        assert_eq!(pose_from_matrix(&m), Err(PoseError::NotHomogeneous));
    }
}
