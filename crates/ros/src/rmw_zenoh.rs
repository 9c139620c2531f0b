//! ROS 2's rmw_zenoh wire conventions, as plain functions: the key expression a topic's samples
//! travel on, the liveliness tokens that make nodes and endpoints visible to the ROS graph
//! (`ros2 topic list`, subscription counts), the QoS text inside them, the publisher id, and the
//! attachment every sample must carry. A zenoh session that follows these talks to ROS 2 nodes
//! running rmw_zenoh_cpp (Jazzy 0.2.4 and later, Kilted, Rolling); `docs/ros2-rmw-zenoh.md`
//! says where in rmw_zenoh's source each rule comes from.
//!
//! Nothing here opens a network connection: the rules are checked byte for byte against
//! independent implementations (PyPI `rosbags` for type hashes, `eclipse-zenoh`'s serializer for
//! attachments, `xxhash` for ids) in `tests/rmw_zenoh.rs`.

use std::fmt::Write as _;

/// The attachment is parsed where every other inbound byte is (voxpan-bag, reachable by the
/// fuzzers without the ROS stack).
pub use voxpan_bag::live::{ATTACHMENT_LEN, Attachment};

/// A ROS 2 message type as rmw_zenoh names it: `pkg/msg/Type` and its RIHS01 type hash
/// (REP-2011: sha256 of the type description; the same for Humble's definitions through
/// Lyrical for these types).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RosType {
    pub name: &'static str,
    pub hash: &'static str,
}

impl RosType {
    /// `sensor_msgs::msg::dds_::Image_`: the DDS-style name rmw_zenoh puts in keys.
    pub fn dds_name(&self) -> String {
        let mut parts = self.name.split('/');
        let (pkg, kind, ty) = (
            parts.next().unwrap_or_default(),
            parts.next().unwrap_or_default(),
            parts.next().unwrap_or_default(),
        );
        format!("{pkg}::{kind}::dds_::{ty}_")
    }
}

/// The ROS 2 message type a camera input is subscribed as (rmw_zenoh's keys name the type).
pub fn input_type(input: voxpan_bag::assemble::Input) -> RosType {
    use voxpan_bag::assemble::Input;
    match input {
        Input::Color | Input::Depth | Input::Labels => types::IMAGE,
        Input::CameraInfo => types::CAMERA_INFO,
        Input::Tf | Input::TfStatic => types::TF_MESSAGE,
        Input::Pose => types::POSE_STAMPED,
        Input::Segments => types::STRING,
    }
}

/// The types voxpan's nodes send and receive. Hashes computed by PyPI rosbags 0.11.9
/// (`Typestore.hash_rihs01`, ROS 2 Jazzy store); the test recomputes them.
pub mod types {
    use super::RosType;

