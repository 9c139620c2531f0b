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
    /// Index into that object's shapes.
    pub shape: usize,
}

/// Class table of the synthetic world: `(class_id, name, is_thing)`. Classes 11-14 are
/// only in the flat world ([`Scene::flat`]), or in masks ([`MaskErrors`](crate::MaskErrors)'
/// flicker: `table-merged` is how a network names a table when it takes it for stuff).
pub const CLASSES: [(u32, &str, bool); 15] = [
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
    (11, "books", true),
    (12, "rug", false),
    (13, "door", false),
    (14, "table-merged", false),
];

/// Classes whose objects are groups of separate items (books along a shelf board): one
/// object of the ground truth, which a network may segment item by item.
const GROUP_CLASSES: [u32; 1] = [11];

/// A room's floor plan: `[x, y]` from `min` to `max`, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Room {
    pub min: [f64; 2],
    pub max: [f64; 2],
}

impl Room {
    pub fn center(&self) -> [f64; 2] {
        [
            (self.min[0] + self.max[0]) / 2.0,
            (self.min[1] + self.max[1]) / 2.0,
        ]
    }

    pub fn half_size(&self) -> [f64; 2] {
        [
            (self.max[0] - self.min[0]) / 2.0,
            (self.max[1] - self.min[1]) / 2.0,
        ]
    }
}

/// The room and everything in it.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub objects: Vec<Object>,
    /// Extent: x in `[0, size.x]`, y in `[0, size.y]`, z in `[0, size.z]` (z up).
    pub size: Vector3<f64>,
    /// The rooms, west to east (one for [`Scene::generate`]'s world).
    pub rooms: Vec<Room>,
    /// The doorway between room `i` and room `i + 1`: the middle of its opening.
    pub doorways: Vec<Point3<f64>>,
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
            rooms: vec![Room {
                min: [0.0, 0.0],
                max: [size.x, size.y],
            }],
            doorways: Vec::new(),
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
            for (k, shape) in object.shapes.iter().enumerate() {
                if let Some(hit) = shape.intersect(origin, dir, 1e-9)
                    && best.is_none_or(|b| hit.t < b.t)
                {
                    best = Some(SceneHit {
                        t: hit.t,
                        normal: hit.normal,
                        object: i,
                        shape: k,
                    });
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
        let room = scene.rooms[0];
        furnish(&mut scene, &mut rng, &room, &[], &mut 10, false);
        scene
    }

    /// A flat of three rooms in a row, joined by doorways, different for every seed: one
    /// floor, one ceiling and one set of walls (as the flat dataset's ground truth has them),
    /// and in every room a rug (stuff), furniture, shelves with rows of books; an open door
    /// (stuff) beside each doorway. Rugs and doors are one object each: the same stuff class
    /// in several rooms, metres apart.
    pub fn flat(seed: u64) -> Self {
        let mut rng = Rand::stream(seed, u64::MAX - 1);
        let (wall, door_width, door_height, h) = (0.1, 1.0, 2.1, 2.7);
        let depth = rng.range(4.4, 5.4);
        let mut rooms = Vec::new();
        let mut x = 0.0;
        for _ in 0..3 {
            let width = rng.range(4.0, 5.0);
            rooms.push(Room {
                min: [x, 0.0],
                max: [x + width, depth],
            });
            x += width + wall;
        }
        let size = Vector3::new(x - wall, depth, h);
        let mut scene = Scene::empty(size);
        scene.rooms = rooms.clone();
        let slab = |center: Point3<f64>, half: Vector3<f64>| Shape::Cuboid {
            center,
            half,
            yaw: 0.0,
        };
        let (w, d) = (size.x, size.y);
        let stuff = |id: u16, class: u32, color: [u8; 3], surface: Surface, shapes| Object {
            instance_id: id,
            class_id: class,
            is_thing: false,
            color,
            surface,
            specular: false,
            shapes,
        };
        scene.add(stuff(
            1,
            0,
            [150, 120, 90],
            Surface::Checker {
                size: 0.5,
                other: [120, 95, 70],
            },
            vec![slab(
                Point3::new(w / 2.0, d / 2.0, -0.05),
                Vector3::new(w / 2.0, d / 2.0, 0.05),
            )],
        ));
        scene.add(stuff(
            2,
            2,
            [235, 235, 230],
            Surface::Plain,
            vec![slab(
                Point3::new(w / 2.0, d / 2.0, h + 0.05),
                Vector3::new(w / 2.0, d / 2.0, 0.05),
            )],
        ));
        let mut walls = vec![
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
        ];
        // Interior walls, each with a doorway: the wall either side of it and a lintel.
        for pair in rooms.windows(2) {
            let x = pair[0].max[0] + wall / 2.0;
            let y = rng.range(1.2, d - 1.2);
            let (south, north) = (y - door_width / 2.0, y + door_width / 2.0);
            walls.push(slab(
                Point3::new(x, south / 2.0, h / 2.0),
                Vector3::new(wall / 2.0, south / 2.0, h / 2.0),
            ));
            walls.push(slab(
                Point3::new(x, (north + d) / 2.0, h / 2.0),
                Vector3::new(wall / 2.0, (d - north) / 2.0, h / 2.0),
            ));
            walls.push(slab(
                Point3::new(x, y, (door_height + h) / 2.0),
                Vector3::new(wall / 2.0, door_width / 2.0, (h - door_height) / 2.0),
            ));
            scene.doorways.push(Point3::new(x, y, door_height / 2.0));
        }
        scene.add(stuff(
            3,
            1,
            [200, 190, 170],
            Surface::Stripes {
                period: 0.8,
                other: [185, 175, 160],
            },
            walls,
        ));
        let mut next_id = 4u16;
        // A rug in the middle of every room, under the camera's loop.
        for room in &rooms {
            let [cx, cy] = room.center();
            let color = [
                rng.index(60, 200) as u8,
                rng.index(40, 160) as u8,
                rng.index(40, 160) as u8,
            ];
            let rug = slab(
                Point3::new(cx + rng.range(-0.3, 0.3), cy + rng.range(-0.3, 0.3), 0.005),
                Vector3::new(rng.range(0.8, 1.2), rng.range(0.6, 0.9), 0.005),
            );
            let other = color.map(|c| c.saturating_sub(40));
            let surface = Surface::Checker { size: 0.2, other };
            scene.add(stuff(next_id, 12, color, surface, vec![rug]));
            next_id += 1;
        }
        // An open door leaf beside each doorway, on the eastern room's side, against the
        // doorway's northern edge.
        for doorway in scene.doorways.clone() {
            let leaf = slab(
                Point3::new(
                    doorway.x + wall / 2.0 + 0.45,
                    doorway.y + door_width / 2.0 + 0.03,
                    1.0,
                ),
                Vector3::new(0.45, 0.02, 1.0),
            );
            let surface = Surface::Stripes {
                period: 0.3,
                other: [150, 110, 70],
            };
            scene.add(stuff(next_id, 13, [170, 125, 80], surface, vec![leaf]));
            next_id += 1;
        }
        next_id = next_id.max(10);
        let ways = crate::trajectory::tour_segments(&scene);
        for room in &rooms {
            furnish(&mut scene, &mut rng, room, &ways, &mut next_id, true);
        }
        scene
    }

    /// `(class_id, name, is_thing)` of every class.
    pub fn classes() -> &'static [(u32, &'static str, bool)] {
        &CLASSES
    }

    /// Whether objects of `class` are groups of items a network may segment one by one.
    pub fn is_group(class: u32) -> bool {
        GROUP_CLASSES.contains(&class)
    }
}

