//! The messages voxpan publishes, in ROS 2's layout and wire format (CDR, little endian, after
//! the 4-byte encapsulation header `00 01 00 00`), made from the same values [`crate::encode`]
//! builds for ROS 1. ROS 2's layouts differ from ROS 1's: the header has no `seq` and its stamp
//! is `{int32 sec, uint32 nanosec}`, CameraInfo's matrices are lower-case `d k r p`, and a
//! Marker has texture, UV and mesh-file fields. Checked against PyPI rosbags' CDR serializer in
//! `tests/rmw_zenoh.rs`.

use serde::Serialize;

use crate::msgs::{geometry_msgs, nav_msgs, sensor_msgs, std_msgs, visualization_msgs};
use crate::rmw_zenoh::{RosType, types};

/// CDR little-endian encapsulation (CDR_LE), as rmw implementations write it.
const ENCAPSULATION: [u8; 4] = [0, 1, 0, 0];

/// `value` as a ROS 2 sample: the encapsulation header, then the CDR body (aligned from the
/// body's first byte).
fn to_cdr<T: Serialize>(value: &T) -> Vec<u8> {
    let body = cdr_encoding::to_vec::<T, byteorder::LittleEndian>(value)
        .expect("these plain structs always serialize");
    let mut out = Vec::with_capacity(4 + body.len());
    out.extend_from_slice(&ENCAPSULATION);
    out.extend_from_slice(&body);
    out
}

#[derive(Serialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

#[derive(Serialize)]
struct Header<'a> {
    stamp: Time,
    frame_id: &'a str,
}

fn header(h: &std_msgs::Header) -> Header<'_> {
    Header {
        stamp: Time {
            sec: h.stamp.secs,
            nanosec: h.stamp.nsecs as u32,
        },
        frame_id: &h.frame_id,
    }
}

#[derive(Serialize)]
struct Image<'a> {
    header: Header<'a>,
    height: u32,
    width: u32,
    encoding: &'a str,
    is_bigendian: u8,
    step: u32,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
}

pub fn image(m: &sensor_msgs::Image) -> Vec<u8> {
    to_cdr(&Image {
        header: header(&m.header),
        height: m.height,
        width: m.width,
        encoding: &m.encoding,
        is_bigendian: m.is_bigendian,
        step: m.step,
        data: &m.data,
    })
}

#[derive(Serialize)]
struct RegionOfInterest {
    x_offset: u32,
    y_offset: u32,
    height: u32,
    width: u32,
    do_rectify: bool,
}

#[derive(Serialize)]
struct CameraInfo<'a> {
    header: Header<'a>,
    height: u32,
    width: u32,
    distortion_model: &'a str,
    d: &'a [f64],
    k: [f64; 9],
    r: [f64; 9],
    p: [f64; 12],
    binning_x: u32,
    binning_y: u32,
    roi: RegionOfInterest,
}

pub fn camera_info(m: &sensor_msgs::CameraInfo) -> Vec<u8> {
    to_cdr(&CameraInfo {
        header: header(&m.header),
        height: m.height,
        width: m.width,
        distortion_model: &m.distortion_model,
        d: &m.D,
        k: m.K,
        r: m.R,
        p: m.P,
        binning_x: m.binning_x,
        binning_y: m.binning_y,
        roi: RegionOfInterest {
            x_offset: m.roi.x_offset,
            y_offset: m.roi.y_offset,
            height: m.roi.height,
            width: m.roi.width,
            do_rectify: m.roi.do_rectify,
        },
    })
}

#[derive(Serialize)]
struct Pose([f64; 3], [f64; 4]);

fn pose(p: &geometry_msgs::Pose) -> Pose {
    let (t, q) = (&p.position, &p.orientation);
    Pose([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
}

#[derive(Serialize)]
struct PoseStamped<'a> {
    header: Header<'a>,
    pose: Pose,
}

pub fn pose_stamped(m: &geometry_msgs::PoseStamped) -> Vec<u8> {
    to_cdr(&PoseStamped {
        header: header(&m.header),
        pose: pose(&m.pose),
    })
}

pub fn string(m: &std_msgs::String) -> Vec<u8> {
    to_cdr(&m.data.as_str())
}

#[derive(Serialize)]
struct Duration {
    sec: i32,
    nanosec: u32,
}

/// sensor_msgs/CompressedImage, empty in every marker voxpan sends.
#[derive(Serialize)]
struct CompressedImage<'a> {
    header: Header<'a>,
    format: &'a str,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
}

/// visualization_msgs/MeshFile, empty likewise.
#[derive(Serialize)]
struct MeshFile<'a> {
    filename: &'a str,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
}

#[derive(Serialize)]
struct Marker<'a> {
    header: Header<'a>,
    ns: &'a str,
    id: i32,
    r#type: i32,
    action: i32,
    pose: Pose,
    scale: [f64; 3],
    color: [f32; 4],
    lifetime: Duration,
    frame_locked: bool,
    points: Vec<[f64; 3]>,
    colors: Vec<[f32; 4]>,
    texture_resource: &'a str,
    texture: CompressedImage<'a>,
    /// visualization_msgs/UVCoordinate[] (u, v).
    uv_coordinates: Vec<[f32; 2]>,
    text: &'a str,
    mesh_resource: &'a str,
    mesh_file: MeshFile<'a>,
    mesh_use_embedded_materials: bool,
}

