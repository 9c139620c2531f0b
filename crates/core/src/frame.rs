use crate::{ColorImage, DepthImage, Intrinsics, LabelImage, Pose, Segment};

/// A segmentation of one frame: a label image (0 = void) and what each of its ids is.
#[derive(Clone, Debug, PartialEq)]
pub struct Segments {
    pub labels: LabelImage,
    /// One entry per id of `labels` that should be mapped; ids without an entry are left alone.
    pub segments: Vec<Segment>,
}

impl Segments {
    /// The entry for segment `id`, if listed.
    pub fn get(&self, id: u16) -> Option<&Segment> {
        self.segments.iter().find(|s| s.id == id)
    }
}

/// One RGB-D frame with its camera, and the annotations its source carries.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The source's name for the frame (flat: `000042`; TUM: the depth timestamp).
    pub id: String,
    /// Seconds.
    pub timestamp: f64,
    pub color: ColorImage,
    /// Planar depth in metres; 0 (or any non-finite or negative value) = no measurement.
    pub depth: DepthImage,
    /// `T_world_camera`.
    pub pose: Pose,
    pub intrinsics: Intrinsics,
    /// Segments that came with the frame (a dataset's network predictions), if any.
    pub segments: Option<Segments>,
    /// Ground-truth instance ids (0 is an id like any other), if the source has them.
    pub ground_truth: Option<LabelImage>,
}

/// Which of a frame's annotations a consumer reads: a source may leave the others out and
/// skip decoding them (a flat frame's ground truth is a second label PNG that only scoring
/// reads, and a network needs neither).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Annotations {
    /// [`Frame::segments`]: the masks the source carries.
    pub segments: bool,
    /// [`Frame::ground_truth`].
    pub ground_truth: bool,
}

impl Annotations {
    /// Everything the source has.
    pub const ALL: Self = Self {
        segments: true,
        ground_truth: true,
    };
    /// Colour, depth and pose only.
    pub const NONE: Self = Self {
        segments: false,
        ground_truth: false,
    };
}

/// Why a frame cannot be used as it is.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameCheckError {
    /// An image whose size differs from the intrinsics'.
    Size {
        image: &'static str,
        found: (usize, usize),
        expected: (usize, usize),
    },
    /// Intrinsics that cannot project (zero, negative or non-finite focal length, ...).
    Intrinsics(String),
    /// A pose with a non-finite entry.
    Pose,
}

impl std::fmt::Display for FrameCheckError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Size {
                image,
                found,
                expected,
            } => write!(
                f,
                "{image} image is {}x{}, but the camera is {}x{}",
                found.0, found.1, expected.0, expected.1
            ),
            Self::Intrinsics(why) => write!(f, "unusable intrinsics: {why}"),
            Self::Pose => write!(f, "the camera pose has a non-finite entry"),
        }
    }
}

impl std::error::Error for FrameCheckError {}

/// What a camera gives for one frame, and all a map fuses: depth, colour, the camera and its
/// pose (Open3D's `Integrate(depth, color, intrinsic, extrinsic)`). A dataset's [`Frame`]
/// lends its own with [`Frame::view`]; a driver's images make one directly.
#[derive(Clone, Copy, Debug)]
pub struct RgbdView<'a> {
    /// Planar depth in metres; 0 (or any non-finite or negative value) = no measurement.
    pub depth: &'a DepthImage,
    pub color: &'a ColorImage,
    pub intrinsics: &'a Intrinsics,
    /// `T_world_camera`.
    pub pose: &'a Pose,
}

impl RgbdView<'_> {
    /// Checks that depth and colour match the camera and that camera and pose are usable.
    pub fn check(&self) -> Result<(), FrameCheckError> {
        self.check_with(&[])
    }

    fn check_with(&self, more: &[(&'static str, (usize, usize))]) -> Result<(), FrameCheckError> {
        self.intrinsics
            .check()
            .map_err(FrameCheckError::Intrinsics)?;
        let expected = (self.intrinsics.width, self.intrinsics.height);
        let images = [("depth", self.depth.dims()), ("colour", self.color.dims())];
        if let Some(&(image, found)) = images.iter().chain(more).find(|(_, d)| *d != expected) {
            return Err(FrameCheckError::Size {
                image,
                found,
                expected,
            });
        }
        let m = self.pose.to_homogeneous();
        if m.iter().any(|v| !v.is_finite()) {
            return Err(FrameCheckError::Pose);
        }
        Ok(())
    }
}

impl Frame {
    /// The frame's sensor parts, as a map fuses them.
    pub fn view(&self) -> RgbdView<'_> {
        RgbdView {
            depth: &self.depth,
            color: &self.color,
            intrinsics: &self.intrinsics,
            pose: &self.pose,
        }
    }

    /// Checks that every image matches the camera and that the camera is usable.
    pub fn check(&self) -> Result<(), FrameCheckError> {
        let mut annotations = Vec::new();
        if let Some(s) = &self.segments {
            annotations.push(("label", s.labels.dims()));
        }
        if let Some(g) = &self.ground_truth {
            annotations.push(("ground-truth", g.dims()));
        }
        self.view().check_with(&annotations)
    }
}

/// A frame a source could not deliver, and why; the stream goes on with the next frame.
#[derive(Debug)]
pub struct FrameError {
    /// The source's name for the frame (or a time, for a stream without names).
    pub frame: String,
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

impl FrameError {
    pub fn new(
        frame: impl Into<String>,
        source: impl Into<Box<dyn std::error::Error + Send + Sync>>,
    ) -> Self {
        Self {
            frame: frame.into(),
            source: source.into(),
        }
    }
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "frame {}: {}", self.frame, self.source)
    }
}

impl std::error::Error for FrameError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(self.source.as_ref())
    }
}

/// Frames in order, from any source (a dataset, a bag, a subscriber, a simulator): what the
/// perception and mapping stages consume.
pub type FrameStream = Box<dyn Iterator<Item = Result<Frame, FrameError>> + Send>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Image;

    fn frame() -> Frame {
        let k = Intrinsics {
            width: 4,
            height: 3,
            fx: 2.0,
            fy: 2.0,
            cx: 2.0,
            cy: 1.5,
        };
        Frame {
            id: "0".into(),
            timestamp: 0.0,
            color: Image::filled(4, 3, [0; 3]),
            depth: Image::filled(4, 3, 1.0),
            pose: Pose::identity(),
            intrinsics: k,
            segments: None,
            ground_truth: None,
        }
    }

    #[test]
    fn check_names_the_image_that_does_not_fit() {
        assert_eq!(frame().check(), Ok(()));
        let mut f = frame();
        f.ground_truth = Some(Image::filled(3, 3, 0));
        let e = f.check().unwrap_err();
        assert!(
            e.to_string().starts_with("ground-truth image is 3x3"),
            "{e}"
        );
        let mut f = frame();
        f.intrinsics.fx = 0.0;
        assert!(matches!(f.check(), Err(FrameCheckError::Intrinsics(_))));
    }

    #[test]
    fn frame_errors_keep_their_cause() {
        let e = FrameError::new("000007", "bad tiff");
        assert_eq!(e.to_string(), "frame 000007: bad tiff");
        assert_eq!(
            std::error::Error::source(&e).unwrap().to_string(),
            "bad tiff"
        );
    }
}
