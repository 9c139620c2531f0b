use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::{TiffEncoder, colortype};
use voxpan_core::DepthImage;

use crate::IoError;

/// Reads a depth map in metres: a float TIFF (`.tif`/`.tiff`, metres) or a 16-bit PNG, whose
/// integer values are divided by `png_units_per_metre` (1000 for millimetres, 5000 for TUM).
pub fn read_depth(path: &Path, png_units_per_metre: f32) -> Result<DepthImage, IoError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("tif" | "tiff") => read_depth_tiff(path),
        Some("png") => read_depth_png(path, png_units_per_metre),
        _ => Err(IoError::format(
            path,
            "unknown depth format: expected a .tiff (float metres) or a 16-bit .png",
        )),
    }
}

/// Reads a single-channel float32 (or float64 / 16-bit integer millimetre) TIFF.
pub fn read_depth_tiff(path: &Path) -> Result<DepthImage, IoError> {
    // Read whole, then decode from memory: the decoder's many small strip reads cost more
    // through a file than the decoding itself.
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    decode_depth_tiff(&bytes, path)
}

/// [`read_depth_tiff`] on a file's bytes; `path` names it in errors.
pub fn decode_depth_tiff(bytes: &[u8], path: &Path) -> Result<DepthImage, IoError> {
    let bad = |e: tiff::TiffError| IoError::format(path, format!("not a readable TIFF: {e}"));
    let mut decoder = Decoder::new(std::io::Cursor::new(bytes)).map_err(bad)?;
    let (width, height) = decoder.dimensions().map_err(bad)?;
    crate::check_image_size(path, width as usize, height as usize)?;
    if let Some(pixels) = uncompressed_f32(&mut decoder, bytes, width as usize * height as usize) {
        return Ok(
            DepthImage::from_vec(width as usize, height as usize, pixels)
                .expect("sample count checked"),
        );
    }
    let pixels: Vec<f32> = match decoder.read_image().map_err(bad)? {
        DecodingResult::F32(v) => v,
        DecodingResult::F64(v) => v.into_iter().map(|d| d as f32).collect(),
        DecodingResult::U16(v) => v.into_iter().map(|d| d as f32 / 1000.0).collect(),
        _ => {
            return Err(IoError::format(
                path,
                "unsupported TIFF sample type: expected float32, float64 or uint16 depth",
            ));
        }
    };
    let (w, h) = (width as usize, height as usize);
    let len = pixels.len();
    DepthImage::from_vec(w, h, pixels).ok_or_else(|| {
        IoError::format(
            path,
            format!("expected one channel: {len} samples for a {w}x{h} image"),
        )
    })
}

