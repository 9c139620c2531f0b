use voxpan_core::Pose;
use voxpan_core::nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::Scene;
use crate::scene::Room;

/// A smooth loop through the free middle of the room, looking around like a mobile robot's
/// camera: an ellipse at 1.2-1.4 m height, the view sweeping between the walls. In a scene of
/// several rooms ([`Scene::flat`]), a tour: a loop and a half in each room, then through the
/// doorway into the next.
pub fn trajectory(scene: &Scene, frames: usize) -> Vec<Pose> {
    if scene.rooms.len() > 1 {
        return tour(scene, frames);
    }
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

/// Centre and radii of the ellipse the camera loops on in `room`: 1.8 m in from its walls.
fn loop_of(room: &Room) -> ([f64; 2], [f64; 2]) {
    let ([cx, cy], [hx, hy]) = (room.center(), room.half_size());
    ([cx, cy], [(hx - 1.8).max(0.3), (hy - 1.8).max(0.3)])
}

/// The angle of the point of `room`'s loop that faces `p`.
fn facing(room: &Room, p: [f64; 2]) -> f64 {
    let (c, r) = loop_of(room);
    ((p[1] - c[1]) / r[1]).atan2((p[0] - c[0]) / r[0])
}

fn on_loop(room: &Room, theta: f64) -> [f64; 2] {
    let (c, r) = loop_of(room);
    [c[0] + r[0] * theta.cos(), c[1] + r[1] * theta.sin()]
}

/// Where the tour enters and leaves each room's loop (angles), west to east: it starts on the
/// western side of the first room and ends where it entered the last.
fn loop_angles(scene: &Scene) -> Vec<(f64, f64)> {
    let n = scene.rooms.len();
    (0..n)
        .map(|i| {
            let room = &scene.rooms[i];
            let enter = if i == 0 {
                std::f64::consts::PI
            } else {
                let d = scene.doorways[i - 1];
                facing(room, [d.x, d.y])
            };
            let leave = if i + 1 < n {
                let d = scene.doorways[i];
                let extra = (facing(room, [d.x, d.y]) - enter).rem_euclid(std::f64::consts::TAU);
                enter + std::f64::consts::TAU + extra
            } else {
                enter + std::f64::consts::TAU
            };
            (enter, leave)
        })
        .collect()
}

/// The tour's ways through the doorways (plan view): from the loop to the doorway and on to
/// the next room's loop. Furniture keeps clear of them.
pub(crate) fn tour_segments(scene: &Scene) -> Vec<([f64; 2], [f64; 2])> {
    let angles = loop_angles(scene);
    let mut ways = Vec::new();
    for (i, d) in scene.doorways.iter().enumerate() {
        let door = [d.x, d.y];
        ways.push((on_loop(&scene.rooms[i], angles[i].1), door));
        ways.push((door, on_loop(&scene.rooms[i + 1], angles[i + 1].0)));
    }
    ways
}

/// A piece of the tour: a loop's arc, or a straight way.
enum Piece {
    Arc {
        room: usize,
        from: f64,
        to: f64,
    },
    Line {
        from: [f64; 2],
        to: [f64; 2],
        headings: (f64, f64),
    },
}

/// Where a loop looks at angle `theta`: outwards, sweeping ±60°, as in the one-room loop.
fn loop_heading(theta: f64) -> f64 {
    theta + 1.05 * (3.0 * theta).sin()
}

fn tour(scene: &Scene, frames: usize) -> Vec<Pose> {
    let angles = loop_angles(scene);
    let mut pieces = Vec::new();
    for (i, &(enter, leave)) in angles.iter().enumerate() {
        pieces.push(Piece::Arc {
            room: i,
            from: enter,
            to: leave,
        });
        if let Some(d) = scene.doorways.get(i) {
            let door = [d.x, d.y];
            let (from, next) = (
                on_loop(&scene.rooms[i], leave),
                on_loop(&scene.rooms[i + 1], angles[i + 1].0),
            );
            // The view turns from where the loop left off to where the next one starts.
            let (start, end) = (loop_heading(leave), loop_heading(angles[i + 1].0));
            let turn = (end - start + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            let middle = start + turn * 0.5;
            pieces.push(Piece::Line {
                from,
                to: door,
                headings: (start, middle),
            });
            pieces.push(Piece::Line {
                from: door,
                to: next,
                headings: (middle, start + turn),
            });
        }
    }
    let length = |p: &Piece| match p {
        Piece::Arc { room, from, to } => {
            let (_, r) = loop_of(&scene.rooms[*room]);
            (to - from) * (r[0] + r[1]) / 2.0
        }
        Piece::Line { from, to, .. } => (to[0] - from[0]).hypot(to[1] - from[1]),
    };
    let lengths: Vec<f64> = pieces.iter().map(length).collect();
    let total: f64 = lengths.iter().sum();
    (0..frames)
        .map(|i| {
            let mut s = total * i as f64 / frames.max(1) as f64;
            let mut k = 0;
            while k + 1 < pieces.len() && s >= lengths[k] {
                s -= lengths[k];
                k += 1;
            }
            let t = (s / lengths[k].max(1e-9)).clamp(0.0, 1.0);
            let (xy, z, heading) = match &pieces[k] {
                Piece::Arc { room, from, to } => {
                    let theta = from + (to - from) * t;
                    (
                        on_loop(&scene.rooms[*room], theta),
                        1.3 + 0.1 * (2.0 * theta).sin(),
                        loop_heading(theta),
                    )
                }
                Piece::Line { from, to, headings } => (
                    [
                        from[0] + (to[0] - from[0]) * t,
                        from[1] + (to[1] - from[1]) * t,
                    ],
                    1.3,
                    headings.0 + (headings.1 - headings.0) * t,
                ),
            };
            let forward = Vector3::new(heading.cos(), heading.sin(), -0.25).normalize();
            look_along(Point3::new(xy[0], xy[1], z), forward)
        })
        .collect()
}
