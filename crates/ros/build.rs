//! Generates the ROS 1 message types from `msg/` (field lists of the standard packages, so
//! their MD5 sums are ROS's own; a test checks them against Debian's ROS).

use std::path::PathBuf;

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let msg = root.join("msg");
    println!("cargo:rerun-if-changed={}", msg.display());
    let (tokens, files) =
        roslibrust_codegen::find_and_generate_ros_messages_without_ros_package_path(vec![msg])
            .expect("msg/ holds valid ROS 1 message definitions");
    for f in files {
        println!("cargo:rerun-if-changed={}", f.display());
    }
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("set by cargo")).join("msgs.rs");
    std::fs::write(&out, tokens.to_string()).expect("OUT_DIR is writable");
}
