//! Which frames the segmenter runs on. A network is the whole cost of perception, and the map
//! already holds most of what the next frame will see: between keyframes a frame's masks come
//! from the map (rendered at its pose, refined on its own depth) instead.

use std::num::NonZeroU32;

use voxpan_core::nalgebra::Point3;
use voxpan_core::{Frame, Intrinsics, Pose, is_valid_depth};

/// When the segmenter runs (`[segment] every`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Keyframes {
    /// On the first frame and every `n`th after it (1: every frame, the default).
    Every(NonZeroU32),
    /// When the camera has moved on: less than nine tenths of what the frame sees lies in the
    /// last keyframe's view (the frame's depth, projected into the keyframe's camera). How the
    /// share was chosen: docs/network.md.
    Auto,
}

impl Default for Keyframes {
    fn default() -> Self {
        Self::Every(NonZeroU32::MIN)
    }
}

impl std::fmt::Display for Keyframes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Every(n) => write!(f, "{n}"),
            Self::Auto => f.write_str("auto"),
        }
    }
}

impl std::str::FromStr for Keyframes {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "auto" {
            return Ok(Self::Auto);
        }
        s.parse::<NonZeroU32>().map(Self::Every).map_err(|_| {
            format!("{s:?}: expected a whole number of frames, 1 or more, or \"auto\"")
        })
    }
}

impl serde::Serialize for Keyframes {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Every(n) => serializer.serialize_u32(n.get()),
            Self::Auto => serializer.serialize_str("auto"),
        }
    }
}

impl<'de> serde::Deserialize<'de> for Keyframes {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Written {
            Count(i64),
            Word(String),
        }
        match Written::deserialize(deserializer)? {
            Written::Count(n) => u32::try_from(n)
                .ok()
                .and_then(NonZeroU32::new)
                .map(Self::Every)
                .ok_or_else(|| {
                    serde::de::Error::custom(format!(
                        "every = {n}: expected a whole number of frames, 1 or more, or \"auto\""
                    ))
                }),
            Written::Word(word) => word.parse().map_err(serde::de::Error::custom),
        }
    }
}

/// Decides, frame by frame, whether a frame is a keyframe.
#[derive(Clone, Debug)]
pub(crate) struct KeyframeScheduler {
    schedule: Keyframes,
    /// The last keyframe's camera and the frames since it (`None` before the first).
    last: Option<LastKeyframe>,
}

#[derive(Clone, Debug)]
struct LastKeyframe {
    pose: Pose,
    intrinsics: Intrinsics,
    since: u32,
}

/// The share of a frame's view the last keyframe must still see for [`Keyframes::Auto`] to
/// carry the map's masks instead of segmenting.
const AUTO_SHARED: f64 = 0.9;

/// Pixels apart of the depth samples [`Keyframes::Auto`] projects (a 640x480 frame gives
/// 4,800: the share they see is within about a point of the full image's).
const AUTO_STRIDE: usize = 8;

impl KeyframeScheduler {
    pub(crate) fn new(schedule: Keyframes) -> Self {
        Self {
            schedule,
            last: None,
        }
    }

    /// Counts a frame that passes while the segmenter is busy (it cannot be a keyframe).
    pub(crate) fn pass(&mut self) {
        if let Some(last) = &mut self.last {
            last.since = last.since.saturating_add(1);
        }
    }

    /// Whether the segmenter runs on `frame` (the frames come in order).
    pub(crate) fn is_keyframe(&mut self, frame: &Frame) -> bool {
        let keyframe = match (self.schedule, &self.last) {
            (_, None) => true,
            (Keyframes::Every(n), Some(last)) => last.since + 1 >= n.get(),
            (Keyframes::Auto, Some(last)) => shared_view(frame, &last.pose, &last.intrinsics)
                .is_some_and(|share| share < AUTO_SHARED),
        };
        if keyframe {
            self.last = Some(LastKeyframe {
                pose: frame.pose,
                intrinsics: frame.intrinsics,
                since: 0,
            });
        } else {
            self.pass();
        }
        keyframe
    }
}

