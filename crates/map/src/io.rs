//! The map file: `VOXPANMP`, a format version, the voxel size, the blocks (TSDF and label
//! voxels), the instance table (class and thing/stuff votes), and a CRC-32 of everything before
//! it. Written to a temporary file and renamed, so a crash never leaves a
//! half-written map; a truncated or corrupted file is rejected, never half-loaded.

use std::io::Write;
use std::path::Path;

use std::collections::BTreeMap;

use crate::{Block, InstanceInfo, LabelVoxel, Layer, TsdfVoxel, VOXELS_PER_BLOCK};

const MAGIC: &[u8; 8] = b"VOXPANMP";
const VERSION: u32 = 2;
const VOXEL_BYTES: usize = 12;
const LABEL_BYTES: usize = 8;
const BLOCK_BYTES: usize = 12 + VOXELS_PER_BLOCK * (VOXEL_BYTES + LABEL_BYTES);

/// Why a map file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum MapFileError {
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid {
        path: std::path::PathBuf,
        message: String,
    },
}

fn invalid(path: &Path, message: impl Into<String>) -> MapFileError {
    MapFileError::Invalid {
        path: path.to_owned(),
        message: message.into(),
    }
}

/// A map as stored: the voxels and what is known of each instance.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFile {
    pub layer: Layer,
    pub instances: BTreeMap<u16, InstanceInfo>,
}

/// Serialises a map (blocks in a fixed order, so equal maps give equal files).
pub fn to_bytes(layer: &Layer, instances: &BTreeMap<u16, InstanceInfo>) -> Vec<u8> {
    let mut out = Vec::with_capacity(32 + layer.blocks.len() * BLOCK_BYTES);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&layer.voxel_size().to_le_bytes());
    out.extend_from_slice(&(layer.blocks.len() as u64).to_le_bytes());
    let mut indices: Vec<_> = layer.blocks.keys().copied().collect();
    indices.sort_unstable();
    for index in indices {
        for c in index {
            out.extend_from_slice(&c.to_le_bytes());
        }
        let block = &layer.blocks[&index];
        for v in block.voxels.iter() {
            out.extend_from_slice(&v.distance.to_le_bytes());
            out.extend_from_slice(&v.weight.to_le_bytes());
            out.extend_from_slice(&v.color);
            out.push(0);
        }
        for l in block.labels.iter() {
            for x in l.ids.iter().chain(&l.counts) {
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

/// Parses a map file's bytes; `path` is only used in messages.
pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<MapFile, MapFileError> {
    if bytes.len() < 32 || &bytes[..8] != MAGIC {
        return Err(invalid(path, "not a voxpan map (bad magic or too short)"));
    }
    let (body, tail) = bytes.split_at(bytes.len() - 4);
    let stored = u32::from_le_bytes(tail.try_into().expect("4 bytes"));
    if crc32fast::hash(body) != stored {
        return Err(invalid(
            path,
            "checksum mismatch: the file is corrupted or truncated",
        ));
    }
    let u32_at = |o: usize| u32::from_le_bytes(body[o..o + 4].try_into().expect("4 bytes"));
    let version = u32_at(8);
    if version != VERSION {
        return Err(invalid(
            path,
            format!("map format version {version}, this voxpan reads {VERSION}"),
        ));
    }
    let voxel_size = f64::from_le_bytes(body[12..20].try_into().expect("8 bytes"));
    let count = u64::from_le_bytes(body[20..28].try_into().expect("8 bytes")) as usize;
    if !(voxel_size.is_finite() && voxel_size > 0.0) {
        return Err(invalid(path, format!("invalid voxel size {voxel_size}")));
    }
    let blocks_end = count
        .checked_mul(BLOCK_BYTES)
        .and_then(|n| n.checked_add(28))
        .filter(|&end| end + 4 <= body.len())
        .ok_or_else(|| {
            invalid(
                path,
                format!(
                    "{count} blocks announced, {} bytes present",
                    body.len() - 28
                ),
            )
        })?;
    let mut layer = Layer::new(voxel_size);
    for b in 0..count {
        let o = 28 + b * BLOCK_BYTES;
        let i32_at = |o: usize| i32::from_le_bytes(body[o..o + 4].try_into().expect("4 bytes"));
        let index = [i32_at(o), i32_at(o + 4), i32_at(o + 8)];
        let mut block = Block::default();
        let voxels_end = o + 12 + VOXELS_PER_BLOCK * VOXEL_BYTES;
        for (v, chunk) in block
            .voxels
            .iter_mut()
            .zip(body[o + 12..voxels_end].chunks_exact(VOXEL_BYTES))
        {
            let f = |a: usize| f32::from_le_bytes(chunk[a..a + 4].try_into().expect("4 bytes"));
            *v = TsdfVoxel::new(f(0), f(4), [chunk[8], chunk[9], chunk[10]]);
        }
        for (l, chunk) in block
            .labels
            .iter_mut()
            .zip(body[voxels_end..o + BLOCK_BYTES].chunks_exact(LABEL_BYTES))
        {
            let h = |a: usize| u16::from_le_bytes(chunk[a..a + 2].try_into().expect("2 bytes"));
            *l = LabelVoxel {
                ids: [h(0), h(2)],
                counts: [h(4), h(6)],
            };
        }
        block.refresh_surface(voxel_size);
        if layer.blocks.insert(index, block).is_some() {
            return Err(invalid(path, format!("block {index:?} appears twice")));
        }
    }
    let instances = read_instances(&body[blocks_end..])
        .ok_or_else(|| invalid(path, "malformed instance table"))?;
    Ok(MapFile { layer, instances })
}

fn read_instances(bytes: &[u8]) -> Option<BTreeMap<u16, InstanceInfo>> {
    let mut at = 0usize;
    let mut take = |n: usize| {
        let s = bytes.get(at..at + n)?;
        at += n;
        Some(s)
    };
    let u32_of = |s: &[u8]| u32::from_le_bytes(s.try_into().expect("4 bytes"));
    let count = u32_of(take(4)?);
    let mut out = BTreeMap::new();
    for _ in 0..count {
        let id = u16::from_le_bytes(take(2)?.try_into().ok()?);
        let mut info = InstanceInfo {
            thing_votes: [u32_of(take(4)?), u32_of(take(4)?)],
            ..InstanceInfo::default()
        };
        for _ in 0..u32_of(take(4)?) {
            let class = u32_of(take(4)?);
            info.class_votes.insert(class, u32_of(take(4)?));
        }
        out.insert(id, info);
    }
    (at == bytes.len()).then_some(out)
}

/// Writes the map to `path` atomically (temporary file in the same folder, then rename).
pub fn save(
    layer: &Layer,
    instances: &BTreeMap<u16, InstanceInfo>,
    path: &Path,
) -> Result<(), MapFileError> {
    let io = |source| MapFileError::Io {
        path: path.to_owned(),
        source,
    };
    let tmp = path.with_extension("voxpan.tmp");
    let mut file = std::fs::File::create(&tmp).map_err(io)?;
    file.write_all(&to_bytes(layer, instances)).map_err(io)?;
    file.sync_all().map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Reads a map written by [`save`].
pub fn load(path: &Path) -> Result<MapFile, MapFileError> {
    let bytes = std::fs::read(path).map_err(|source| MapFileError::Io {
        path: path.to_owned(),
        source,
    })?;
    from_bytes(&bytes, path)
}
