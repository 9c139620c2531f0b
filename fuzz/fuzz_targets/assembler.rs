//! A live node's camera inputs as anyone on the network could send them: a stream of messages
//! on any subscribed input, in any order, with any stamps, fed to the assembler that pairs
//! them into frames. The first byte picks the wire, whether masks come from topics and whether
//! poses come from a pose topic; then each message is `[input][length: u16 LE][body]`. Nothing
//! may panic; every frame it gives has images of the camera's size and a finite pose; what it
//! holds stays bounded.
#![no_main]
use libfuzzer_sys::fuzz_target;
use voxpan_bag::BagOptions;
use voxpan_bag::assemble::{Assembler, Input, MAX_FRAMES, MAX_HELD, MAX_PENDING};
use voxpan_bag::live::Wire;

fuzz_target!(|data: &[u8]| {
    let Some((&setup, mut rest)) = data.split_first() else {
        return;
    };
    let wire = if setup & 1 == 0 { Wire::Ros1 } else { Wire::Cdr };
    let masks = setup & 2 != 0;
    let mut options = BagOptions::default();
    if setup & 4 != 0 {
        options.pose_topic = Some("/pose".into());
    }
    let mut assembler = Assembler::new(options, masks, wire);
    while rest.len() >= 3 {
        let input = Input::ALL[usize::from(rest[0]) % Input::ALL.len()];
        let len = usize::from(u16::from_le_bytes([rest[1], rest[2]])).min(rest.len() - 3);
        let body = &rest[3..3 + len];
        rest = &rest[3 + len..];
        if assembler.topic(input).is_none() {
            continue;
        }
        let _ = assembler.add(input, body, 0);
        for ready in assembler.take_ready() {
            if let Ok(f) = ready {
                let frame = &f.frame;
                let k = frame.intrinsics;
                assert_eq!(frame.color.dims(), (k.width, k.height));
                assert_eq!(frame.depth.dims(), (k.width, k.height));
                assert_eq!(frame.depth.pixels().len(), k.width * k.height);
                assert!(frame.pose.translation.vector.iter().all(|c| c.is_finite()));
                if let Some(s) = &frame.segments {
                    assert_eq!(s.labels.dims(), (k.width, k.height));
                }
                assert_eq!(frame.segments.is_some(), masks);
            }
        }
        // Bounded memory: at most MAX_HELD per stream and per moving edge, MAX_FRAMES edges.
        assert!(assembler.held() <= MAX_PENDING + 4 * MAX_HELD + MAX_FRAMES * MAX_HELD);
    }
});
