//! Message bodies as the live nodes receive them from anyone on the network (ROS 1
//! TCPROS-serialised, or CDR with its encapsulation header): the first byte picks the decoder
//! and the wire, the rest is the body. Any bytes decode or fail with an error; what decodes
//! holds sizes that agree with its pixels and finite poses.
#![no_main]
use libfuzzer_sys::fuzz_target;
use voxpan_bag::live::{self, Wire};

fuzz_target!(|data: &[u8]| {
    let Some((&pick, body)) = data.split_first() else {
        return;
    };
    let wire = if pick & 1 == 0 { Wire::Ros1 } else { Wire::Cdr };
    match (pick >> 1) % 8 {
        0 => {
            if let Ok((_, c)) = live::color_image(wire, body) {
                assert_eq!(c.pixels().len(), c.width() * c.height());
            }
        }
        1 => {
            if let Ok((_, d)) = live::depth_image(wire, body) {
                assert_eq!(d.pixels().len(), d.width() * d.height());
            }
        }
        2 => {
            if let Ok((_, l)) = live::label_image(wire, body) {
                assert_eq!(l.pixels().len(), l.width() * l.height());
            }
        }
        3 => {
            if let Ok((_, k, _)) = live::camera_info(wire, body) {
                assert!(k.check().is_ok());
            }
        }
        4 => {
            let _ = live::transforms(wire, body);
        }
        5 => {
            if let Ok((_, pose)) = live::pose_stamped(wire, body) {
                assert!(pose.translation.vector.iter().all(|c| c.is_finite()));
            }
        }
        6 => {
            let _ = live::segment_list(wire, body);
        }
        _ => {
            let _ = live::string(wire, body);
        }
    }
});
