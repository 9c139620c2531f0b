//! The map node's distance queries (`PREFIX/distance`, voxpan_msgs/DistanceQuery, ROS 1): a
//! planner asks for the signed distance and its gradient at many points at once.

use voxpan_core::nalgebra::Point3;
use voxpan_map::PanopticMap;

use crate::msgs::{geometry_msgs, voxpan_msgs};

/// The answer for `points` from `map` (`None` once the node has stopped mapping): the
/// distance field brought up to date with the frames integrated so far, then interpolated
/// distances and gradients where the eight voxels around a point are observed, the point's
/// own voxel's distance (and a NaN gradient) where only it is, NaN where it is unknown.
pub fn distance_response(
    map: Option<&mut PanopticMap>,
    points: &[geometry_msgs::Point],
) -> voxpan_msgs::DistanceQueryResponse {
    let nan = geometry_msgs::Vector3 {
        x: f64::NAN,
        y: f64::NAN,
        z: f64::NAN,
    };
    let Some(map) = map else {
        return voxpan_msgs::DistanceQueryResponse {
            distances: vec![f32::NAN; points.len()],
            gradients: vec![nan; points.len()],
        };
    };
    map.update_esdf();
    let points: Vec<Point3<f64>> = points.iter().map(|p| Point3::new(p.x, p.y, p.z)).collect();
    let interpolated = map.distances_and_gradients(&points);
    let mut distances = Vec::with_capacity(points.len());
    let mut gradients = Vec::with_capacity(points.len());
    for (p, answer) in points.iter().zip(interpolated) {
        match answer {
            Some((d, g)) => {
                distances.push(d);
                gradients.push(geometry_msgs::Vector3 {
                    x: g.x as f64,
                    y: g.y as f64,
                    z: g.z as f64,
                });
            }
            None => {
                distances.push(map.distance(p).unwrap_or(f32::NAN));
                gradients.push(nan.clone());
            }
        }
    }
    voxpan_msgs::DistanceQueryResponse {
        distances,
        gradients,
    }
}
