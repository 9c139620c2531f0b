use voxpan_core::nalgebra::{Point3, Vector3};

use crate::{Rand, Shape};

/// How an object's colour varies over its surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Surface {
    Plain,
    /// Squares of `size` metres alternating with `other` (floors).
    Checker {
        size: f64,
        other: [u8; 3],
    },
    /// Vertical stripes of `period` metres (walls).
    Stripes {
        period: f64,
        other: [u8; 3],
    },
}

/// One instance: a few primitives sharing an id, a class and an appearance.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub instance_id: u16,
    pub class_id: u32,
    pub is_thing: bool,
    pub color: [u8; 3],
    pub surface: Surface,
    /// Shiny: a structured-light sensor often returns no depth there.
    pub specular: bool,
    pub shapes: Vec<Shape>,
}

/// A ray's first hit in the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneHit {
    pub t: f64,
    pub normal: Vector3<f64>,
    /// Index into [`Scene::objects`].
    pub object: usize,
}

/// Class table of the synthetic world: `(class_id, name, is_thing)`.
pub const CLASSES: [(u32, &str, bool); 11] = [
    (0, "floor", false),
    (1, "wall", false),
    (2, "ceiling", false),
    (3, "table", true),
    (4, "chair", true),
    (5, "shelf", true),
    (6, "sofa", true),
    (7, "lamp", true),
    (8, "cup", true),
    (9, "ball", true),
    (10, "box", true),
];

/// The room and everything in it.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub objects: Vec<Object>,
    /// Room extent: x in `[0, size.x]`, y in `[0, size.y]`, z in `[0, size.z]` (z up).
    pub size: Vector3<f64>,
    /// Unit direction towards the light.
    pub light: Vector3<f64>,
    bounds: Vec<(Point3<f64>, f64)>,
}

impl Scene {
    /// An empty scene (tests build analytic scenes with [`Scene::add`]).
    pub fn empty(size: Vector3<f64>) -> Self {
        Self {
            objects: Vec::new(),
            size,
            light: Vector3::new(0.3, 0.5, 1.0).normalize(),
            bounds: Vec::new(),
        }
    }

    pub fn add(&mut self, object: Object) {
        // A sphere around all of the object's shapes.
        let spheres: Vec<_> = object.shapes.iter().map(Shape::bounding_sphere).collect();
        let n = spheres.len().max(1) as f64;
        let center = Point3::from(spheres.iter().map(|(c, _)| c.coords).sum::<Vector3<f64>>() / n);
        let radius = spheres
            .iter()
            .map(|(c, r)| (c - center).norm() + r)
            .fold(0.0, f64::max);
        self.bounds.push((center, radius));
        self.objects.push(object);
    }

