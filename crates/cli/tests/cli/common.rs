//! Running the `voxpan` binary from the command-line tests.

use std::ffi::OsStr;
use std::process::{Command, Output};

/// Runs `voxpan` with `args`.
pub fn voxpan<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    Command::new(env!("CARGO_BIN_EXE_voxpan"))
        .args(args)
        .output()
        .expect("the voxpan binary runs")
}

/// Runs `voxpan` with `args`, expects success and returns its standard output.
#[allow(dead_code)] // not every test file uses both helpers
pub fn voxpan_ok<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    let out = voxpan(args);
    assert!(
        out.status.success(),
        "voxpan failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Generates the tiny synthetic world into `dir/synth` and writes it as bags named `s` into
/// `dir/bags` with PyPI rosbags (`py`: tools/ros/make_test_bags.py; `options` are its own).
#[allow(dead_code)] // used by the bag tests and the ROS node tests (feature ros1)
pub fn tiny_world_bags(py: &std::path::Path, dir: &std::path::Path, options: &[&OsStr]) {
    voxpan_ok([
        "synth".as_ref(),
        "--out".as_ref(),
        dir.join("synth").as_os_str(),
        "--preset".as_ref(),
        "tiny".as_ref(),
    ]);
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ros/make_test_bags.py");
    let out = Command::new(py)
        .arg(script)
        .args([dir.join("synth"), dir.join("bags")])
        .args(["--name", "s"])
        .args(options)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