/// The share of `frame`'s valid depth samples that project into the image of a camera with
/// intrinsics `k` at `pose`; `None` when the frame has no valid depth.
pub fn shared_view(frame: &Frame, pose: &Pose, k: &Intrinsics) -> Option<f64> {
    let own = &frame.intrinsics;
    let to_other = pose.inverse() * frame.pose;
    let (width, height) = frame.depth.dims();
    let (mut seen, mut shared) = (0usize, 0usize);
    for v in (AUTO_STRIDE / 2..height).step_by(AUTO_STRIDE) {
        for u in (AUTO_STRIDE / 2..width).step_by(AUTO_STRIDE) {
            let z = *frame.depth.get(u, v);
            if !is_valid_depth(z) {
                continue;
            }
            let p = Point3::from(own.ray(u as f64, v as f64) * z as f64);
            seen += 1;
            if let Some((x, y)) = k.project(&(to_other * p))
                && x >= 0.0
                && y >= 0.0
                && x < k.width as f64
                && y < k.height as f64
            {
                shared += 1;
            }
        }
    }
    (seen > 0).then(|| shared as f64 / seen as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxpan_core::Image;
    use voxpan_core::nalgebra::{UnitQuaternion, Vector3};

    fn frame_at(pose: Pose) -> Frame {
        let k = Intrinsics {
            width: 320,
            height: 240,
            fx: 200.0,
            fy: 200.0,
            cx: 160.0,
            cy: 120.0,
        };
        Frame {
            id: "f".into(),
            timestamp: 0.0,
            color: Image::filled(320, 240, [0, 0, 0]),
            depth: Image::filled(320, 240, 2.0),
            pose,
            intrinsics: k,
            segments: None,
            ground_truth: None,
        }
    }

    fn turned(degrees: f64) -> Pose {
        Pose::from_parts(
            Vector3::zeros().into(),
            UnitQuaternion::from_euler_angles(0.0, degrees.to_radians(), 0.0),
        )
    }

    #[test]
    fn every_n_segments_the_first_frame_and_every_nth_after_it() {
        let every = |n: u32, frames: usize| {
            let mut s = KeyframeScheduler::new(Keyframes::Every(NonZeroU32::new(n).unwrap()));
            let f = frame_at(Pose::identity());
            (0..frames).map(|_| s.is_keyframe(&f)).collect::<Vec<_>>()
        };
        assert!(every(1, 5).iter().all(|&k| k));
        assert_eq!(every(3, 7), [true, false, false, true, false, false, true]);
    }

    /// A camera turning on the spot: the share of the view it still has in common with the
    /// keyframe falls as it turns, and a keyframe follows once it is under nine tenths.
    #[test]
    fn auto_segments_where_the_camera_has_turned_away_from_the_last_keyframe() {
        let still = frame_at(Pose::identity());
        let share = |deg: f64| shared_view(&frame_at(turned(deg)), &still.pose, &still.intrinsics);
        assert_eq!(share(0.0), Some(1.0));
        // Horizontal field of view 2·atan(160/200) = 77°: half of it shared at about 38°.
        assert!(share(20.0).unwrap() > 0.5);
        assert!(share(60.0).unwrap() < 0.5);
        assert_eq!(share(120.0), Some(0.0));

        // A tenth of the 77° view is new after about 8°.
        assert!(share(5.0).unwrap() > 0.9);
        assert!(share(12.0).unwrap() < 0.9);
        let mut s = KeyframeScheduler::new(Keyframes::Auto);
        let keyframes: Vec<usize> = (0..=90)
            .step_by(2)
            .filter(|&deg| s.is_keyframe(&frame_at(turned(deg as f64))))
            .collect();
        // The first frame, then one each time the camera has turned a tenth of a view on.
        assert_eq!(keyframes[0], 0);
        assert!(keyframes.len() >= 8, "{keyframes:?}");
        for pair in keyframes.windows(2) {
            let step = pair[1] - pair[0];
            assert!((6..=12).contains(&step), "{keyframes:?}");
        }
        // A camera that keeps still is segmented once.
        let mut s = KeyframeScheduler::new(Keyframes::Auto);
        let still_keyframes = (0..20).filter(|_| s.is_keyframe(&still)).count();
        assert_eq!(still_keyframes, 1);
    }

    #[test]
    fn the_schedule_reads_and_writes_as_a_count_or_auto() {
        for (text, expected) in [
            ("1", Keyframes::default()),
            ("5", Keyframes::Every(NonZeroU32::new(5).unwrap())),
            ("auto", Keyframes::Auto),
        ] {
            let parsed: Keyframes = text.parse().unwrap();
            assert_eq!(parsed, expected);
            assert_eq!(parsed.to_string(), text);
        }
        for bad in ["0", "-2", "often", ""] {
            let error = bad.parse::<Keyframes>().unwrap_err();
            assert!(error.contains("auto"), "{error}");
        }
    }
}