/// The samples of an uncompressed, single-channel float32 TIFF read straight from its strips
/// (the flat dataset's format): ten times faster than the decoder's generic path. `None` for
/// anything else, which the decoder then handles.
fn uncompressed_f32(
    decoder: &mut Decoder<std::io::Cursor<&[u8]>>,
    bytes: &[u8],
    samples: usize,
) -> Option<Vec<f32>> {
    use tiff::tags::{ByteOrder, Tag};
    let tag = |d: &mut Decoder<_>, t: Tag| d.find_tag_unsigned::<u32>(t).ok().flatten();
    let plain = tag(decoder, Tag::Compression) == Some(1)
        && tag(decoder, Tag::BitsPerSample) == Some(32)
        && tag(decoder, Tag::SampleFormat) == Some(3)
        && tag(decoder, Tag::SamplesPerPixel).unwrap_or(1) == 1;
    if !plain {
        return None;
    }
    let offsets = decoder.get_tag_u32_vec(Tag::StripOffsets).ok()?;
    let counts = decoder.get_tag_u32_vec(Tag::StripByteCounts).ok()?;
    // Whole samples in every strip, and exactly the image's: anything else is the decoder's.
    if offsets.len() != counts.len()
        || counts.iter().any(|&c| c % 4 != 0)
        || counts.iter().map(|&c| c as usize).sum::<usize>() != samples * 4
    {
        return None;
    }
    let little = matches!(decoder.byte_order(), ByteOrder::LittleEndian);
    // Whole 4-byte samples, the byte order chosen once per strip: the extension has an exact
    // length and compiles to a copy (sample by sample, testing the order each time, it cost
    // 11 instructions a sample).
    fn convert(out: &mut Vec<f32>, strip: &[u8], from_bytes: impl Fn([u8; 4]) -> f32) {
        // As 4-byte arrays (a cast, no copy): `chunks_exact` kept a length check per sample
        // in the loop and stopped it compiling to a copy.
        let whole: &[[u8; 4]] = bytemuck::cast_slice(&strip[..strip.len() / 4 * 4]);
        out.extend(whole.iter().map(|&b| from_bytes(b)));
    }
    let mut out = Vec::with_capacity(samples);
    for (&offset, &count) in offsets.iter().zip(&counts) {
        let strip = bytes.get(offset as usize..(offset as usize).checked_add(count as usize)?)?;
        if little {
            convert(&mut out, strip, f32::from_le_bytes);
        } else {
            convert(&mut out, strip, f32::from_be_bytes);
        }
    }
    Some(out)
}

/// Reads a 16-bit single-channel PNG depth map; 0 stays 0 (invalid).
pub fn read_depth_png(path: &Path, units_per_metre: f32) -> Result<DepthImage, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    decode_depth_png(&bytes, units_per_metre, path)
}

/// [`read_depth_png`] on a file's bytes; `path` names it in errors.
pub fn decode_depth_png(
    bytes: &[u8],
    units_per_metre: f32,
    path: &Path,
) -> Result<DepthImage, IoError> {
    let bad = |e: &dyn std::fmt::Display| IoError::format(path, format!("not a readable PNG: {e}"));
    let mut reader =
        image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(crate::MAX_IMAGE_SIDE as u32);
    limits.max_image_height = Some(crate::MAX_IMAGE_SIDE as u32);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| bad(&e))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let raw = match img {
        image::DynamicImage::ImageLuma16(buf) => buf.into_raw(),
        other => {
            return Err(IoError::format(
                path,
                format!(
                    "expected a 16-bit single-channel depth PNG, found {:?}",
                    other.color()
                ),
            ));
        }
    };
    let pixels = raw
        .into_iter()
        .map(|d| d as f32 / units_per_metre)
        .collect();
    Ok(DepthImage::from_vec(w, h, pixels).expect("decoder returns width*height samples"))
}