fn rgba(c: &std_msgs::ColorRGBA) -> [f32; 4] {
    [c.r, c.g, c.b, c.a]
}

pub fn marker_array(m: &visualization_msgs::MarkerArray) -> Vec<u8> {
    let markers: Vec<Marker<'_>> = m
        .markers
        .iter()
        .map(|k| Marker {
            header: header(&k.header),
            ns: &k.ns,
            id: k.id,
            r#type: k.r#type,
            action: k.action,
            pose: pose(&k.pose),
            scale: [k.scale.x, k.scale.y, k.scale.z],
            color: rgba(&k.color),
            lifetime: Duration {
                sec: k.lifetime.sec,
                nanosec: k.lifetime.nsec as u32,
            },
            frame_locked: k.frame_locked,
            points: k.points.iter().map(|p| [p.x, p.y, p.z]).collect(),
            colors: k.colors.iter().map(rgba).collect(),
            texture_resource: "",
            texture: CompressedImage {
                header: Header {
                    stamp: Time { sec: 0, nanosec: 0 },
                    frame_id: "",
                },
                format: "",
                data: &[],
            },
            uv_coordinates: Vec::new(),
            text: &k.text,
            mesh_resource: &k.mesh_resource,
            mesh_file: MeshFile {
                filename: "",
                data: &[],
            },
            mesh_use_embedded_materials: k.mesh_use_embedded_materials,
        })
        .collect();
    to_cdr(&markers)
}

#[derive(Serialize)]
struct MapMetaData {
    map_load_time: Time,
    resolution: f32,
    width: u32,
    height: u32,
    origin: Pose,
}

#[derive(Serialize)]
struct OccupancyGrid<'a> {
    header: Header<'a>,
    info: MapMetaData,
    data: &'a [i8],
}

pub fn occupancy_grid(m: &nav_msgs::OccupancyGrid) -> Vec<u8> {
    to_cdr(&OccupancyGrid {
        header: header(&m.header),
        info: MapMetaData {
            map_load_time: Time {
                sec: m.info.map_load_time.secs,
                nanosec: m.info.map_load_time.nsecs as u32,
            },
            resolution: m.info.resolution,
            width: m.info.width,
            height: m.info.height,
            origin: pose(&m.info.origin),
        },
        data: &m.data,
    })
}

#[derive(Serialize)]
struct PointField<'a> {
    name: &'a str,
    offset: u32,
    datatype: u8,
    count: u32,
}

#[derive(Serialize)]
struct PointCloud2<'a> {
    header: Header<'a>,
    height: u32,
    width: u32,
    fields: Vec<PointField<'a>>,
    is_bigendian: bool,
    point_step: u32,
    row_step: u32,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
    is_dense: bool,
}

pub fn point_cloud2(m: &sensor_msgs::PointCloud2) -> Vec<u8> {
    to_cdr(&PointCloud2 {
        header: header(&m.header),
        height: m.height,
        width: m.width,
        fields: m
            .fields
            .iter()
            .map(|f| PointField {
                name: &f.name,
                offset: f.offset,
                datatype: f.datatype,
                count: f.count,
            })
            .collect(),
        is_bigendian: m.is_bigendian,
        point_step: m.point_step,
        row_step: m.row_step,
        data: &m.data,
        is_dense: m.is_dense,
    })
}

/// A message the nodes publish, as ROS 2 sends it: its type (for rmw_zenoh's keys and
/// tokens) and its CDR sample.
pub trait Ros2Message {
    const TYPE: RosType;
    fn to_cdr(&self) -> Vec<u8>;
}

impl Ros2Message for sensor_msgs::Image {
    const TYPE: RosType = types::IMAGE;
    fn to_cdr(&self) -> Vec<u8> {
        image(self)
    }
}

impl Ros2Message for sensor_msgs::CameraInfo {
    const TYPE: RosType = types::CAMERA_INFO;
    fn to_cdr(&self) -> Vec<u8> {
        camera_info(self)
    }
}

impl Ros2Message for geometry_msgs::PoseStamped {
    const TYPE: RosType = types::POSE_STAMPED;
    fn to_cdr(&self) -> Vec<u8> {
        pose_stamped(self)
    }
}

impl Ros2Message for std_msgs::String {
    const TYPE: RosType = types::STRING;
    fn to_cdr(&self) -> Vec<u8> {
        string(self)
    }
}

impl Ros2Message for nav_msgs::OccupancyGrid {
    const TYPE: RosType = types::OCCUPANCY_GRID;
    fn to_cdr(&self) -> Vec<u8> {
        occupancy_grid(self)
    }
}

impl Ros2Message for sensor_msgs::PointCloud2 {
    const TYPE: RosType = types::POINT_CLOUD2;
    fn to_cdr(&self) -> Vec<u8> {
        point_cloud2(self)
    }
}

impl Ros2Message for visualization_msgs::MarkerArray {
    const TYPE: RosType = types::MARKER_ARRAY;
    fn to_cdr(&self) -> Vec<u8> {
        marker_array(self)
    }
}