    pub const STRING: RosType = RosType {
        name: "std_msgs/msg/String",
        hash: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    };
    pub const IMAGE: RosType = RosType {
        name: "sensor_msgs/msg/Image",
        hash: "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    };
    pub const CAMERA_INFO: RosType = RosType {
        name: "sensor_msgs/msg/CameraInfo",
        hash: "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    };
    pub const POSE_STAMPED: RosType = RosType {
        name: "geometry_msgs/msg/PoseStamped",
        hash: "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    };
    pub const MARKER_ARRAY: RosType = RosType {
        name: "visualization_msgs/msg/MarkerArray",
        hash: "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf",
    };
    pub const OCCUPANCY_GRID: RosType = RosType {
        name: "nav_msgs/msg/OccupancyGrid",
        hash: "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7",
    };
    pub const POINT_CLOUD2: RosType = RosType {
        name: "sensor_msgs/msg/PointCloud2",
        hash: "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
    };
    pub const TF_MESSAGE: RosType = RosType {
        name: "tf2_msgs/msg/TFMessage",
        hash: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    };

    pub const ALL: [RosType; 8] = [
        STRING,
        IMAGE,
        CAMERA_INFO,
        POSE_STAMPED,
        MARKER_ARRAY,
        OCCUPANCY_GRID,
        POINT_CLOUD2,
        TF_MESSAGE,
    ];
}

/// The key expression a topic's samples are put on and subscribed from (publisher and
/// subscription use the same one, exactly: a different type or hash means no data):
/// `<domain>/<topic without its leading and trailing '/'>/<dds type>/<hash>`.
pub fn data_key(domain: u32, topic: &str, ty: &RosType) -> String {
    let topic = topic.strip_prefix('/').unwrap_or(topic);
    let topic = topic.strip_suffix('/').unwrap_or(topic);
    format!("{domain}/{topic}/{}/{}", ty.dds_name(), ty.hash)
}

/// A name inside a liveliness token: every '/' becomes '%' (so `/` alone is `%`).
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// The QoS of an endpoint, as far as voxpan sets it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Qos {
    pub reliable: bool,
    /// TRANSIENT_LOCAL (late joiners get the last `depth` samples) instead of VOLATILE.
    pub transient_local: bool,
    /// KEEP_ALL instead of KEEP_LAST(`depth`).
    pub keep_all: bool,
    pub depth: usize,
}

impl Qos {
    /// rclcpp's default: reliable, volatile, keep last 10.
    pub const DEFAULT: Qos = Qos {
        reliable: true,
        transient_local: false,
        keep_all: false,
        depth: 10,
    };
    /// The sensor-data profile: best effort, keep last 5.
    pub const SENSOR_DATA: Qos = Qos {
        reliable: false,
        transient_local: false,
        keep_all: false,
        depth: 5,
    };

    /// The token's QoS part, `R:D:H,depth:DLs,DLns:LSs,LSns:LV,LLs,LLns`, each field left
    /// empty when it equals rmw_zenoh's default (reliable, volatile, keep last, depth 42, no
    /// deadline, no lifespan, automatic liveliness, no lease); rmw enum numbers otherwise
    /// (best effort 2, transient local 1, keep all 2).
    pub fn keyexpr(&self) -> String {
        let reliability = if self.reliable { "" } else { "2" };
        let durability = if self.transient_local { "1" } else { "" };
        let history = if self.keep_all { "2" } else { "" };
        // rmw_zenoh turns depth 0 into its default, 42, and leaves the default out.
        let depth = match self.depth {
            0 | 42 => String::new(),
            d => d.to_string(),
        };
        format!("{reliability}:{durability}:{history},{depth}:,:,:,,")
    }
}

/// What an endpoint's liveliness token announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EntityKind {
    Publisher,
    Subscription,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// A node as the ROS graph sees it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeName {
    pub domain: u32,
    /// This zenoh session's id (`Session::zid()` as text): tokens are matched to sessions by it.
    pub session_id: String,
    /// Unique among this session's nodes and entities.
    pub node_id: u64,
    /// Security enclave, `/` by default.
    pub enclave: String,
    /// `/` or `/robot`.
    pub namespace: String,
    pub name: String,
}

impl NodeName {
    /// `@ros2_lv/<domain>/<zid>/<nid>/<id>/<kind>/<enclave>/<ns>/<node>`, names mangled.
    fn token_prefix(&self, entity_id: u64, kind: &str) -> String {
        format!(
            "@ros2_lv/{}/{}/{}/{}/{}/{}/{}/{}",
            self.domain,
            self.session_id,
            self.node_id,
            entity_id,
            kind,
            mangle(&self.enclave),
            mangle(&self.namespace),
            mangle(&self.name)
        )
    }
}

/// The node's own liveliness token (its entity id is its node id).
pub fn node_token(node: &NodeName) -> String {
    node.token_prefix(node.node_id, "NN")
}

/// The liveliness token of one of `node`'s publishers or subscriptions: the node's part, then
/// `/<topic>/<type>/<hash>/<qos>`, names mangled.
pub fn endpoint_token(
    node: &NodeName,
    entity_id: u64,
    kind: EntityKind,
    topic: &str,
    ty: &RosType,
    qos: &Qos,
) -> String {
    let mut token = node.token_prefix(entity_id, kind.code());
    let _ = write!(
        token,
        "/{}/{}/{}/{}",
        mangle(topic),
        mangle(&ty.dds_name()),
        ty.hash,
        qos.keyexpr()
    );
    token
}

/// A publisher's id (its GID) as rmw_zenoh makes it: XXH3-128 of its liveliness token, low
/// 64 bits first, little endian. Receivers only report it; it need not match anything.
pub fn publisher_id(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_tokens_follow_rmw_zenoh() {
        assert_eq!(
            data_key(0, "/camera/color/image_raw", &types::IMAGE),
            "0/camera/color/image_raw/sensor_msgs::msg::dds_::Image_/\
             RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
        );
        assert_eq!(Qos::DEFAULT.keyexpr(), "::,10:,:,:,,");
        assert_eq!(Qos::SENSOR_DATA.keyexpr(), "2::,5:,:,:,,");
        let tf_static = Qos {
            transient_local: true,
            depth: 1,
            ..Qos::DEFAULT
        };
        assert_eq!(tf_static.keyexpr(), ":1:,1:,:,:,,");
        let node = NodeName {
            domain: 0,
            session_id: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
            node_id: 0,
            enclave: "/".into(),
            namespace: "/".into(),
            name: "talker".into(),
        };
        assert_eq!(
            node_token(&node),
            "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/talker"
        );
        assert_eq!(
            endpoint_token(
                &node,
                10,
                EntityKind::Publisher,
                "/chatter",
                &types::STRING,
                &Qos::DEFAULT
            ),
            "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MP/%/%/talker/%chatter/\
             std_msgs::msg::dds_::String_/\
             RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
        );
    }
}