    /// The first surface along `origin + t·dir`, `t > 0`.
    pub fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>) -> Option<SceneHit> {
        let dir_len_sq = dir.norm_squared();
        let mut best: Option<SceneHit> = None;
        for (i, (object, (center, radius))) in self.objects.iter().zip(&self.bounds).enumerate() {
            // Cull by bounding sphere (unless the origin is inside it).
            let oc = center - origin;
            let along = oc.dot(dir) / dir_len_sq;
            let closest = oc - dir * along.max(0.0);
            if oc.norm_squared() > radius * radius
                && (along < 0.0 || closest.norm_squared() > radius * radius)
            {
                continue;
            }
            for shape in &object.shapes {
                if let Some(hit) = shape.intersect(origin, dir, 1e-9) {
                    if best.is_none_or(|b| hit.t < b.t) {
                        best = Some(SceneHit {
                            t: hit.t,
                            normal: hit.normal,
                            object: i,
                        });
                    }
                }
            }
        }
        best
    }

    /// The shaded colour of object `index` at `point` with normal `normal`.
    pub fn shade(&self, index: usize, point: &Point3<f64>, normal: &Vector3<f64>) -> [u8; 3] {
        let object = &self.objects[index];
        let base = match object.surface {
            Surface::Plain => object.color,
            Surface::Checker { size, other } => {
                let parity = ((point.x / size).floor() + (point.y / size).floor()) as i64;
                if parity.rem_euclid(2) == 0 {
                    object.color
                } else {
                    other
                }
            }
            Surface::Stripes { period, other } => {
                let u = (point.x + point.y) / period;
                if u.rem_euclid(1.0) < 0.5 {
                    object.color
                } else {
                    other
                }
            }
        };
        // Ambient plus two-sided Lambert: enough shading for texture-less boxes to show edges.
        let factor = 0.45 + 0.55 * normal.dot(&self.light).abs();
        base.map(|c| (c as f64 * factor).round().clamp(0.0, 255.0) as u8)
    }

    /// A furnished room, different for every seed.
    pub fn generate(seed: u64) -> Self {
        let mut rng = Rand::stream(seed, u64::MAX);
        let size = Vector3::new(rng.range(6.0, 8.0), rng.range(5.0, 6.5), 2.7);
        let mut scene = Scene::empty(size);
        let slab = |center: Point3<f64>, half: Vector3<f64>| Shape::Cuboid {
            center,
            half,
            yaw: 0.0,
        };
        let (w, d, h) = (size.x, size.y, size.z);
        scene.add(Object {
            instance_id: 1,
            class_id: 0,
            is_thing: false,
            color: [150, 120, 90],
            surface: Surface::Checker {
                size: 0.5,
                other: [120, 95, 70],
            },
            specular: false,
            shapes: vec![slab(
                Point3::new(w / 2.0, d / 2.0, -0.05),
                Vector3::new(w / 2.0, d / 2.0, 0.05),
            )],
        });
        scene.add(Object {
            instance_id: 2,
            class_id: 2,
            is_thing: false,
            color: [235, 235, 230],
            surface: Surface::Plain,
            specular: false,
            shapes: vec![slab(
                Point3::new(w / 2.0, d / 2.0, h + 0.05),
                Vector3::new(w / 2.0, d / 2.0, 0.05),
            )],
        });
        scene.add(Object {
            instance_id: 3,
            class_id: 1,
            is_thing: false,
            color: [200, 190, 170],
            surface: Surface::Stripes {
                period: 0.8,
                other: [185, 175, 160],
            },
            specular: false,
            shapes: vec![
                slab(
                    Point3::new(-0.05, d / 2.0, h / 2.0),
                    Vector3::new(0.05, d / 2.0 + 0.1, h / 2.0),
                ),
                slab(
                    Point3::new(w + 0.05, d / 2.0, h / 2.0),
                    Vector3::new(0.05, d / 2.0 + 0.1, h / 2.0),
                ),
                slab(
                    Point3::new(w / 2.0, -0.05, h / 2.0),
                    Vector3::new(w / 2.0 + 0.1, 0.05, h / 2.0),
                ),
                slab(
                    Point3::new(w / 2.0, d + 0.05, h / 2.0),
                    Vector3::new(w / 2.0 + 0.1, 0.05, h / 2.0),
                ),
            ],
        });
        crate::scene::furnish(&mut scene, &mut rng);
        scene
    }

    /// `(class_id, name, is_thing)` of every class.
    pub fn classes() -> &'static [(u32, &'static str, bool)] {
        &CLASSES
    }
}

/// Places furniture in a ring along the walls, leaving the middle free for the camera.
fn furnish(scene: &mut Scene, rng: &mut Rand) {
    let size = scene.size;
    let center = Vector3::new(size.x / 2.0, size.y / 2.0, 0.0);
    let mut footprints: Vec<(f64, f64, f64)> = Vec::new();
    let mut next_id = 10u16;
    let kinds = [3u32, 3, 4, 4, 4, 4, 5, 6, 7, 7];
    for &kind in &kinds {
        let radius = match kind {
            3 => 0.75,
            4 => 0.35,
            5 => 0.55,
            6 => 1.0,
            _ => 0.25,
        };
        // Rejection sampling: inside the room, outside the camera's central zone, not
        // overlapping earlier furniture.
        let spot = (0..200).find_map(|_| {
            let x = rng.range(radius + 0.05, size.x - radius - 0.05);
            let y = rng.range(radius + 0.05, size.y - radius - 0.05);
            let ex = (x - center.x) / (size.x / 2.0 - 1.3);
            let ey = (y - center.y) / (size.y / 2.0 - 1.3);
            let free = footprints
                .iter()
                .all(|&(fx, fy, fr)| (fx - x).hypot(fy - y) > fr + radius + 0.1);
            (ex * ex + ey * ey > 1.0 && free).then_some((x, y))
        });
        let Some((x, y)) = spot else { continue };
        footprints.push((x, y, radius));
        // Face the room's centre.
        let yaw = (center.y - y).atan2(center.x - x) - std::f64::consts::FRAC_PI_2;
        let color = [
            rng.index(40, 220) as u8,
            rng.index(40, 220) as u8,
            rng.index(40, 220) as u8,
        ];
        let mut object = Object {
            instance_id: next_id,
            class_id: kind,
            is_thing: true,
            color,
            surface: Surface::Plain,
            specular: false,
            shapes: furniture(kind, x, y, yaw),
        };
        if kind == 6 {
            // A dark sofa: dark surfaces lose depth on active sensors.
            object.color = [28, 28, 34];
        }
        next_id += 1;
        scene.add(object);
        if kind == 3 {
            // Small objects on the table top.
            for _ in 0..rng.index(1, 4) {
                let (lx, ly) = (rng.range(-0.45, 0.45), rng.range(-0.25, 0.25));
                let (s, c) = yaw.sin_cos();
                let (px, py) = (x + c * lx - s * ly, y + s * lx + c * ly);
                let small = rng.index(8, 11) as u32;
                let top = 0.75;
                let shape = match small {
                    8 => Shape::Cylinder {
                        base: Point3::new(px, py, top),
                        radius: 0.045,
                        height: 0.11,
                    },
                    9 => {
                        let r = rng.range(0.07, 0.12);
                        Shape::Sphere {
                            center: Point3::new(px, py, top + r),
                            radius: r,
                        }
                    }
                    _ => {
                        let half = Vector3::new(
                            rng.range(0.05, 0.1),
                            rng.range(0.05, 0.1),
                            rng.range(0.04, 0.1),
                        );
                        Shape::Cuboid {
                            center: Point3::new(px, py, top + half.z),
                            half,
                            yaw: rng.range(0.0, 3.0),
                        }
                    }
                };
                scene.add(Object {
                    instance_id: next_id,
                    class_id: small,
                    is_thing: true,
                    color: [
                        rng.index(60, 250) as u8,
                        rng.index(60, 250) as u8,
                        rng.index(60, 250) as u8,
                    ],
                    surface: Surface::Plain,
                    specular: small == 8,
                    shapes: vec![shape],
                });
                next_id += 1;
            }
        }
    }
}

