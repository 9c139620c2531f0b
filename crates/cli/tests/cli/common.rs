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
