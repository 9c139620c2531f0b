//! Replays the fuzz corpora (fuzz/seeds, fuzz/corpus, fuzz/regressions) through the readers on
//! the stable toolchain: every input the fuzzers kept, and every input that once crashed a
//! reader, must give a value or an error. The same calls as fuzz/fuzz_targets/*.rs.

use std::path::{Path, PathBuf};

use voxpan_map::PanopticMap;

/// Every file under fuzz/{seeds,corpus,regressions}/`target`.
fn inputs(target: &str) -> Vec<PathBuf> {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut files = Vec::new();
    for kind in ["seeds", "corpus", "regressions"] {
        if let Ok(dir) = std::fs::read_dir(fuzz.join(kind).join(target)) {
            files.extend(dir.map(|e| e.unwrap().path()).filter(|p| p.is_file()));
        }
    }
    assert!(!files.is_empty(), "no fuzz inputs for {target}");
    files.sort();
    files
}

fn each(target: &str, mut check: impl FnMut(&[u8], &Path)) {
    for path in inputs(target) {
        let bytes = std::fs::read(&path).unwrap();
        check(&bytes, &path);
    }
}

fn each_text(target: &str, check: impl Fn(&str, &Path)) {
    each(target, |bytes, path| {
        if let Ok(text) = std::str::from_utf8(bytes) {
            check(text, path);
        }
    });
}

#[test]
fn image_readers_survive_their_corpora() {
    each("depth_tiff", |b, p| {
        let _ = voxpan_io::decode_depth_tiff(b, p);
    });
    each("depth_png", |b, p| {
        let _ = voxpan_io::decode_depth_png(b, 1000.0, p);
    });
    each("label_png", |b, p| {
        let _ = voxpan_io::decode_label_png(b, p);
    });
    // The seeds themselves are valid files.
    let seeds = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds");
    let palette = seeds.join("label_png/palette.png");
    let labels = voxpan_io::read_label_png(&palette).unwrap();
    assert!(labels.pixels().iter().all(|&id| id < 5), "palette indices");
    assert!(voxpan_io::read_depth_tiff(&seeds.join("depth_tiff/float32.tiff")).is_ok());
}

#[test]
fn text_readers_survive_their_corpora() {
    each_text("segments_json", |t, p| {
        let _ = voxpan_io::parse_segments_json(t, p);
    });
    each_text("pose_intrinsics", |t, p| {
        let _ = voxpan_dataset::flat::parse_pose(t, p);
        if let Ok(k) = voxpan_dataset::flat::parse_intrinsics(t, p) {
            assert!(k.check().is_ok());
        }
    });
    each_text("tum_lists", |t, p| {
        let _ = voxpan_dataset::tum::parse_list(t, p, 1);
        if let Ok(poses) = voxpan_dataset::tum::parse_trajectory(t, p) {
            assert!(poses.iter().all(|(t, _)| t.is_finite()));
        }
    });
}

#[test]
fn the_map_loader_survives_its_corpus() {
    each("map_file", |b, p| {
        if let Ok(map) = PanopticMap::from_bytes(b, p) {
            let again = PanopticMap::from_bytes(&map.to_bytes(), p).unwrap();
            assert!(again == map);
        }
    });
    let seed = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds/map_file/tiny.voxpan");
    assert!(PanopticMap::load(&seed).unwrap().block_count() > 0);
}

#[test]
fn the_live_message_decoders_survive_their_corpus() {
    use voxpan_bag::live::{self, Wire};
    each("live_messages", |b, _| {
        let Some((&pick, body)) = b.split_first() else {
            return;
        };
        let wire = if pick & 1 == 0 { Wire::Ros1 } else { Wire::Cdr };
        match (pick >> 1) % 8 {
            0 => drop(live::color_image(wire, body)),
            1 => drop(live::depth_image(wire, body)),
            2 => drop(live::label_image(wire, body)),
            3 => {
                if let Ok((_, k, _)) = live::camera_info(wire, body) {
                    assert!(k.check().is_ok());
                }
            }
            4 => drop(live::transforms(wire, body)),
            5 => drop(live::pose_stamped(wire, body)),
            6 => drop(live::segment_list(wire, body)),
            _ => drop(live::string(wire, body)),
        }
    });
    // The seeds are real messages: each decodes.
    let seeds = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds/live_messages");
    let color = std::fs::read(seeds.join("ros1-camera_color_image_raw")).unwrap();
    assert!(live::color_image(Wire::Ros1, &color[1..]).is_ok());
    let info = std::fs::read(seeds.join("cdr-camera_color_camera_info")).unwrap();
    assert!(live::camera_info(Wire::Cdr, &info[1..]).is_ok());
}

#[test]
fn the_rmw_zenoh_attachment_parser_survives_its_corpus() {
    use voxpan_bag::live::{ATTACHMENT_LEN, Attachment};
    let mut parsed = 0;
    each("attachment", |b, path| {
        if let Ok(a) = Attachment::parse(b) {
            parsed += 1;
            let bytes = a.to_bytes();
            assert_eq!(Attachment::parse(&bytes), Ok(a), "{}", path.display());
            if b.len() == ATTACHMENT_LEN {
                assert_eq!(&bytes[..], b, "{}", path.display());
            }
        }
    });
    // Both seeds (the current layout and Jazzy 0.2.0-0.2.3's) are real attachments.
    assert!(parsed >= 2, "the two seeds parse: {parsed}");
}

#[test]
fn the_bag_readers_survive_their_corpus() {
    use voxpan_dataset::FrameSource;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("input.bag");
    let mut opened = 0;
    each("bag_file", |b, _| {
        std::fs::write(&path, b).unwrap();
        let _ = voxpan_bag::summarize(&path);
        if let Ok(bag) = voxpan_bag::BagDataset::open(&path, voxpan_bag::BagOptions::default()) {
            opened += 1;
            if !bag.is_empty() {
                let _ = bag.load(0);
            }
        }
    });
    assert!(
        opened >= 3,
        "the seeds (ROS 1, MCAP, SQLite) open: {opened}"
    );
}

#[test]
fn the_assembler_survives_its_corpus() {
    use voxpan_bag::assemble::{Assembler, Input};
    use voxpan_bag::live::Wire;
    each("assembler", |b, path| {
        let Some((&setup, mut rest)) = b.split_first() else {
            return;
        };
        let wire = if setup & 1 == 0 {
            Wire::Ros1
        } else {
            Wire::Cdr
        };
        let mut options = voxpan_bag::BagOptions::default();
        if setup & 4 != 0 {
            options.pose_topic = Some("/pose".into());
        }
        let mut assembler = Assembler::new(options, setup & 2 != 0, wire);
        let mut frames = 0;
        while rest.len() >= 3 {
            let input = Input::ALL[usize::from(rest[0]) % Input::ALL.len()];
            let len = usize::from(u16::from_le_bytes([rest[1], rest[2]])).min(rest.len() - 3);
            let body = &rest[3..3 + len];
            rest = &rest[3 + len..];
            if assembler.topic(input).is_some() {
                let _ = assembler.add(input, body, 0);
                frames += assembler.take_ready().iter().filter(|r| r.is_ok()).count();
            }
        }
        // The seeds are the 2-frame bags' messages in log order: both frames assemble.
        if path.to_string_lossy().contains("seeds") {
            assert_eq!(frames, 2, "{}", path.display());
        }
    });
}