/// The primitives of a piece of furniture at `(x, y)` turned by `yaw`.
fn furniture(kind: u32, x: f64, y: f64, yaw: f64) -> Vec<Shape> {
    let (s, c) = yaw.sin_cos();
    let at = |lx: f64, ly: f64, z: f64| Point3::new(x + c * lx - s * ly, y + s * lx + c * ly, z);
    let cuboid = |lx: f64, ly: f64, z: f64, hx: f64, hy: f64, hz: f64| Shape::Cuboid {
        center: at(lx, ly, z),
        half: Vector3::new(hx, hy, hz),
        yaw,
    };
    let leg = |lx: f64, ly: f64, r: f64, height: f64| Shape::Cylinder {
        base: at(lx, ly, 0.0),
        radius: r,
        height,
    };
    match kind {
        // table: top and four legs
        3 => vec![
            cuboid(0.0, 0.0, 0.73, 0.6, 0.35, 0.02),
            leg(0.52, 0.28, 0.03, 0.71),
            leg(-0.52, 0.28, 0.03, 0.71),
            leg(0.52, -0.28, 0.03, 0.71),
            leg(-0.52, -0.28, 0.03, 0.71),
        ],
        // chair: seat, back, legs
        4 => vec![
            cuboid(0.0, 0.0, 0.45, 0.22, 0.22, 0.02),
            cuboid(0.0, -0.2, 0.7, 0.22, 0.02, 0.23),
            leg(0.18, 0.18, 0.02, 0.43),
            leg(-0.18, 0.18, 0.02, 0.43),
            leg(0.18, -0.18, 0.02, 0.43),
            leg(-0.18, -0.18, 0.02, 0.43),
        ],
        // shelf: two sides and four boards
        5 => {
            let mut v = vec![
                cuboid(0.45, 0.0, 0.8, 0.02, 0.17, 0.8),
                cuboid(-0.45, 0.0, 0.8, 0.02, 0.17, 0.8),
            ];
            v.extend([0.02, 0.55, 1.05, 1.58].map(|z| cuboid(0.0, 0.0, z, 0.43, 0.17, 0.02)));
            v
        }
        // sofa: base, back, arms
        6 => vec![
            cuboid(0.0, 0.0, 0.22, 0.9, 0.4, 0.22),
            cuboid(0.0, -0.32, 0.65, 0.9, 0.08, 0.22),
            cuboid(0.82, 0.0, 0.55, 0.08, 0.4, 0.1),
            cuboid(-0.82, 0.0, 0.55, 0.08, 0.4, 0.1),
        ],
        // lamp: pole and shade
        _ => vec![
            leg(0.0, 0.0, 0.02, 1.5),
            Shape::Sphere {
                center: at(0.0, 0.0, 1.62),
                radius: 0.17,
            },
        ],
    }
}
