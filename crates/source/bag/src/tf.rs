//! Poses from a bag: time-stamped transforms (/tf, a pose topic) interpolated at an image's
//! stamp, and the chain of /tf and /tf_static edges from the world frame to the camera.

use std::collections::HashMap;

use voxpan_core::Pose;
use voxpan_core::nalgebra::{Quaternion, Translation3, UnitQuaternion};

use crate::fmt_time;
use crate::msgs::TransformMsg;

pub fn pose_of(t: &TransformMsg) -> Result<Pose, String> {
    let [x, y, z, w] = t.rotation;
    let raw = Quaternion::new(w, x, y, z);
    // Within 1 % of unit length is rounding; farther is no rotation (e.g. all zeros).
    if !(raw.norm() - 1.0).abs().lt(&0.01) || t.translation.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "transform {} -> {} is not rigid: rotation ({x} {y} {z} {w}), translation {:?}",
            t.header.frame_id, t.child_frame_id, t.translation
        ));
    }
    Ok(Pose::from_parts(
        Translation3::new(t.translation[0], t.translation[1], t.translation[2]),
        UnitQuaternion::from_quaternion(raw),
    ))
}

/// A transform over time, sorted by stamp.
#[derive(Default)]
pub struct Track {
    samples: Vec<(i64, Pose)>,
}

impl Track {
    /// Adds a sample in stamp order (after any sample with the same stamp); in-order samples,
    /// as live transforms arrive, append.
    pub fn push(&mut self, t: i64, pose: Pose) {
        let i = self.samples.partition_point(|(st, _)| *st <= t);
        self.samples.insert(i, (t, pose));
    }

    /// Drops samples that interpolation at `t` or later can no longer need (all but the last
    /// one before `t`): a live node's memory stays bounded.
    pub fn forget_before(&mut self, t: i64) {
        let i = self.samples.partition_point(|(st, _)| *st < t);
        if i > 1 {
            self.samples.drain(..i - 1);
        }
    }

    /// Keeps the `n` newest samples by stamp (a live stream's bound; a bag keeps all).
    pub fn keep_newest(&mut self, n: usize) {
        if self.samples.len() > n {
            self.samples.drain(..self.samples.len() - n);
        }
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The transform at `t`: a sample at exactly `t` as it is; between two samples at most
    /// `max_gap` apart, linear in translation and spherical in rotation; before the first or
    /// after the last sample only within `slack`, as that sample. The error says why not.
    pub fn at(&self, t: i64, max_gap: i64, slack: i64) -> Result<Pose, String> {
        let s = &self.samples;
        let i = s.partition_point(|(st, _)| *st < t);
        if let Some((st, p)) = s.get(i)
            && *st == t
        {
            return Ok(*p);
        }
        let (Some(a), Some(b)) = (i.checked_sub(1).and_then(|j| s.get(j)), s.get(i)) else {
            let (first, last) = match (s.first(), s.last()) {
                (Some(f), Some(l)) => (f, l),
                _ => return Err("no sample at all".into()),
            };
            if i == 0 && first.0 - t <= slack {
                return Ok(first.1);
            }
            if i == s.len() && t - last.0 <= slack {
                return Ok(last.1);
            }
            return Err(format!(
                "outside the samples ({} .. {} s)",
                fmt_time(first.0),
                fmt_time(last.0)
            ));
        };
        if b.0 - a.0 > max_gap {
            return Err(format!(
                "a gap of {:.3} s between samples at {} and {} s (more than {:.3} s)",
                (b.0 - a.0) as f64 / 1e9,
                fmt_time(a.0),
                fmt_time(b.0),
                max_gap as f64 / 1e9
            ));
        }
        let f = (t - a.0) as f64 / (b.0 - a.0) as f64;
        let ta = a.1.translation.vector;
        let tb = b.1.translation.vector;
        let rotation =
            a.1.rotation
                .try_slerp(&b.1.rotation, f, 1e-12)
                .ok_or_else(|| {
                    format!(
                        "rotations at {} and {} s are half a turn apart: no unique interpolation",
                        fmt_time(a.0),
                        fmt_time(b.0)
                    )
                })?;
        Ok(Pose::from_parts(
            Translation3::from(ta + (tb - ta) * f),
            rotation,
        ))
    }
}

enum Edge {
    Static(Pose),
    Dynamic(Track),
}

/// The /tf and /tf_static tree: each child frame has one parent.
#[derive(Default)]
pub struct TfTree {
    /// child -> (parent, transform parent <- child).
    edges: HashMap<String, (String, Edge)>,
    pub tf_topic: String,
}

/// Longest chain followed before assuming a cycle.
const MAX_DEPTH: usize = 256;

impl TfTree {
    /// Adds one transform; a child that changes parent is an error (tf allows one parent).
    pub fn add(&mut self, t: &TransformMsg, is_static: bool) -> Result<(), String> {
        let pose = pose_of(t)?;
        let (parent, child) = (&t.header.frame_id, &t.child_frame_id);
        let entry = self.edges.entry(child.clone()).or_insert_with(|| {
            let edge = if is_static {
                Edge::Static(pose)
            } else {
                Edge::Dynamic(Track::default())
            };
            (parent.clone(), edge)
        });
        if &entry.0 != parent {
            return Err(format!(
                "frame {child} has two parents, {} and {parent}",
                entry.0
            ));
        }
        match (&mut entry.1, is_static) {
            (Edge::Dynamic(track), false) => track.push(t.header.stamp_ns, pose),
            (Edge::Static(p), true) => *p = pose,
            (Edge::Static(_), false) => {
                return Err(format!("{parent} -> {child} is on both /tf_static and /tf"));
            }
            (Edge::Dynamic(_), true) => {
                return Err(format!("{parent} -> {child} is on both /tf and /tf_static"));
            }
        }
        Ok(())
    }