/// Places furniture in a ring along `room`'s walls, leaving the middle free for the camera and
/// away from the segments of `keep_clear` (the camera's way through doorways). Instance ids
/// start at `next_id`. With `books`, shelves carry rows of books (one object per board).
fn furnish(
    scene: &mut Scene,
    rng: &mut Rand,
    room: &Room,
    keep_clear: &[([f64; 2], [f64; 2])],
    next_id: &mut u16,
    books: bool,
) {
    let [cx, cy] = room.center();
    let [hx, hy] = room.half_size();
    let mut footprints: Vec<(f64, f64, f64)> = Vec::new();
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
            let x = rng.range(room.min[0] + radius + 0.05, room.max[0] - radius - 0.05);
            let y = rng.range(room.min[1] + radius + 0.05, room.max[1] - radius - 0.05);
            let ex = (x - cx) / (hx - 1.3);
            let ey = (y - cy) / (hy - 1.3);
            let free = footprints
                .iter()
                .all(|&(fx, fy, fr)| (fx - x).hypot(fy - y) > fr + radius + 0.1);
            let clear = keep_clear
                .iter()
                .all(|&(a, b)| distance_to_segment([x, y], a, b) > radius + 0.5);
            (ex * ex + ey * ey > 1.0 && free && clear).then_some((x, y))
        });
        let Some((x, y)) = spot else { continue };
        footprints.push((x, y, radius));
        // Face the room's centre.
        let yaw = (cy - y).atan2(cx - x) - std::f64::consts::FRAC_PI_2;
        let color = [
            rng.index(40, 220) as u8,
            rng.index(40, 220) as u8,
            rng.index(40, 220) as u8,
        ];
        let mut object = Object {
            instance_id: *next_id,
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
        *next_id += 1;
        scene.add(object);
        if kind == 5 && books {
            for board in [0.57, 1.07] {
                let shapes = book_row(rng, x, y, yaw, board);
                scene.add(Object {
                    instance_id: *next_id,
                    class_id: 11,
                    is_thing: true,
                    color: [
                        rng.index(60, 230) as u8,
                        rng.index(60, 230) as u8,
                        rng.index(60, 230) as u8,
                    ],
                    surface: Surface::Stripes {
                        period: 0.07,
                        other: [
                            rng.index(40, 200) as u8,
                            rng.index(40, 200) as u8,
                            rng.index(40, 200) as u8,
                        ],
                    },
                    specular: false,
                    shapes,
                });
                *next_id += 1;
            }
        }
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
                    instance_id: *next_id,
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
                *next_id += 1;
            }
        }
    }
}

/// A row of upright books standing on a shelf board whose top is at height `board` (the shelf
/// at `(x, y)` turned by `yaw`), side by side with small gaps.
fn book_row(rng: &mut Rand, x: f64, y: f64, yaw: f64, board: f64) -> Vec<Shape> {
    let (s, c) = yaw.sin_cos();
    let mut shapes = Vec::new();
    let mut lx = -0.38 + rng.range(0.0, 0.1);
    let end = 0.38 - rng.range(0.0, 0.2);
    while shapes.len() < 9 {
        let thickness = rng.range(0.012, 0.03);
        if lx + 2.0 * thickness > end {
            break;
        }
        let height = rng.range(0.07, 0.13);
        let depth = rng.range(0.08, 0.12);
        lx += thickness;
        let ly = 0.0;
        shapes.push(Shape::Cuboid {
            center: Point3::new(x + c * lx - s * ly, y + s * lx + c * ly, board + height),
            half: Vector3::new(thickness, depth, height),
            yaw,
        });
        lx += thickness + rng.range(0.002, 0.01);
    }
    shapes
}

/// Distance from `p` to the segment from `a` to `b` (plan view).
fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (ap[0] - t * ab[0]).hypot(ap[1] - t * ab[1])
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
