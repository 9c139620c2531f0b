//! What both test binaries build their messages from.

/// A costmap of three columns and two rows, up along -y (a turned origin): one cell of each
/// kind, one inflated (0.03 m within the robot's 0.04 m), one with no obstacle in the map.
pub fn small_costmap() -> voxpan_map::Costmap {
    voxpan_map::Costmap {
        resolution: 0.05,
        axes: [0, 2],
        origin: [-1.25, 0.5],
        width: 3,
        height: 2,
        clearance: vec![
            Some(0.0),
            Some(0.1),
            None,
            Some(0.5),
            Some(0.03),
            Some(f32::INFINITY),
        ],
        robot_radius: 0.04,
        elevation: 0.1,
    }
}