    pub fn new(tf_topic: &str) -> Self {
        Self {
            edges: HashMap::new(),
            tf_topic: tf_topic.to_owned(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    /// Whether `frame` has a parent.
    pub fn has_parent(&self, frame: &str) -> bool {
        self.edges.contains_key(frame)
    }

    /// How many frames have a parent.
    pub fn frames(&self) -> usize {
        self.edges.len()
    }

    /// Samples held over every moving edge.
    pub fn samples(&self) -> usize {
        self.edges
            .values()
            .map(|(_, e)| match e {
                Edge::Dynamic(track) => track.len(),
                Edge::Static(_) => 1,
            })
            .sum()
    }

    /// [`Track::keep_newest`] on every moving edge.
    pub fn keep_newest(&mut self, n: usize) {
        for (_, edge) in self.edges.values_mut() {
            if let Edge::Dynamic(track) = edge {
                track.keep_newest(n);
            }
        }
    }

    /// [`Track::forget_before`] on every moving edge.
    pub fn forget_before(&mut self, t: i64) {
        for (_, edge) in self.edges.values_mut() {
            if let Edge::Dynamic(track) = edge {
                track.forget_before(t);
            }
        }
    }

    /// `[frame, parent, grandparent, ..., root]`.
    fn ancestry(&self, frame: &str) -> Result<Vec<String>, String> {
        let mut out = vec![frame.to_owned()];
        while let Some((parent, _)) = self.edges.get(out.last().expect("non-empty")) {
            if out.len() > MAX_DEPTH || out.contains(parent) {
                return Err(format!("the frames above {frame} form a cycle"));
            }
            out.push(parent.clone());
        }
        Ok(out)
    }

    /// Whether a /tf (moving) edge lies between `frame` and its root. A live node that has
    /// only heard the latched /tf_static so far would otherwise take the top of the static
    /// chain for the world.
    pub fn moves(&self, frame: &str) -> Result<bool, String> {
        let chain = self.ancestry(frame)?;
        Ok(chain
            .iter()
            .any(|f| matches!(self.edges.get(f), Some((_, Edge::Dynamic(_))))))
    }

    /// The root of `frame`'s tree: the default world frame.
    pub fn root(&self, frame: &str) -> Result<String, String> {
        Ok(self.ancestry(frame)?.pop().expect("non-empty"))
    }

    /// `T_world_frame` at `t`.
    pub fn lookup(
        &self,
        world: &str,
        frame: &str,
        t: i64,
        max_gap: i64,
        slack: i64,
    ) -> Result<Pose, String> {
        let up_frame = self.ancestry(frame)?;
        let up_world = self.ancestry(world)?;
        let Some(common) = up_frame.iter().find(|f| up_world.contains(f)) else {
            return Err(format!(
                "{world} and {frame} are not connected by /tf and /tf_static ({world}'s root \
                 is {}, {frame}'s is {})",
                up_world.last().expect("non-empty"),
                up_frame.last().expect("non-empty")
            ));
        };
        let to_common = |chain: &[String]| -> Result<Pose, String> {
            let mut pose = Pose::identity();
            for child in chain.iter().take_while(|f| *f != common) {
                let (parent, edge) = &self.edges[child];
                let step = match edge {
                    Edge::Static(p) => *p,
                    Edge::Dynamic(track) => track.at(t, max_gap, slack).map_err(|e| {
                        format!(
                            "{} has no transform {parent} -> {child} at {} s: {e}",
                            self.tf_topic,
                            fmt_time(t)
                        )
                    })?,
                };
                pose = step * pose;
            }
            Ok(pose)
        };
        let common_frame = to_common(&up_frame)?;
        let common_world = to_common(&up_world)?;
        Ok(common_world.inverse() * common_frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::Header;

    fn tf(t: i64, parent: &str, child: &str, x: f64, yaw: f64) -> TransformMsg {
        let (s, c) = (yaw / 2.0).sin_cos();
        TransformMsg {
            header: Header {
                stamp_ns: t,
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            translation: [x, 0.0, 0.0],
            rotation: [0.0, 0.0, s, c],
        }
    }

    #[test]
    fn samples_stay_in_order_and_old_ones_are_forgotten() {
        let mut track = Track::default();
        for t in [30, 10, 20, 40] {
            track.push(t, Pose::translation(t as f64, 0.0, 0.0));
        }
        let x = |t| track.at(t, 100, 0).unwrap().translation.x;
        assert_eq!((x(10), x(15), x(35)), (10.0, 15.0, 35.0));
        track.forget_before(25);
        // The sample before 25 stays, so 25..=40 still interpolate; earlier times are gone.
        assert_eq!(track.len(), 3);
        assert_eq!(track.at(25, 100, 0).unwrap().translation.x, 25.0);
        assert!(track.at(15, 100, 0).is_err());
    }

    #[test]
    fn chain_interpolates_and_reports_gaps() {
        let mut tree = TfTree::new("/tf");
        tree.add(&tf(0, "world", "base", 0.0, 0.0), false).unwrap();
        tree.add(&tf(100, "world", "base", 1.0, 1.0), false)
            .unwrap();
        tree.add(&tf(1000, "world", "base", 2.0, 1.0), false)
            .unwrap();
        tree.add(&tf(0, "base", "cam", 0.5, 0.0), true).unwrap();
        assert_eq!(tree.root("cam").unwrap(), "world");
        let p = tree.lookup("world", "cam", 50, 200, 0).unwrap();
        let expected = Pose::from_parts(
            Translation3::new(0.5, 0.0, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5),
        ) * Pose::translation(0.5, 0.0, 0.0);
        assert!((p.to_homogeneous() - expected.to_homogeneous()).abs().max() < 1e-12);
        // Exactly at a sample: the sample itself.
        let at = tree.lookup("world", "base", 100, 200, 0).unwrap();
        assert_eq!(at, pose_of(&tf(100, "world", "base", 1.0, 1.0)).unwrap());
        let gap = tree.lookup("world", "cam", 500, 200, 0).unwrap_err();
        assert!(gap.contains("/tf has no transform world -> base"), "{gap}");
        assert!(gap.contains("gap of"), "{gap}");
        assert!(tree.lookup("world", "cam", 1001, 200, 0).is_err());
        assert!(tree.lookup("world", "cam", 1001, 200, 5).is_ok());
        assert!(
            tree.lookup("map", "cam", 50, 200, 0)
                .unwrap_err()
                .contains("not connected")
        );
        assert!(tree.add(&tf(5, "odom", "base", 0.0, 0.0), false).is_err());
    }
}
