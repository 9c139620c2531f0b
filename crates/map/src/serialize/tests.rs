//! The map file: exact round trips, compactness, corruption rejected, version 2 still read.

use std::collections::BTreeMap;
use std::path::Path;

use voxpan_core::nalgebra::Point3;

use super::{StoredMap, from_bytes, to_bytes};
use crate::MapConfig;
use crate::associate::InstanceInfo;
use crate::layer::{Layer, VOXELS_PER_BLOCK};
use crate::mesh::tests::{sphere_layer, sphere_layer_banded};

fn stored() -> StoredMap {
    let mut layer = sphere_layer(Point3::new(0.1, 0.2, 0.3), 0.25, 0.02);
    // Labels on some voxels, and a never-observed voxel in one block.
    let indices = layer.sorted_indices();
    let (block, _) = layer.get_or_allocate(indices[3]);
    for i in 0..40 {
        block.labels[i].observe(3);
        block.labels[i].observe(if i % 2 == 0 { 3 } else { 7 });
    }
    block.voxels.set(100, Default::default());
    let mut instances = BTreeMap::new();
    let mut info = InstanceInfo::default();
    info.class_votes.insert(9, 4);
    info.thing_votes = [4, 1];
    info.frames_seen = 5;
    info.confirmed = true;
    info.shell_covered = 2;
    info.smallest_matched_view = 11;
    instances.insert(3u16, info);
    let mut config = MapConfig::default();
    config.tsdf.voxel_size = 0.02;
    config.tracking.min_overlap = 0.3;
    StoredMap {
        config,
        layer,
        instances,
        class_names: BTreeMap::from([(9, "chair".to_owned())]),
    }
}

fn bytes_of(s: &StoredMap) -> Vec<u8> {
    to_bytes(&s.config, &s.layer, &s.instances, &s.class_names)
}

#[test]
fn maps_round_trip_exactly_and_compactly() {
    let original = stored();
    let bytes = bytes_of(&original);
    let loaded = from_bytes(&bytes, Path::new("m.voxpan")).unwrap();
    assert_eq!(loaded, original);
    // Equal maps, equal files.
    assert_eq!(bytes_of(&loaded), bytes);
    let per_voxel = bytes.len() as f64 / original.layer.allocated_voxels() as f64;
    assert!(per_voxel < 4.0, "{per_voxel:.2} bytes per allocated voxel");
}

#[test]
fn corruption_and_truncation_are_rejected_naming_the_file() {
    let bytes = bytes_of(&stored());
    let path = Path::new("dir/map.voxpan");
    for position in [3, 9, 40, bytes.len() / 2, bytes.len() - 2] {
        let mut flipped = bytes.clone();
        flipped[position] ^= 0x10;
        let err = from_bytes(&flipped, path).unwrap_err().to_string();
        assert!(err.contains("map.voxpan"), "{err}");
    }
    for len in [0, 7, 20, bytes.len() - 100, bytes.len() - 1] {
        let err = from_bytes(&bytes[..len], path).unwrap_err().to_string();
        assert!(err.contains("map.voxpan"), "{err}");
    }
}

