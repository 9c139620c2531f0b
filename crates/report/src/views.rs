//! Pictures of a map for the run report: a top-down orthographic view with the camera
//! trajectory, and two perspective ray casts of the TSDF, each coloured by RGB, instance and
//! class.

use voxpan_core::nalgebra::{Isometry3, Point3, Vector3};
use voxpan_core::{ColorImage, Image, Intrinsics, Pose};
use voxpan_map::{PanopticMap, id_color};

/// How a picture is coloured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Paint {
    Rgb,
    Instance,
    Class,
}

impl Paint {
    pub const ALL: [Paint; 3] = [Paint::Rgb, Paint::Instance, Paint::Class];

    pub fn name(self) -> &'static str {
        match self {
            Paint::Rgb => "rgb",
            Paint::Instance => "instance",
            Paint::Class => "class",
        }
    }

    fn color(self, map: &PanopticMap, rgb: [u8; 3], instance: u16) -> [u8; 3] {
        match self {
            Paint::Rgb => rgb,
            Paint::Instance => id_color(instance as u32),
            Paint::Class => class_color(map, instance),
        }
    }
}

/// The colour of an instance's class (grey when it has none), as in the class mesh.
pub fn class_color(map: &PanopticMap, instance: u16) -> [u8; 3] {
    id_color(map.class_of(instance).map_or(0, |c| c + 1))
}

/// The world axis closest to "up" for the cameras (image rows point down, so up is the mean of
/// their negative y axes), with its sign: robot cameras are held roughly upright even when the
/// dataset's world frame has y or z up.
pub fn up_axis(poses: &[Pose]) -> (usize, f64) {
    let mean: Vector3<f64> = poses.iter().map(|p| -(p.rotation * Vector3::y())).sum();
    if mean.norm() < 1e-9 {
        return (2, 1.0);
    }
    let axis = mean.iamax();
    (axis, mean[axis].signum())
}

