//! `voxpan run --live / --record`: the live view for Foxglove. Without the feature `live` the
//! options say how to build it; with it, a recording of a flat run holds every mapped frame
//! and the mesh (the view's own tests check the messages and the WebSocket server).

use crate::common::voxpan;

#[cfg(not(feature = "live"))]
#[test]
fn without_the_feature_the_live_options_say_how_to_build_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let record = dir.path().join("run.mcap");
    for flag in [vec!["--live"], vec!["--record", record.to_str().unwrap()]] {
        let mut args = vec!["run", "--out", out.to_str().unwrap()];
        args.extend(flag.iter().copied());
        let o = voxpan(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(err.contains("--features live"), "{err}");
    }
    assert!(!record.exists());
}

#[cfg(feature = "live")]
#[test]
fn a_recorded_run_holds_every_mapped_frame_and_the_mesh() {
    use std::collections::BTreeMap;
    let Some(flat) = voxpan_test_support::require_flat_sample(
        "a_recorded_run_holds_every_mapped_frame_and_the_mesh",
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let record = dir.path().join("run.mcap");
    let o = voxpan([
        "run".as_ref(),
        flat.as_os_str(),
        "--frames".as_ref(),
        "0:18:2".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
        "--record".as_ref(),
        record.as_os_str(),
        "--live-mesh-every".as_ref(),
        "4".as_ref(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&record).unwrap();
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *counts.entry(m.unwrap().channel.topic.clone()).or_default() += 1;
    }
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    let frames = metrics["report"]["frames"].as_u64().unwrap() as usize;
    assert!(frames >= 5, "{metrics}");
    for topic in [
        "/camera/color",
        "/camera/depth",
        "/camera/calibration",
        "/tf",
    ] {
        assert_eq!(counts.get(topic), Some(&frames), "{topic}: {counts:?}");
    }
    // Every 4th frame, and once at the end if anything changed since.
    let updates = counts["/map/mesh"];
    assert!(
        (frames / 4..=frames / 4 + 1).contains(&updates),
        "{updates} mesh updates for {frames} frames"
    );
}

#[cfg(feature = "live")]
#[test]
fn a_bad_live_address_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let o = voxpan([
        "run",
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "--live",
        "localhost",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--live") && err.contains("HOST:PORT"),
        "{err}"
    );
}
