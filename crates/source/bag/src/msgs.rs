//! The few message types voxpan reads, decoded from ROS 1 serialisation (by hand: the `rosbag`
//! crate hands out raw bytes, and the ROS 1 serde decoders on crates.io are unmaintained or
//! decode `uint8[]` byte by byte) or from CDR (with `cdr-encoding`, after the 4-byte
//! encapsulation header). Both end up in the same plain structs; image data stays borrowed.

use byteorder::{BigEndian, LittleEndian};
use serde::Deserialize;

/// How a connection's messages are serialised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wire {
    Ros1,
    Cdr,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// Nanoseconds since the epoch (ROS 2 allows negative seconds).
    pub stamp_ns: i64,
    pub frame_id: String,
}

#[derive(Debug)]
pub struct ImageMsg<'a> {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: bool,
    pub step: u32,
    pub data: &'a [u8],
}

#[derive(Clone, Debug)]
pub struct CameraInfoMsg {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant` (fisheye), or empty.
    pub distortion_model: String,
    /// The model's coefficients (`D`).
    pub distortion: Vec<f64>,
    /// Row-major 3×3 camera matrix.
    pub k: [f64; 9],
}

impl CameraInfoMsg {
    /// Why the images cannot be taken as pinhole images, when their distortion is not zero:
    /// voxpan maps rectified images only.
    pub fn distortion_warning(&self) -> Option<String> {
        self.distortion.iter().any(|d| d.abs() > 1e-9).then(|| {
            format!(
                "camera_info says the images are distorted ({} model, D = {:?}); voxpan maps \
                 rectified images with K alone, so the map will be bent: rectify first \
                 (image_proc's rectify, or the camera driver's rectified topics)",
                if self.distortion_model.is_empty() {
                    "unnamed"
                } else {
                    &self.distortion_model
                },
                self.distortion
            )
        })
    }
}

/// A rigid transform `T_parent_child` (geometry_msgs/TransformStamped; a PoseStamped is the
/// same with no child name).
#[derive(Clone, Debug)]
pub struct TransformMsg {
    pub header: Header,
    pub child_frame_id: String,
    pub translation: [f64; 3],
    /// x, y, z, w.
    pub rotation: [f64; 4],
}

pub type Result<T> = std::result::Result<T, String>;

// ---------------------------------------------------------------------------------------------
// ROS 1: little-endian, u32-length-prefixed strings and arrays, no alignment.

struct Ros1<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Ros1<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        let end = end.ok_or_else(|| {
            format!(
                "message ends early: {what} needs {n} bytes at offset {}, {} left",
                self.pos,
                self.buf.len() - self.pos
            )
        })?;
        let out = &self.buf[self.pos..end];
        self.pos = end;
        Ok(out)
    }
    fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        let b = self.take(8, what)?;
        Ok(f64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
    fn bytes(&mut self, what: &str) -> Result<&'a [u8]> {
        let n = self.u32(what)? as usize;
        self.take(n, what)
    }
    fn string(&mut self, what: &str) -> Result<String> {
        let b = self.bytes(what)?;
        String::from_utf8(b.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }
    fn f64s<const N: usize>(&mut self, what: &str) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }
    fn header(&mut self) -> Result<Header> {
        let _seq = self.u32("header.seq")?;
        let sec = self.u32("header.stamp")?;
        let nsec = self.u32("header.stamp")?;
        Ok(Header {
            stamp_ns: sec as i64 * 1_000_000_000 + nsec as i64,
            frame_id: self.string("header.frame_id")?,
        })
    }
    fn transform(&mut self) -> Result<([f64; 3], [f64; 4])> {
        Ok((self.f64s("translation")?, self.f64s("rotation")?))
    }
    fn end(&self, what: &str) -> Result<()> {
        if self.pos != self.buf.len() {
            return Err(format!(
                "{} bytes left over after a {what}: not that type",
                self.buf.len() - self.pos
            ));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// ROS 2: CDR structs for serde (field order is the wire order).

#[derive(Deserialize)]
struct CdrTime {
    sec: i32,
    nanosec: u32,
}

#[derive(Deserialize)]
struct CdrHeader {
    stamp: CdrTime,
    frame_id: String,
}

impl From<CdrHeader> for Header {
    fn from(h: CdrHeader) -> Self {
        Header {
            stamp_ns: h.stamp.sec as i64 * 1_000_000_000 + h.stamp.nanosec as i64,
            frame_id: h.frame_id,
        }
    }
}

#[derive(Deserialize)]
struct CdrImage<'a> {
    header: CdrHeader,
    height: u32,
    width: u32,
    encoding: String,
    is_bigendian: u8,
    step: u32,
    #[serde(borrow, with = "serde_bytes")]
    data: &'a [u8],
}

#[derive(Deserialize)]
struct CdrCameraInfo {
    header: CdrHeader,
    height: u32,
    width: u32,
    distortion_model: String,
    d: Vec<f64>,
    k: [f64; 9],
}

#[derive(Deserialize)]
struct CdrVector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Deserialize)]
struct CdrQuaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Deserialize)]
struct CdrTransform {
    translation: CdrVector3,
    rotation: CdrQuaternion,
}

#[derive(Deserialize)]
struct CdrTransformStamped {
    header: CdrHeader,
    child_frame_id: String,
    transform: CdrTransform,
}

#[derive(Deserialize)]
struct CdrTfMessage {
    transforms: Vec<CdrTransformStamped>,
}

#[derive(Deserialize)]
struct CdrPoseStamped {
    header: CdrHeader,
    pose: CdrTransform,
}

#[derive(Deserialize)]
struct CdrString {
    data: String,
}

impl From<CdrTransformStamped> for TransformMsg {
    fn from(t: CdrTransformStamped) -> Self {
        let (v, q) = (t.transform.translation, t.transform.rotation);
        TransformMsg {
            header: t.header.into(),
            child_frame_id: t.child_frame_id,
            translation: [v.x, v.y, v.z],
            rotation: [q.x, q.y, q.z, q.w],
        }
    }
}

/// Decodes a CDR payload: the encapsulation header says the byte order; alignment counts from
/// after it, so the body is handed to the decoder without it.
fn cdr<'a, T: Deserialize<'a>>(data: &'a [u8]) -> Result<T> {
    if data.len() < 4 {
        return Err(format!(
            "{} bytes: too short for a CDR encapsulation header",
            data.len()
        ));
    }
    // rosbag2's per-message compression (`--compression-mode message`) stores zstd frames.
    if data.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]) {
        return Err(
            "a zstd-compressed message (recorded with --compression-mode message): not \
                    read; `ros2 bag decompress` or `rosbags-convert` writes an uncompressed copy"
                .into(),
        );
    }
    let body = &data[4..];
    let decoded = match (data[0], data[1]) {
        (0, 1) => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        (0, 0) => cdr_encoding::from_bytes::<T, BigEndian>(body),
        (a, b) => {
            return Err(format!(
                "CDR representation {a:#04x}{b:02x} is not plain CDR (XCDR2 and others are not read)"
            ));
        }
    };
    decoded
        .map(|(v, _)| v)
        .map_err(|e| format!("not a valid CDR message of this type: {e}"))
}

// ---------------------------------------------------------------------------------------------

pub fn image(wire: Wire, data: &[u8]) -> Result<ImageMsg<'_>> {
    match wire {
        Wire::Ros1 => {
            let mut r = Ros1 { buf: data, pos: 0 };
            let msg = ImageMsg {
                header: r.header()?,
                height: r.u32("height")?,
                width: r.u32("width")?,
                encoding: r.string("encoding")?,
                is_bigendian: r.u8("is_bigendian")? != 0,
                step: r.u32("step")?,
                data: r.bytes("data")?,
            };
            r.end("sensor_msgs/Image")?;
            Ok(msg)
        }
        Wire::Cdr => {
            let m: CdrImage = cdr(data)?;
            Ok(ImageMsg {
                header: m.header.into(),
                height: m.height,
                width: m.width,
                encoding: m.encoding,
                is_bigendian: m.is_bigendian != 0,
                step: m.step,
                data: m.data,
            })
        }
    }
}

pub fn camera_info(wire: Wire, data: &[u8]) -> Result<CameraInfoMsg> {
    match wire {
        Wire::Ros1 => {
            let mut r = Ros1 { buf: data, pos: 0 };
            let header = r.header()?;
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            let distortion_model = r.string("distortion_model")?;
            let n = r.u32("D")? as usize;
            let d = r.take(n.saturating_mul(8), "D")?;
            let distortion = d
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                .collect();
            let k = r.f64s::<9>("K")?;
            // R, P, binning, ROI: not needed, but their presence confirms the type.
            r.take(9 * 8 + 12 * 8 + 4 + 4 + 4 * 4 + 1, "R, P, binning, roi")?;
            r.end("sensor_msgs/CameraInfo")?;
            Ok(CameraInfoMsg {
                header,
                height,
                width,
                distortion_model,
                distortion,
                k,
            })
        }
        Wire::Cdr => {
            let m: CdrCameraInfo = cdr(data)?;
            Ok(CameraInfoMsg {
                header: m.header.into(),
                height: m.height,
                width: m.width,
                distortion_model: m.distortion_model,
                distortion: m.d,
                k: m.k,
            })
        }
    }
}

pub fn tf_message(wire: Wire, data: &[u8]) -> Result<Vec<TransformMsg>> {
    match wire {
        Wire::Ros1 => {
            let mut r = Ros1 { buf: data, pos: 0 };
            let n = r.u32("transforms")? as usize;
            let mut out = Vec::with_capacity(n.min(1024));
            for _ in 0..n {
                let header = r.header()?;
                let child_frame_id = r.string("child_frame_id")?;
                let (translation, rotation) = r.transform()?;
                out.push(TransformMsg {
                    header,
                    child_frame_id,
                    translation,
                    rotation,
                });
            }
            r.end("tf2_msgs/TFMessage")?;
            Ok(out)
        }
        Wire::Cdr => {
            let m: CdrTfMessage = cdr(data)?;
            Ok(m.transforms.into_iter().map(Into::into).collect())
        }
    }
}

pub fn transform_stamped(wire: Wire, data: &[u8]) -> Result<TransformMsg> {
    match wire {
        Wire::Ros1 => {
            let mut r = Ros1 { buf: data, pos: 0 };
            let header = r.header()?;
            let child_frame_id = r.string("child_frame_id")?;
            let (translation, rotation) = r.transform()?;
            r.end("geometry_msgs/TransformStamped")?;
            Ok(TransformMsg {
                header,
                child_frame_id,
                translation,
                rotation,
            })
        }
        Wire::Cdr => Ok(cdr::<CdrTransformStamped>(data)?.into()),
    }
}

/// A geometry_msgs/PoseStamped as the transform `T_{header.frame_id}_{pose}` (no child name).
pub fn pose_stamped(wire: Wire, data: &[u8]) -> Result<TransformMsg> {
    match wire {
        Wire::Ros1 => {
            let mut r = Ros1 { buf: data, pos: 0 };
            let header = r.header()?;
            let (translation, rotation) = r.transform()?;
            r.end("geometry_msgs/PoseStamped")?;
            Ok(TransformMsg {
                header,
                child_frame_id: String::new(),
                translation,
                rotation,
            })
        }
        Wire::Cdr => {
            let m: CdrPoseStamped = cdr(data)?;
            let (v, q) = (m.pose.translation, m.pose.rotation);
            Ok(TransformMsg {
                header: m.header.into(),
                child_frame_id: String::new(),
                translation: [v.x, v.y, v.z],
                rotation: [q.x, q.y, q.z, q.w],
            })
        }
    }
}

pub fn string(wire: Wire, data: &[u8]) -> Result<String> {
    match wire {
        Wire::Ros1 => {
            let mut r = Ros1 { buf: data, pos: 0 };
            let s = r.string("data")?;
            r.end("std_msgs/String")?;
            Ok(s)
        }
        Wire::Cdr => Ok(cdr::<CdrString>(data)?.data),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ros1_header(out: &mut Vec<u8>, sec: u32, nsec: u32, frame: &str) {
        out.extend(7u32.to_le_bytes());
        out.extend(sec.to_le_bytes());
        out.extend(nsec.to_le_bytes());
        out.extend((frame.len() as u32).to_le_bytes());
        out.extend(frame.as_bytes());
    }

    #[test]
    fn ros1_image_round_trip_and_truncation() {
        let mut b = Vec::new();
        ros1_header(&mut b, 3, 5, "cam");
        b.extend(1u32.to_le_bytes()); // height
        b.extend(2u32.to_le_bytes()); // width
        b.extend(4u32.to_le_bytes());
        b.extend(b"rgb8");
        b.push(0);
        b.extend(6u32.to_le_bytes());
        b.extend(6u32.to_le_bytes());
        b.extend([1, 2, 3, 4, 5, 6]);
        let m = image(Wire::Ros1, &b).unwrap();
        assert_eq!(m.header.stamp_ns, 3_000_000_005);
        assert_eq!((m.width, m.height, m.encoding.as_str()), (2, 1, "rgb8"));
        assert_eq!(m.data, &[1, 2, 3, 4, 5, 6]);
        for cut in 0..b.len() {
            assert!(image(Wire::Ros1, &b[..cut]).is_err(), "cut at {cut}");
        }
        let mut longer = b.clone();
        longer.push(0);
        assert!(
            image(Wire::Ros1, &longer)
                .unwrap_err()
                .contains("left over")
        );
    }

    #[test]
    fn cdr_string_and_bad_encapsulation() {
        // LE CDR: header, u32 length 3 (with NUL), "hi\0".
        let b = [0u8, 1, 0, 0, 3, 0, 0, 0, b'h', b'i', 0];
        assert_eq!(string(Wire::Cdr, &b).unwrap(), "hi");
        let mut xcdr2 = b;
        xcdr2[1] = 7;
        assert!(
            string(Wire::Cdr, &xcdr2)
                .unwrap_err()
                .contains("not plain CDR")
        );
        assert!(string(Wire::Cdr, &b[..2]).is_err());
        for cut in 4..b.len() {
            assert!(string(Wire::Cdr, &b[..cut]).is_err(), "cut at {cut}");
        }
        // A zstd frame (rosbag2's per-message compression) is named as such.
        let zstd = [0x28u8, 0xb5, 0x2f, 0xfd, 0x20, 0x0b, 0x59, 0, 0];
        assert!(
            string(Wire::Cdr, &zstd)
                .unwrap_err()
                .contains("zstd-compressed")
        );
    }
}