/// The top-down orthographic view: surface voxels seen from above, the highest per pixel,
/// shaded by height, cut half a metre above the highest camera (ceilings would hide the room),
/// with the camera trajectory drawn in black. At most `max_side` pixels on the longer side.
pub fn top_down(map: &PanopticMap, poses: &[Pose], paint: Paint, max_side: usize) -> ColorImage {
    let (up, sign) = up_axis(poses);
    let (a, b) = match up {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let height = |p: &Point3<f64>| sign * p[up];
    let cut = poses
        .iter()
        .map(|p| height(&Point3::from(p.translation.vector)))
        .fold(f64::NEG_INFINITY, f64::max)
        + 0.5;
    let voxels: Vec<_> = map
        .surface_voxels()
        .filter(|v| poses.is_empty() || height(&v.position) <= cut)
        .collect();
    if voxels.is_empty() {
        return Image::filled(1, 1, [255; 3]);
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let (mut h_lo, mut h_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in &voxels {
        for (k, axis) in [a, b].into_iter().enumerate() {
            lo[k] = lo[k].min(v.position[axis]);
            hi[k] = hi[k].max(v.position[axis]);
        }
        h_lo = h_lo.min(height(&v.position));
        h_hi = h_hi.max(height(&v.position));
    }
    let voxel = map.voxel_size();
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]) + voxel;
    let pixel = (extent / max_side as f64).max(voxel);
    let w = ((hi[0] - lo[0] + voxel) / pixel).ceil() as usize + 1;
    let h = ((hi[1] - lo[1] + voxel) / pixel).ceil() as usize + 1;
    let mut top = vec![f64::NEG_INFINITY; w * h];
    let mut image: ColorImage = Image::filled(w, h, [255; 3]);
    // Rows from the far end of axis b, so the picture reads like a floor plan.
    // Rounded, not truncated: voxel centres lie on the pixel grid when the pixel is a voxel,
    // and truncating 2.9999 would leave empty columns.
    let at = |p: &Point3<f64>| {
        let x = ((p[a] - lo[0]) / pixel).round() as usize;
        let y = h - 1 - (((p[b] - lo[1]) / pixel).round() as usize).min(h - 1);
        (x.min(w - 1), y)
    };
    for v in &voxels {
        let (x, y) = at(&v.position);
        let z = height(&v.position);
        if z > top[y * w + x] {
            top[y * w + x] = z;
            let shade = 0.55 + 0.45 * (z - h_lo) / (h_hi - h_lo).max(1e-9);
            let c = paint.color(map, v.color, v.instance);
            *image.get_mut(x, y) = c.map(|c| (c as f64 * shade) as u8);
        }
    }
    let path: Vec<(usize, usize)> = poses
        .iter()
        .map(|p| at(&Point3::from(p.translation.vector)))
        .collect();
    // A small map is enlarged (each voxel a square of pixels) before the path is drawn.
    let scale = (max_side / w.max(h)).max(1);
    let mut image = Image::from_fn(w * scale, h * scale, |x, y| {
        *image.get(x / scale, y / scale)
    });
    for pair in path.windows(2) {
        let at = |(x, y): (usize, usize)| (x * scale + scale / 2, y * scale + scale / 2);
        draw_line(&mut image, at(pair[0]), at(pair[1]), [0, 0, 0]);
    }
    image
}

fn draw_line(image: &mut ColorImage, from: (usize, usize), to: (usize, usize), c: [u8; 3]) {
    let steps = from.0.abs_diff(to.0).max(from.1.abs_diff(to.1)).max(1);
    for s in 0..=steps {
        let t = s as f64 / steps as f64;
        let x = (from.0 as f64 + t * (to.0 as f64 - from.0 as f64)).round() as usize;
        let y = (from.1 as f64 + t * (to.1 as f64 - from.1 as f64)).round() as usize;
        for (dx, dy) in [(0, 0), (1, 0), (0, 1)] {
            if x + dx < image.width() && y + dy < image.height() {
                *image.get_mut(x + dx, y + dy) = c;
            }
        }
    }
}

/// Two viewpoints that overlook the map: above opposite corners of the trajectory's box,
/// pulled back by half the map's size, looking at the map's centre.
pub fn overview_poses(map: &PanopticMap, poses: &[Pose]) -> Vec<Pose> {
    let (up, sign) = up_axis(poses);
    let mut up_vector = Vector3::zeros();
    up_vector[up] = sign;
    let points: Vec<Point3<f64>> = map.surface_voxels().map(|v| v.position).collect();
    if points.is_empty() {
        return Vec::new();
    }
    let centre =
        Point3::from(points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / points.len() as f64);
    let size = points
        .iter()
        .map(|p| (p - centre).norm())
        .fold(0.0, f64::max)
        .max(1.0);
    let cameras: Vec<Point3<f64>> = if poses.is_empty() {
        vec![centre]
    } else {
        poses
            .iter()
            .map(|p| Point3::from(p.translation.vector))
            .collect()
    };
    // The horizontal direction in which the trajectory spreads most.
    let spread = cameras
        .iter()
        .map(|c| {
            let d = c - centre;
            d - up_vector * d.dot(&up_vector)
        })
        .max_by(|x, y| x.norm().total_cmp(&y.norm()))
        .filter(|d| d.norm() > 1e-6)
        .map(|d| d.normalize())
        .unwrap_or_else(|| {
            let any = if up == 0 { Vector3::y() } else { Vector3::x() };
            (any - up_vector * any.dot(&up_vector)).normalize()
        });
    [1.0, -1.0]
        .into_iter()
        .map(|side| {
            let eye = centre + spread * (side * 0.6 * size) + up_vector * (0.8 * size);
            // Camera z looks at the centre, y points down in the image.
            Isometry3::face_towards(&eye, &centre, &-up_vector)
        })
        .collect()
}

/// A camera for overview pictures: 640×480, 70° horizontal field of view.
pub fn overview_camera() -> Intrinsics {
    let f = 320.0 / (35f64.to_radians()).tan();
    Intrinsics {
        width: 640,
        height: 480,
        fx: f,
        fy: f,
        cx: 319.5,
        cy: 239.5,
    }
}

/// The map ray cast from `pose`, shaded by the surface's facing, on white.
pub fn perspective(map: &PanopticMap, pose: &Pose, paint: Paint) -> ColorImage {
    let k = overview_camera();
    let view = map.render(&k, pose);
    let light = pose.rotation * Vector3::new(0.3, -0.5, -1.0).normalize();
    Image::from_fn(k.width, k.height, |x, y| {
        let depth = *view.depth.get(x, y);
        if !(depth.is_finite() && depth > 0.0) {
            return [255; 3];
        }
        let n = view.normals.get(x, y);
        let n = Vector3::new(n[0] as f64, n[1] as f64, n[2] as f64);
        let shade = 0.45 + 0.55 * n.dot(&light).abs();
        let c = paint.color(map, *view.color.get(x, y), *view.instances.get(x, y));
        c.map(|c| (c as f64 * shade).min(255.0) as u8)
    })
}
