use voxpan_core::nalgebra::{Point3, Vector3};

/// A primitive solid.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A box with half extents `half`, turned by `yaw` about the vertical axis.
    Cuboid {
        center: Point3<f64>,
        half: Vector3<f64>,
        yaw: f64,
    },
    /// A vertical cylinder from `base.z` to `base.z + height`.
    Cylinder {
        base: Point3<f64>,
        radius: f64,
        height: f64,
    },
    Sphere {
        center: Point3<f64>,
        radius: f64,
    },
}

/// Where a ray meets a shape: the ray parameter and the outward unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub normal: Vector3<f64>,
}

impl Shape {
    /// The first intersection with `t > t_min` of the ray `origin + t·dir`.
    pub fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>, t_min: f64) -> Option<Hit> {
        match self {
            Shape::Sphere { center, radius } => {
                let oc = origin - center;
                let a = dir.dot(dir);
                let b = oc.dot(dir);
                let c = oc.dot(&oc) - radius * radius;
                let disc = b * b - a * c;
                if disc < 0.0 {
                    return None;
                }
                let sq = disc.sqrt();
                [(-b - sq) / a, (-b + sq) / a]
                    .into_iter()
                    .find(|&t| t > t_min)
                    .map(|t| Hit {
                        t,
                        normal: (origin + dir * t - center) / *radius,
                    })
            }
            Shape::Cuboid { center, half, yaw } => {
                let (s, c) = yaw.sin_cos();
                // Into the box's frame (rotate by -yaw about z).
                let to_local =
                    |v: Vector3<f64>| Vector3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z);
                let o = to_local(origin - center);
                let d = to_local(*dir);
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                let (mut n0, mut n1) = (Vector3::zeros(), Vector3::zeros());
                for axis in 0..3 {
                    if d[axis].abs() < 1e-15 {
                        if o[axis].abs() > half[axis] {
                            return None;
                        }
                        continue;
                    }
                    let mut ta = (-half[axis] - o[axis]) / d[axis];
                    let mut tb = (half[axis] - o[axis]) / d[axis];
                    let mut na = Vector3::zeros();
                    na[axis] = -1.0;
                    let mut nb = -na;
                    if ta > tb {
                        std::mem::swap(&mut ta, &mut tb);
                        std::mem::swap(&mut na, &mut nb);
                    }
                    if ta > t0 {
                        t0 = ta;
                        n0 = na;
                    }
                    if tb < t1 {
                        t1 = tb;
                        n1 = nb;
                    }
                    if t0 > t1 {
                        return None;
                    }
                }
                let to_world =
                    |v: Vector3<f64>| Vector3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z);
                if t0 > t_min {
                    Some(Hit {
                        t: t0,
                        normal: to_world(n0),
                    })
                } else if t1 > t_min {
                    // Inside the box (the room's walls are seen from inside).
                    Some(Hit {
                        t: t1,
                        normal: -to_world(n1),
                    })
                } else {
                    None
                }
            }
            Shape::Cylinder {
                base,
                radius,
                height,
            } => {
                let mut best: Option<Hit> = None;
                let mut consider = |t: f64, normal: Vector3<f64>| {
                    if t > t_min && best.is_none_or(|b| t < b.t) {
                        best = Some(Hit { t, normal });
                    }
                };
                let o = origin - base;
                // Side: (o + t d)_xy on the circle, z within the height.
                let a = dir.x * dir.x + dir.y * dir.y;
                if a > 1e-15 {
                    let b = o.x * dir.x + o.y * dir.y;
                    let c = o.x * o.x + o.y * o.y - radius * radius;
                    let disc = b * b - a * c;
                    if disc >= 0.0 {
                        let sq = disc.sqrt();
                        for t in [(-b - sq) / a, (-b + sq) / a] {
                            let p = o + dir * t;
                            if (0.0..=*height).contains(&p.z) {
                                consider(t, Vector3::new(p.x, p.y, 0.0) / *radius);
                            }
                        }
                    }
                }
                // Caps.
                if dir.z.abs() > 1e-15 {
                    for (z, nz) in [(0.0, -1.0), (*height, 1.0)] {
                        let t = (z - o.z) / dir.z;
                        let p = o + dir * t;
                        if p.x * p.x + p.y * p.y <= radius * radius {
                            consider(t, Vector3::new(0.0, 0.0, nz));
                        }
                    }
                }
                best
            }
        }
    }

    /// A sphere containing the shape, for culling.
    pub fn bounding_sphere(&self) -> (Point3<f64>, f64) {
        match self {
            Shape::Sphere { center, radius } => (*center, *radius),
            Shape::Cuboid { center, half, .. } => (*center, half.norm()),
            Shape::Cylinder {
                base,
                radius,
                height,
            } => (
                base + Vector3::new(0.0, 0.0, height / 2.0),
                (radius * radius + height * height / 4.0).sqrt(),
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_from_outside_and_inside() {
        let b = Shape::Cuboid {
            center: Point3::new(0.0, 0.0, 5.0),
            half: Vector3::new(1.0, 1.0, 1.0),
            yaw: 0.3,
        };
        let hit = b.intersect(&Point3::origin(), &Vector3::z(), 0.0).unwrap();
        assert!((hit.t - 4.0).abs() < 1e-12 && (hit.normal.z + 1.0).abs() < 1e-12);
        let hit = b
            .intersect(&Point3::new(0.0, 0.0, 5.0), &Vector3::z(), 0.0)
            .unwrap();
        assert!((hit.t - 1.0).abs() < 1e-12 && (hit.normal.z + 1.0).abs() < 1e-12);
    }

    #[test]
    fn cylinder_side_and_cap() {
        let c = Shape::Cylinder {
            base: Point3::new(3.0, 0.0, 0.0),
            radius: 0.5,
            height: 2.0,
        };
        let side = c
            .intersect(&Point3::new(0.0, 0.0, 1.0), &Vector3::x(), 0.0)
            .unwrap();
        assert!((side.t - 2.5).abs() < 1e-12 && (side.normal.x + 1.0).abs() < 1e-12);
        let cap = c
            .intersect(&Point3::new(3.0, 0.0, 5.0), &-Vector3::z(), 0.0)
            .unwrap();
        assert!((cap.t - 3.0).abs() < 1e-12 && (cap.normal.z - 1.0).abs() < 1e-12);
    }

    #[test]
    fn sphere_hit_and_miss() {
        let s = Shape::Sphere {
            center: Point3::new(0.0, 0.0, 4.0),
            radius: 1.0,
        };
        assert!(
            (s.intersect(&Point3::origin(), &Vector3::z(), 0.0)
                .unwrap()
                .t
                - 3.0)
                .abs()
                < 1e-12
        );
        assert!(
            s.intersect(&Point3::new(2.0, 0.0, 0.0), &Vector3::z(), 0.0)
                .is_none()
        );
    }
}