/// What voxpan 0.1 wrote: format version 2, raw voxels, no configuration.
fn version_2_bytes(layer: &Layer, instances: &BTreeMap<u16, InstanceInfo>) -> Vec<u8> {
    let mut out = b"VOXPANMP".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&layer.voxel_size().to_le_bytes());
    out.extend_from_slice(&(layer.len() as u64).to_le_bytes());
    for index in layer.sorted_indices() {
        for c in index {
            out.extend_from_slice(&c.to_le_bytes());
        }
        let block = layer.get(&index).unwrap();
        for v in block.voxels.iter() {
            out.extend_from_slice(&layer.distance(&v).to_le_bytes());
            out.extend_from_slice(&v.weight().to_le_bytes());
            out.extend_from_slice(&v.color());
            out.push(0);
        }
        for l in block.labels.iter() {
            for x in l.ids().iter().chain(&l.counts()) {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    out.extend_from_slice(&(instances.len() as u32).to_le_bytes());
    for (id, info) in instances {
        out.extend_from_slice(&id.to_le_bytes());
        out.extend_from_slice(&info.thing_votes[0].to_le_bytes());
        out.extend_from_slice(&info.thing_votes[1].to_le_bytes());
        out.extend_from_slice(&(info.class_votes.len() as u32).to_le_bytes());
        for (class, votes) in &info.class_votes {
            out.extend_from_slice(&class.to_le_bytes());
            out.extend_from_slice(&votes.to_le_bytes());
        }
    }
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

#[test]
fn version_2_files_still_load() {
    let mut original = stored();
    let info = original.instances.get_mut(&3).unwrap();
    (
        info.frames_seen,
        info.shell_covered,
        info.smallest_matched_view,
    ) = (0, 0, 0);
    let bytes = version_2_bytes(&original.layer, &original.instances);
    assert_eq!(
        bytes.len(),
        8 + 4 + 8 + 8 + original.layer.len() * (12 + VOXELS_PER_BLOCK * 20) + 4 + 2 + 12 + 8 + 4
    );
    let loaded = from_bytes(&bytes, Path::new("old.voxpan")).unwrap();
    assert_eq!(loaded.layer, original.layer);
    assert_eq!(loaded.instances, original.instances);
    assert_eq!(loaded.config.tsdf.voxel_size, 0.02);
    // A future version is refused with a reason.
    let mut future = bytes_of(&original);
    future[8..12].copy_from_slice(&9u32.to_le_bytes());
    let n = future.len() - 4;
    let crc = crc32fast::hash(&future[..n]);
    future[n..].copy_from_slice(&crc.to_le_bytes());
    let err = from_bytes(&future, Path::new("new.voxpan"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("version 9") && err.contains("newer"), "{err}");
}

#[test]
fn version_3_files_load_without_shell_evidence() {
    let original = stored();
    // Version 3's instance record is version 4's without the two evidence counts after the
    // confirmed byte: magic, version, voxel size, configuration, count, id, three counts.
    let mut bytes = bytes_of(&original);
    let config_len = u32::from_le_bytes(bytes[20..24].try_into().unwrap()) as usize;
    let evidence = 24 + config_len + 4 + 2 + 12 + 1;
    assert_eq!(bytes[evidence - 1], 1, "the confirmed byte");
    bytes.drain(evidence..evidence + 8);
    bytes[8..12].copy_from_slice(&3u32.to_le_bytes());
    let n = bytes.len() - 4;
    let crc = crc32fast::hash(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
    let loaded = from_bytes(&bytes, Path::new("v3.voxpan")).unwrap();
    let mut expected = original.instances.clone();
    let info = expected.get_mut(&3).unwrap();
    (info.shell_covered, info.smallest_matched_view) = (0, 0);
    assert_eq!(loaded.instances, expected);
    assert_eq!(loaded.layer, original.layer);
    assert_eq!(loaded.class_names, original.class_names);
}

/// A map file written by the version 2 code itself (`voxpan run` at 79fc2de on 1 frame of
/// `voxpan synth --preset tiny`, 20 cm voxels, 1.5 m range).
#[test]
fn a_file_the_version_2_code_wrote_loads() {
    let bytes = include_bytes!("../../tests/data/v2-79fc2de.voxpan");
    assert_eq!(&bytes[8..12], &2u32.to_le_bytes());
    let loaded = from_bytes(bytes, Path::new("v2-79fc2de.voxpan")).unwrap();
    assert_eq!(loaded.config.tsdf.voxel_size, 0.2);
    assert_eq!(loaded.layer.len(), 6);
    assert_eq!(loaded.instances.len(), 8);
    // Every voxel against the file's own fields (block: 3 coordinates, then 512 voxels of
    // distance, weight, colour, pad): observed where the file's weight is, at its distance
    // (to the voxel's quantisation: a 255th of the band) and colour.
    let band = loaded.layer.truncation();
    let mut at = 8 + 4 + 8 + 8;
    let f32_at = |i: usize| f32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
    let mut observed = 0;
    for _ in 0..6 {
        let index: [i32; 3] = std::array::from_fn(|a| {
            i32::from_le_bytes(bytes[at + 4 * a..][..4].try_into().unwrap())
        });
        let block = loaded.layer.get(&index).expect("the file's block");
        at += 12;
        for (k, v) in block.voxels.iter().enumerate() {
            let (distance, weight) = (f32_at(at), f32_at(at + 4));
            assert_eq!(v.observed(), weight > 0.0, "block {index:?} voxel {k}");
            if weight > 0.0 {
                observed += 1;
                assert!(
                    (loaded.layer.distance(&v) - distance).abs() <= band / 254.0,
                    "block {index:?} voxel {k}"
                );
                assert_eq!(v.color(), [bytes[at + 8], bytes[at + 9], bytes[at + 10]]);
            }
            at += 12;
        }
        at += VOXELS_PER_BLOCK * 8; // the label slots
    }
    assert!(observed > 100, "{observed}");
    // What loaded saves (as the current version) and loads back unchanged.
    let again = from_bytes(&bytes_of(&loaded), Path::new("m.voxpan")).unwrap();
    assert_eq!(again, loaded);
}

#[test]
fn a_maps_own_truncation_band_scales_its_distances() {
    // Built with a band of 5 voxels: voxels hold distances the default band (3) could not.
    let mut original = stored();
    original.config.tsdf.truncation_voxels = 5.0;
    original.layer = sphere_layer_banded(Point3::new(0.1, 0.2, 0.3), 0.25, 0.02, 5.0);
    let far = |layer: &Layer| {
        layer
            .iter()
            .flat_map(|(_, b)| b.voxels.iter())
            .filter(|v| v.observed() && layer.distance(v).abs() > 0.09)
            .count()
    };
    assert!(far(&original.layer) > 1000);
    let loaded = from_bytes(&bytes_of(&original), Path::new("m.voxpan")).unwrap();
    assert_eq!(loaded, original);
    assert_eq!(far(&loaded.layer), far(&original.layer));
}

#[test]
fn odd_weights_in_version_2_files_load_and_save_back() {
    let original = stored();
    let mut bytes = version_2_bytes(&original.layer, &original.instances);
    // The weights of the first block's first voxels: a negative NaN, a negative weight, an
    // infinite one, and one below the smallest a voxel holds.
    let weights = [f32::from_bits(u32::MAX), -1.0, f32::INFINITY, 1e-42];
    for (k, w) in weights.iter().enumerate() {
        let at = 8 + 4 + 8 + 8 + 12 + k * 12 + 4;
        bytes[at..at + 4].copy_from_slice(&w.to_le_bytes());
    }
    let n = bytes.len() - 4;
    let crc = crc32fast::hash(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
    let loaded = from_bytes(&bytes, Path::new("old.voxpan")).unwrap();
    let first = loaded.layer.sorted_indices()[0];
    let voxels = &loaded.layer.get(&first).unwrap().voxels;
    assert!(!voxels.get(0).observed() && !voxels.get(1).observed());
    for v in voxels.iter().skip(2).take(2) {
        assert!(v.observed() && v.weight().is_finite() && v.weight() > 0.0);
    }
    // What loaded saves and loads back unchanged.
    let again = from_bytes(&bytes_of(&loaded), Path::new("m.voxpan")).unwrap();
    assert_eq!(again.layer, loaded.layer);
}

#[test]
fn maps_of_several_chunks_round_trip() {
    // A sphere of 3 m radius at 2 cm voxels allocates more blocks than one chunk holds.
    let layer = sphere_layer(Point3::new(0.0, 0.0, 0.0), 3.0, 0.02);
    assert!(layer.len() > super::CHUNK_BLOCKS, "{} blocks", layer.len());
    let original = StoredMap { layer, ..stored() };
    let bytes = bytes_of(&original);
    assert!(bytes.len() as u64 <= super::size_bound(&original.layer));
    assert_eq!(
        from_bytes(&bytes, Path::new("big.voxpan")).unwrap(),
        original
    );
}
