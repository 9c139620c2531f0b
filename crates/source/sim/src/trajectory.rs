use voxpan_core::Pose;
use voxpan_core::nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::Scene;

/// A smooth loop through the free middle of the room, looking around like a mobile robot's
/// camera: an ellipse at 1.2-1.4 m height, the view sweeping between the walls.
pub fn trajectory(scene: &Scene, frames: usize) -> Vec<Pose> {
    let c = Vector3::new(scene.size.x / 2.0, scene.size.y / 2.0, 0.0);
    let (ax, ay) = (
        (scene.size.x / 2.0 - 1.8).max(0.3),
        (scene.size.y / 2.0 - 1.8).max(0.3),
    );
    (0..frames)
        .map(|i| {
            let s = i as f64 / frames.max(1) as f64;
            let theta = std::f64::consts::TAU * s;
            let position = Point3::new(
                c.x + ax * theta.cos(),
                c.y + ay * theta.sin(),
                1.3 + 0.1 * (2.0 * theta).sin(),
            );
            // Look outwards, sweeping ±60° around the radial direction, slightly down.
            let heading = theta + 1.05 * (3.0 * theta).sin();
            let forward = Vector3::new(heading.cos(), heading.sin(), -0.25).normalize();
            look_along(position, forward)
        })
        .collect()
}

/// The pose of a camera at `position` looking along `forward` with world z up
/// (optical frame: x right, y down, z forward).
pub fn look_along(position: Point3<f64>, forward: Vector3<f64>) -> Pose {
    let z = forward.normalize();
    let x = z.cross(&Vector3::z()).normalize();
    let y = z.cross(&x);
    let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Pose::from_parts(
        Translation3::from(position.coords),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}