/// Writes a float32 depth TIFF (metres), the flat dataset's format.
pub fn write_depth_tiff(path: &Path, depth: &DepthImage) -> Result<(), IoError> {
    let file = File::create(path).map_err(|e| IoError::io(path, e))?;
    let mut encoder =
        TiffEncoder::new(BufWriter::new(file)).map_err(|e| IoError::format(path, e.to_string()))?;
    encoder
        .write_image::<colortype::Gray32Float>(
            depth.width() as u32,
            depth.height() as u32,
            depth.pixels(),
        )
        .map_err(|e| IoError::format(path, e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiff_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.tiff");
        let depth = DepthImage::from_fn(5, 3, |x, y| x as f32 * 0.5 + y as f32);
        write_depth_tiff(&path, &depth).unwrap();
        assert_eq!(read_depth(&path, 1000.0).unwrap(), depth);
    }

    #[test]
    fn the_strip_fast_path_reads_what_the_decoder_reads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.tiff");
        // Large enough for the encoder to write several strips; NaN and negatives included.
        let depth = DepthImage::from_fn(333, 217, |x, y| match (x + y) % 97 {
            0 => f32::NAN,
            1 => -1.0,
            k => k as f32 * 0.013 + y as f32 * 1e-4,
        });
        write_depth_tiff(&path, &depth).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut decoder = Decoder::new(std::io::Cursor::new(bytes.as_slice())).unwrap();
        let fast = uncompressed_f32(&mut decoder, &bytes, 333 * 217).expect("a plain float TIFF");
        let DecodingResult::F32(slow) = decoder.read_image().unwrap() else {
            panic!("float samples expected");
        };
        assert_eq!(fast.len(), slow.len());
        assert!(
            fast.iter()
                .zip(&slow)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
    }

    /// A big-endian ("MM"), uncompressed float32 TIFF of `w`×`h` samples in one strip, written
    /// by hand (the encoder writes little-endian only).
    fn big_endian_tiff(w: u32, h: u32, samples: &[f32]) -> Vec<u8> {
        let entries: [(u16, u16, u32); 10] = [
            (256, 4, w),                   // ImageWidth
            (257, 4, h),                   // ImageLength
            (258, 3, 32),                  // BitsPerSample
            (259, 3, 1),                   // Compression: none
            (262, 3, 1),                   // PhotometricInterpretation: black is zero
            (273, 4, 8 + 2 + 12 * 10 + 4), // StripOffsets: right after the IFD
            (277, 3, 1),                   // SamplesPerPixel
            (278, 4, h),                   // RowsPerStrip
            (279, 4, 4 * w * h),           // StripByteCounts
            (339, 3, 3),                   // SampleFormat: IEEE float
        ];
        let mut out = b"MM\0\x2a".to_vec();
        out.extend(8u32.to_be_bytes());
        out.extend((entries.len() as u16).to_be_bytes());
        for (tag, kind, value) in entries {
            out.extend(tag.to_be_bytes());
            out.extend(kind.to_be_bytes());
            out.extend(1u32.to_be_bytes());
            // A SHORT sits in the first two bytes of the value field.
            if kind == 3 {
                out.extend((value as u16).to_be_bytes());
                out.extend([0, 0]);
            } else {
                out.extend(value.to_be_bytes());
            }
        }
        out.extend(0u32.to_be_bytes());
        for v in samples {
            out.extend(v.to_be_bytes());
        }
        out
    }

    #[test]
    fn the_strip_fast_path_reads_big_endian_files_as_the_decoder_does() {
        let (w, h) = (7u32, 5u32);
        let samples: Vec<f32> = (0..w * h).map(|i| i as f32 * 0.37 - 3.0).collect();
        let bytes = big_endian_tiff(w, h, &samples);
        let mut decoder = Decoder::new(std::io::Cursor::new(bytes.as_slice())).unwrap();
        let fast = uncompressed_f32(&mut decoder, &bytes, (w * h) as usize).expect("plain float");
        assert_eq!(fast, samples);
        let DecodingResult::F32(slow) = decoder.read_image().unwrap() else {
            panic!("float samples expected");
        };
        assert_eq!(fast, slow);
        let path = Path::new("be.tiff");
        assert_eq!(
            decode_depth_tiff(&bytes, path).unwrap().pixels(),
            &samples[..]
        );
    }

    #[test]
    fn png_depth_is_scaled() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.png");
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(2, 1, vec![0u16, 1500])
            .unwrap()
            .save(&path)
            .unwrap();
        let d = read_depth(&path, 1000.0).unwrap();
        assert_eq!(d.pixels(), &[0.0, 1.5]);
    }

    #[test]
    fn errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.tiff");
        std::fs::write(&path, b"not a tiff").unwrap();
        let err = read_depth(&path, 1000.0).unwrap_err();
        assert!(err.to_string().contains("broken.tiff"), "{err}");
        let err = read_depth(&dir.path().join("missing.tiff"), 1000.0).unwrap_err();
        assert!(err.to_string().contains("missing.tiff"), "{err}");
        let err = read_depth(&dir.path().join("depth.exr"), 1000.0).unwrap_err();
        assert!(err.to_string().contains("unknown depth format"), "{err}");
    }
}
