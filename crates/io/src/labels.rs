use std::path::Path;

use voxpan_core::LabelImage;

use crate::IoError;

/// Reads a label image: a PNG of 1 to 16 bits per sample. Grey images hold the ids; a
/// palette (indexed) image holds them as palette indices (never as the palette's colours);
/// with several channels, channel 0 holds the id (as the flat dataset's ground truth does).
pub fn read_label_png(path: &Path) -> Result<LabelImage, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    decode_label_png(&bytes, path)
}

/// [`read_label_png`] on a file's bytes; `path` names it in errors.
pub fn decode_label_png(bytes: &[u8], path: &Path) -> Result<LabelImage, IoError> {
    let bad = |e: &dyn std::fmt::Display| {
        IoError::format(path, format!("not a readable label image: {e}"))
    };
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    // Raw samples: palette indices stay indices, 16-bit stays 16-bit.
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(|e| bad(&e))?;
    let (w, h) = (reader.info().width as usize, reader.info().height as usize);
    crate::check_image_size(path, w, h)?;
    let (color, depth) = (reader.info().color_type, reader.info().bit_depth);
    let channels = color.samples();
    let bits = depth as usize;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad(&"image too large"))?;
    let mut buf = vec![0u8; size];
    let frame = reader.next_frame(&mut buf).map_err(|e| bad(&e))?;
    let line = frame.line_size;
    let mut ids = Vec::with_capacity(w * h);
    for row in buf.chunks(line).take(h) {
        // The usual layouts, a row at a time (a short row leaves too few ids: an error below).
        match (bits, channels) {
            (8, 1) => {
                ids.extend(row.iter().take(w).map(|&b| u16::from(b)));
                continue;
            }
            (16, 1) => {
                let samples = row.chunks_exact(2).take(w);
                ids.extend(samples.map(|b| u16::from_be_bytes([b[0], b[1]])));
                continue;
            }
            _ => {}
        }
        for x in 0..w {
            // The first sample of pixel x.
            let bit = x * channels * bits;
            let id = match bits {
                16 => u16::from_be_bytes([row[bit / 8], row[bit / 8 + 1]]),
                8 => row[bit / 8] as u16,
                // 1, 2 or 4 bits, most significant first.
                _ => ((row[bit / 8] >> (8 - bits - bit % 8)) & ((1u8 << bits) - 1)) as u16,
            };
            ids.push(id);
        }
    }
    LabelImage::from_vec(w, h, ids).ok_or_else(|| bad(&"fewer pixels than the header says"))
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

    /// A valid PNG header claiming `w`x`h` pixels, followed by a few bytes of pixel data.
    fn header_only(w: u32, h: u32) -> Vec<u8> {
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, w, h);
        encoder.set_depth(png::BitDepth::Sixteen);
        encoder.set_color(png::ColorType::Grayscale);
        let mut writer = encoder.write_header().unwrap();
        writer
            .write_chunk(png::chunk::IDAT, &[0x78, 0x9c, 0x63, 0, 0])
            .unwrap();
        drop(writer);
        bytes
    }

    #[test]
    fn a_header_claiming_a_huge_image_is_refused_before_allocating() {
        let name = Path::new("huge.png");
        let err = decode_label_png(&header_only(60_000, 60_000), name).unwrap_err();
        assert!(err.to_string().contains("60000x60000"), "{err}");
        let err = crate::decode_depth_png(&header_only(60_000, 60_000), 1000.0, name).unwrap_err();
        assert!(err.to_string().contains("huge.png"), "{err}");
        // A small one with its pixels missing is an error too, not a panic.
        assert!(decode_label_png(&header_only(4, 4), name).is_err());
    }

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
    fn palette_labels_are_read_by_index_not_colour() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("palette.png");
        // Indices 1..4 with palette colours whose red values are 37, 74, 111, 148.
        let mut encoder = png::Encoder::new(std::fs::File::create(&path).unwrap(), 4, 1);
        encoder.set_color(png::ColorType::Indexed);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_palette(vec![0, 0, 0, 37, 0, 0, 74, 0, 0, 111, 0, 0, 148, 0, 0]);
        let mut writer = encoder.write_header().unwrap();
        writer.write_image_data(&[1, 2, 3, 4]).unwrap();
        drop(writer);
        assert_eq!(read_label_png(&path).unwrap().pixels(), &[1, 2, 3, 4]);
        // Four-bit palettes pack two pixels per byte.
        let mut encoder = png::Encoder::new(std::fs::File::create(&path).unwrap(), 3, 1);
        encoder.set_color(png::ColorType::Indexed);
        encoder.set_depth(png::BitDepth::Four);
        encoder.set_palette(vec![0; 48]);
        let mut writer = encoder.write_header().unwrap();
        writer.write_image_data(&[0x1f, 0x70]).unwrap();
        drop(writer);
        assert_eq!(read_label_png(&path).unwrap().pixels(), &[1, 15, 7]);
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
