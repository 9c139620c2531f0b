//! Files on disk: depth maps, colour and label images, segment lists, label tables, PLY
//! meshes, and atomic writes.
//!
//! Every error names the file and says what is wrong with it; nothing here panics on data.
//!
//! ```
//! use voxpan_core::Image;
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("labels.png");
//! let labels = Image::from_fn(8, 4, |x, _| x as u16);
//! voxpan_io::write_label_png(&path, &labels).unwrap();
//! assert_eq!(voxpan_io::read_label_png(&path).unwrap(), labels);
//! ```

mod atomic;
mod classes;
mod color;
mod depth;
mod error;
mod identity;
mod labels;
mod ply;
mod sample;
mod segments;

pub use atomic::write_atomically;
pub use classes::{read_class_csv, write_class_csv};
pub use color::{color_image_size, read_color_png, write_color_png};
pub use depth::{
    decode_depth_png, decode_depth_tiff, read_depth, read_depth_png, read_depth_tiff,
    write_depth_tiff,
};
pub use error::IoError;
pub use identity::{is_file_at, same_file};
pub use labels::{decode_label_png, read_label_png, write_label_png};
pub use ply::{read_ply, write_ply, write_ply_to};
pub use sample::{
    FLAT_DIR_ENV, MODELS_DIR_ENV, ORT_LIBRARY_ENV, flat_sample_dir, models_dir, onnxruntime_library,
};
pub use segments::{parse_segments_json, read_segments_json, segments_json, write_segments_json};

/// The longest image side read: 16384 px is past every RGB-D camera's resolution, and a
/// header claiming more (a corrupt or hostile file) would otherwise allocate gigabytes.
pub const MAX_IMAGE_SIDE: usize = 16384;

/// Refuses images wider or taller than [`MAX_IMAGE_SIDE`] before their pixels are allocated.
pub(crate) fn check_image_size(path: &std::path::Path, w: usize, h: usize) -> Result<(), IoError> {
    if w == 0 || h == 0 || w > MAX_IMAGE_SIDE || h > MAX_IMAGE_SIDE {
        return Err(IoError::format(
            path,
            format!("image size {w}x{h}: expected 1 to {MAX_IMAGE_SIDE} pixels per side"),
        ));
    }
    Ok(())
}
