use rayon::prelude::*;
use voxpan_core::nalgebra::Point3;
use voxpan_core::{ColorImage, DepthImage, Image, Intrinsics, LabelImage, Pose};

use crate::Scene;

/// A ray-cast view: exact colour, planar depth and instance ids.
#[derive(Clone, Debug, PartialEq)]
pub struct Rendered {
    pub color: ColorImage,
    /// Planar depth (z in the camera frame), metres; 0 where the ray hits nothing.
    pub depth: DepthImage,
    /// Instance id per pixel; 0 where the ray hits nothing.
    pub instances: LabelImage,
    /// Which of its object's shapes each pixel shows, counted from 1; 0 where the ray hits
    /// nothing. (A group's items: see [`MaskErrors::one_by_one`](crate::MaskErrors).)
    pub parts: LabelImage,
}

/// One pixel of a ray-cast: colour, planar depth, instance id, shape of the instance.
type Sample = ([u8; 3], f32, u16, u16);

/// Ray-casts `scene` from `pose` (`T_world_camera`, optical frame), rows in parallel.
pub fn render(scene: &Scene, pose: &Pose, k: &Intrinsics) -> Rendered {
    let origin = Point3::from(pose.translation.vector);
    let rows: Vec<Vec<Sample>> = (0..k.height)
        .into_par_iter()
        .map(|v| {
            (0..k.width)
                .map(|u| {
                    // z = 1 in the camera frame, so the ray parameter is the planar depth.
                    let dir = pose.rotation * k.ray(u as f64, v as f64);
                    match scene.intersect(&origin, &dir) {
                        Some(hit) => {
                            let point = origin + dir * hit.t;
                            (
                                scene.shade(hit.object, &point, &hit.normal),
                                hit.t as f32,
                                scene.objects[hit.object].instance_id,
                                (hit.shape + 1).min(u16::MAX as usize) as u16,
                            )
                        }
                        None => ([0, 0, 0], 0.0, 0, 0),
                    }
                })
                .collect()
        })
        .collect();
    let flat: Vec<_> = rows.into_iter().flatten().collect();
    let (w, h) = (k.width, k.height);
    Rendered {
        color: Image::from_vec(w, h, flat.iter().map(|p| p.0).collect()).expect("w*h pixels"),
        depth: Image::from_vec(w, h, flat.iter().map(|p| p.1).collect()).expect("w*h pixels"),
        instances: Image::from_vec(w, h, flat.iter().map(|p| p.2).collect()).expect("w*h pixels"),
        parts: Image::from_vec(w, h, flat.iter().map(|p| p.3).collect()).expect("w*h pixels"),
    }
}
