//! The types every voxpan stage shares: a dense row-major [`Image`], a [`Frame`] with its
//! camera ([`Intrinsics`], [`Pose`]) and [`Segments`], the [`FrameStream`] sources produce,
//! label tables ([`ClassTable`]), and the indexed triangle [`Mesh`].
//!
//! Kept tiny (serde and nalgebra only), so that a segmentation network, a ROS subscriber or a
//! simulator can produce frames without pulling in image decoding or the map.
//!
//! ```
//! use voxpan_core::{Frame, Image, Intrinsics, Pose};
//!
//! let k = Intrinsics { width: 64, height: 48, fx: 32.0, fy: 32.0, cx: 32.0, cy: 24.0 };
//! let frame = Frame {
//!     id: "000000".into(),
//!     timestamp: 0.0,
//!     color: Image::filled(64, 48, [128, 128, 128]),
//!     depth: Image::filled(64, 48, 1.5), // metres
//!     pose: Pose::identity(),
//!     intrinsics: k,
//!     segments: None,
//!     ground_truth: None,
//! };
//! assert!(frame.check().is_ok());
//! ```

mod camera;
mod classes;
pub mod cpu;
mod frame;
mod image;
mod mesh;
mod segment;

pub use camera::{Intrinsics, Pose, PoseError, pose_from_matrix};
pub use classes::{ClassInfo, ClassTable};
pub use frame::{Annotations, Frame, FrameCheckError, FrameError, FrameStream, RgbdView, Segments};
pub use image::{ColorImage, DepthImage, Image, LabelImage, is_depth_within, is_valid_depth};
pub use mesh::{Mesh, MeshError, add_triangle_normals, unit_normal};
pub use nalgebra;
pub use segment::{Segment, label_runs, run_end, segment_ids};
