use std::path::Path;

use voxpan_core::ColorImage;

use crate::IoError;

/// Reads an 8-bit colour image (RGB; alpha is dropped, grey is replicated).
pub fn read_color_png(path: &Path) -> Result<ColorImage, IoError> {
    let img = image::open(path)
        .map_err(|e| IoError::format(path, format!("not a readable colour image: {e}")))?;
    let rgb = img.into_rgb8();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let pixels = rgb
        .into_raw()
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    Ok(ColorImage::from_vec(w, h, pixels).expect("decoder returns width*height pixels"))
}

/// Writes an 8-bit RGB PNG.
pub fn write_color_png(path: &Path, color: &ColorImage) -> Result<(), IoError> {
    let raw: Vec<u8> = color.pixels().iter().flatten().copied().collect();
    image::RgbImage::from_raw(color.width() as u32, color.height() as u32, raw)
        .expect("buffer matches dimensions")
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| IoError::format(path, format!("cannot write PNG: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.png");
        let img = ColorImage::from_fn(5, 4, |x, y| [x as u8, y as u8, (x * y) as u8]);
        write_color_png(&path, &img).unwrap();
        assert_eq!(read_color_png(&path).unwrap(), img);
    }
}
