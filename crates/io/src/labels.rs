use std::path::Path;

use image::DynamicImage;
use voxpan_core::LabelImage;

use crate::IoError;

/// Reads a label image (8- or 16-bit PNG). With several channels, channel 0 holds the id (as
/// the flat dataset's ground truth does).
pub fn read_label_png(path: &Path) -> Result<LabelImage, IoError> {
    let img = image::open(path)
        .map_err(|e| IoError::format(path, format!("not a readable label image: {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let first_channel = |raw: Vec<u16>, channels: usize| -> Vec<u16> {
        raw.into_iter().step_by(channels).collect()
    };
    let ids: Vec<u16> = match img {
        DynamicImage::ImageLuma8(b) => b.into_raw().into_iter().map(u16::from).collect(),
        DynamicImage::ImageLumaA8(b) => {
            first_channel(b.into_raw().into_iter().map(u16::from).collect(), 2)
        }
        DynamicImage::ImageRgb8(b) => {
            first_channel(b.into_raw().into_iter().map(u16::from).collect(), 3)
        }
        DynamicImage::ImageRgba8(b) => {
            first_channel(b.into_raw().into_iter().map(u16::from).collect(), 4)
        }
        DynamicImage::ImageLuma16(b) => b.into_raw(),
        DynamicImage::ImageLumaA16(b) => first_channel(b.into_raw(), 2),
        DynamicImage::ImageRgb16(b) => first_channel(b.into_raw(), 3),
        DynamicImage::ImageRgba16(b) => first_channel(b.into_raw(), 4),
        other => {
            return Err(IoError::format(
                path,
                format!("unsupported label pixel format {:?}", other.color()),
            ));
        }
    };
    Ok(LabelImage::from_vec(w, h, ids).expect("decoder returns width*height pixels"))
}

/// Writes a label image as an 8-bit PNG when every id fits, else 16-bit.
pub fn write_label_png(path: &Path, labels: &LabelImage) -> Result<(), IoError> {
    let (w, h) = (labels.width() as u32, labels.height() as u32);
    let fail = |e: image::ImageError| IoError::format(path, format!("cannot write PNG: {e}"));
    if labels.pixels().iter().all(|&l| l <= u8::MAX as u16) {
        let raw: Vec<u8> = labels.pixels().iter().map(|&l| l as u8).collect();
        image::GrayImage::from_raw(w, h, raw)
            .expect("buffer matches dimensions")
            .save_with_format(path, image::ImageFormat::Png)
            .map_err(fail)
    } else {
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, labels.pixels().to_vec())
            .expect("buffer matches dimensions")
            .save_with_format(path, image::ImageFormat::Png)
            .map_err(fail)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_8_and_16_bit() {
        let dir = tempfile::tempdir().unwrap();
        for max in [200u16, 4000] {
            let path = dir.path().join(format!("l{max}.png"));
            let labels = LabelImage::from_fn(7, 4, |x, y| ((x * 31 + y * 17) as u16) % (max + 1));
            write_label_png(&path, &labels).unwrap();
            assert_eq!(read_label_png(&path).unwrap(), labels);
        }
    }

    #[test]
    fn rgb_labels_use_channel_zero() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rgb.png");
        image::RgbImage::from_raw(2, 1, vec![5, 9, 9, 7, 1, 1])
            .unwrap()
            .save(&path)
            .unwrap();
        assert_eq!(read_label_png(&path).unwrap().pixels(), &[5, 7]);
    }
}
