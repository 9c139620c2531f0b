//! rmw_zenoh's sample attachment as a ROS 2 node receives it from anyone on the network: any
//! bytes parse or fail with an error, and what parses writes back to bytes that parse to the
//! same attachment (the very bytes, for the current 33-byte layout).
#![no_main]
use libfuzzer_sys::fuzz_target;
use voxpan_bag::live::{ATTACHMENT_LEN, Attachment};

fuzz_target!(|data: &[u8]| {
    if let Ok(a) = Attachment::parse(data) {
        let bytes = a.to_bytes();
        assert_eq!(Attachment::parse(&bytes), Ok(a));
        if data.len() == ATTACHMENT_LEN {
            assert_eq!(&bytes[..], data);
        }
    }
});
