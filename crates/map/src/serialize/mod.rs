//! The map file: `VOXPANMP`, a format version, the voxel size, the map's configuration, the
//! instance table, and the blocks, compressed, then a CRC-32 of everything before it. Written
//! to a temporary file and renamed, so a crash never leaves a half-written map; a truncated
//! or corrupted file is rejected, never half-loaded.
//!
//! Versions 3 and 4 (4 written now) store only observed voxels, column by column with the
//! bytes of each number split into planes (exponents next to exponents, so the compressor
//! finds the redundancy that interleaved records hide), deflate-compressed in chunks of 4096
//! blocks (written and read one chunk at a time); version 4 adds each instance's shell
//! evidence. Version 2 (raw 20-byte voxels, no configuration) is still read.

mod columns;
mod cursor;

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use voxpan_io::IoError;

use cursor::Cursor;

use crate::MapConfig;
use crate::associate::InstanceInfo;
use crate::layer::{Block, LabelVoxel, Layer, TsdfVoxel, VOXELS_PER_BLOCK};

const MAGIC: &[u8; 8] = b"VOXPANMP";
const VERSION: u32 = 4;

/// Why a map file could not be read or written: the file's [`IoError`].
pub type MapFileError = IoError;

fn invalid(path: &Path, message: impl Into<String>) -> MapFileError {
    IoError::format(path, message)
}

/// A map as stored.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StoredMap {
    pub config: MapConfig,
    pub layer: Layer,
    pub instances: BTreeMap<u16, InstanceInfo>,
    pub class_names: BTreeMap<u32, String>,
}

/// Deflate level of the blocks. Saving is on the path a robot waits on (shutdown, the save
/// service). Measured on the flat map (2 cm, 8,279 blocks): level 6 takes 0.86-0.92 s and
/// writes 10.9 MB, level 3 0.52-0.55 s and 11.1 MB, level 1 0.18-0.24 s and 12.2 MB: a
/// quarter of the time for 12 % more bytes.
const DEFLATE_LEVEL: u8 = 1;

/// Blocks per compressed chunk: writing and reading hold one chunk uncompressed at a time
/// (at most ~40 MB, usually a few), never the whole map.
const CHUNK_BLOCKS: usize = 4096;

/// Passes bytes through, keeping their CRC-32.
struct CrcWriter<'a> {
    inner: &'a mut dyn Write,
    crc: crc32fast::Hasher,
}

impl Write for CrcWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Writes a map file into `out`, chunk by chunk (blocks in a fixed order, so equal maps give
/// equal files).
pub(crate) fn write_to(
    out: &mut dyn Write,
    config: &MapConfig,
    layer: &Layer,
    instances: &BTreeMap<u16, InstanceInfo>,
    class_names: &BTreeMap<u32, String>,
) -> std::io::Result<()> {
    let mut out = CrcWriter {
        inner: out,
        crc: crc32fast::Hasher::new(),
    };
    let mut head = Vec::new();
    head.extend_from_slice(MAGIC);
    head.extend_from_slice(&VERSION.to_le_bytes());
    head.extend_from_slice(&layer.voxel_size().to_le_bytes());
    let config = toml::to_string(config).expect("plain data");
    head.extend_from_slice(&(config.len() as u32).to_le_bytes());
    head.extend_from_slice(config.as_bytes());
    write_instances(&mut head, instances);
    head.extend_from_slice(&(class_names.len() as u32).to_le_bytes());
    for (class, name) in class_names {
        head.extend_from_slice(&class.to_le_bytes());
        head.extend_from_slice(&(name.len() as u32).to_le_bytes());
        head.extend_from_slice(name.as_bytes());
    }
    let indices = layer.sorted_indices();
    head.extend_from_slice(&(indices.len() as u64).to_le_bytes());
    head.extend_from_slice(&(indices.len().div_ceil(CHUNK_BLOCKS) as u32).to_le_bytes());
    out.write_all(&head)?;
    for chunk in indices.chunks(CHUNK_BLOCKS) {
        let payload = columns::encode(layer, chunk);
        let compressed = miniz_oxide::deflate::compress_to_vec(&payload, DEFLATE_LEVEL);
        out.write_all(&(chunk.len() as u32).to_le_bytes())?;
        out.write_all(&(payload.len() as u64).to_le_bytes())?;
        out.write_all(&(compressed.len() as u64).to_le_bytes())?;
        out.write_all(&compressed)?;
    }
    let crc = out.crc.finalize();
    out.inner.write_all(&crc.to_le_bytes())
}

/// Serialises a map into memory (what [`write_to`] writes).
pub(crate) fn to_bytes(
    config: &MapConfig,
    layer: &Layer,
    instances: &BTreeMap<u16, InstanceInfo>,
    class_names: &BTreeMap<u32, String>,
) -> Vec<u8> {
    let mut out = Vec::new();
    write_to(&mut out, config, layer, instances, class_names).expect("writing to memory");
    out
}

/// An upper bound of the file's size: every chunk stored uncompressed.
pub(crate) fn size_bound(layer: &Layer) -> u64 {
    let observed: usize = layer
        .iter()
        .map(|(_, b)| b.voxels.iter().filter(|v| v.observed()).count())
        .sum();
    4096 + columns::encoded_len(layer.len(), observed) as u64
        + 20 * (layer.len() / CHUNK_BLOCKS + 1) as u64
}

fn write_instances(out: &mut Vec<u8>, instances: &BTreeMap<u16, InstanceInfo>) {
    out.extend_from_slice(&(instances.len() as u32).to_le_bytes());
    for (id, info) in instances {
        out.extend_from_slice(&id.to_le_bytes());
        out.extend_from_slice(&info.thing_votes[0].to_le_bytes());
        out.extend_from_slice(&info.thing_votes[1].to_le_bytes());
        out.extend_from_slice(&info.frames_seen.to_le_bytes());
        out.push(info.confirmed as u8);
        out.extend_from_slice(&info.shell_covered.to_le_bytes());
        out.extend_from_slice(&info.smallest_matched_view.to_le_bytes());
        out.extend_from_slice(&(info.class_votes.len() as u32).to_le_bytes());
        for (class, votes) in &info.class_votes {
            out.extend_from_slice(&class.to_le_bytes());
            out.extend_from_slice(&votes.to_le_bytes());
        }
    }
}

/// What an instance record holds, by format version.
#[derive(Clone, Copy, PartialEq, PartialOrd)]
enum InstanceRecord {
    /// Version 2: votes only.
    Votes,
    /// Version 3: also frames seen and whether confirmed.
    Observations,
    /// Version 4: also the shell's covers and the smallest matched view.
    Evidence,
}

fn read_instances(c: &mut Cursor, record: InstanceRecord) -> Option<BTreeMap<u16, InstanceInfo>> {
    let count = c.u32()?;
    let mut out = BTreeMap::new();
    for _ in 0..count {
        let id = c.u16()?;
        let mut info = InstanceInfo {
            thing_votes: [c.u32()?, c.u32()?],
            ..InstanceInfo::default()
        };
        if record >= InstanceRecord::Observations {
            info.frames_seen = c.u32()?;
            info.confirmed = match c.bytes(1)?[0] {
                0 => false,
                1 => true,
                _ => return None,
            };
        } else {
            // Version 2 showed every instance.
            info.confirmed = true;
        }
        if record == InstanceRecord::Evidence {
            info.shell_covered = c.u32()?;
            info.smallest_matched_view = c.u32()?;
        }
        for _ in 0..c.u32()? {
            let class = c.u32()?;
            info.class_votes.insert(class, c.u32()?);
        }
        if out.insert(id, info).is_some() {
            return None;
        }
    }
    Some(out)
}

/// Parses a map file's bytes; `path` is only used in messages.
pub(crate) fn from_bytes(bytes: &[u8], path: &Path) -> Result<StoredMap, MapFileError> {
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err(invalid(path, "not a voxpan map (bad magic or too short)"));
    }
    let (body, tail) = bytes.split_at(bytes.len() - 4);
    let stored = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
    if crc32fast::hash(body) != stored {
        return Err(invalid(
            path,
            "checksum mismatch: the file is corrupted or truncated",
        ));
    }
    let mut c = Cursor::new(&body[8..]);
    let version = c.u32().expect("checked length");
    let voxel_size = c.f64().ok_or_else(|| invalid(path, "truncated header"))?;
    if !(voxel_size.is_finite() && voxel_size > 0.0) {
        return Err(invalid(path, format!("invalid voxel size {voxel_size}")));
    }
    match version {
        2 => read_v2(&mut c, voxel_size, path),
        3 => read_columnar(&mut c, voxel_size, path, InstanceRecord::Observations),
        4 => read_columnar(&mut c, voxel_size, path, InstanceRecord::Evidence),
        other => Err(invalid(
            path,
            format!(
                "map format version {other}; this voxpan reads versions 2 to 4{}",
                if other > VERSION {
                    " (the file is from a newer voxpan)"
                } else {
                    ""
                }
            ),
        )),
    }
}

/// Versions 3 and 4, which differ only in the instance `record`.
fn read_columnar(
    c: &mut Cursor,
    voxel_size: f64,
    path: &Path,
    record: InstanceRecord,
) -> Result<StoredMap, MapFileError> {
    let config_len = c.u32().ok_or_else(|| invalid(path, "truncated header"))? as usize;
    let config_text = c
        .bytes(config_len)
        .and_then(|b| std::str::from_utf8(b).ok())
        .ok_or_else(|| invalid(path, "malformed configuration"))?;
    let config: MapConfig = toml::from_str(config_text)
        .map_err(|e| invalid(path, format!("malformed configuration: {e}")))?;
    if config.tsdf.voxel_size != voxel_size {
        return Err(invalid(
            path,
            "the configuration's voxel size differs from the file's",
        ));
    }
    // The same checks as a map built from it gets (the layer needs a usable truncation band),
    // but here the message names the file.
    config
        .validate()
        .map_err(|e| invalid(path, format!("invalid configuration: {e}")))?;
    let instances =
        read_instances(c, record).ok_or_else(|| invalid(path, "malformed instance table"))?;
    let class_names = read_class_names(c).ok_or_else(|| invalid(path, "malformed class names"))?;
    let truncated = || invalid(path, "truncated block data");
    let blocks = c.u64().ok_or_else(truncated)? as usize;
    let chunks = c.u32().ok_or_else(truncated)? as usize;
    if chunks != blocks.div_ceil(CHUNK_BLOCKS) {
        return Err(invalid(
            path,
            format!("{chunks} chunks for {blocks} blocks"),
        ));
    }
    let mut layer = Layer::new(voxel_size, config.tsdf.truncation());
    for _ in 0..chunks {
        let (count, raw_len, compressed_len) = (
            c.u32().ok_or_else(truncated)? as usize,
            c.u64().ok_or_else(truncated)?,
            c.u64().ok_or_else(truncated)?,
        );
        if count == 0 || count > CHUNK_BLOCKS {
            return Err(invalid(path, format!("a chunk of {count} blocks")));
        }
        let compressed = c.bytes(compressed_len as usize).ok_or_else(truncated)?;
        // The raw size is bounded by the block count: a corrupt file cannot inflate it.
        let limit = columns::max_encoded_len(count);
        if raw_len as usize > limit {
            return Err(invalid(path, "block data larger than its blocks can need"));
        }
        let payload = miniz_oxide::inflate::decompress_to_vec_with_limit(compressed, limit)
            .map_err(|e| invalid(path, format!("block data does not decompress: {e:?}")))?;
        if payload.len() as u64 != raw_len {
            return Err(invalid(path, "block data has the wrong length"));
        }
        columns::decode(&payload, count, &mut layer)
            .map_err(|why| invalid(path, format!("malformed block data: {why}")))?;
    }
    if !c.is_empty() || layer.len() != blocks {
        return Err(invalid(path, "block data length does not match the file"));
    }
    Ok(StoredMap {
        config,
        layer,
        instances,
        class_names,
    })
}

fn read_class_names(c: &mut Cursor) -> Option<BTreeMap<u32, String>> {
    let mut out = BTreeMap::new();
    for _ in 0..c.u32()? {
        let class = c.u32()?;
        let len = c.u32()? as usize;
        let name = std::str::from_utf8(c.bytes(len)?).ok()?;
        out.insert(class, name.to_owned());
    }
    Some(out)
}

/// Version 2: raw blocks (12-byte TSDF voxels, 8-byte label voxels), then the instance table.
fn read_v2(c: &mut Cursor, voxel_size: f64, path: &Path) -> Result<StoredMap, MapFileError> {
    let count = c.u64().ok_or_else(|| invalid(path, "truncated header"))? as usize;
    const BLOCK_BYTES: usize = 12 + VOXELS_PER_BLOCK * 20;
    if count
        .checked_mul(BLOCK_BYTES)
        .is_none_or(|n| n > c.remaining())
    {
        return Err(invalid(
            path,
            format!("{count} blocks announced, {} bytes present", c.remaining()),
        ));
    }
    // Version 2 stored no configuration: it loads with the default one, so its distances are
    // held in the default truncation band (a map built with a wider band keeps its surface;
    // its far voxels clamp to the band).
    let mut config = MapConfig::default();
    config.tsdf.voxel_size = voxel_size;
    let mut layer = Layer::new(voxel_size, config.tsdf.truncation());
    for _ in 0..count {
        let truncated = || invalid(path, "truncated block");
        let index = [
            c.i32().ok_or_else(truncated)?,
            c.i32().ok_or_else(truncated)?,
            c.i32().ok_or_else(truncated)?,
        ];
        let mut block = Block::default();
        for i in 0..block.voxels.len() {
            let (d, w) = (
                c.f32().ok_or_else(truncated)?,
                c.f32().ok_or_else(truncated)?,
            );
            let rgba = c.bytes(4).ok_or_else(truncated)?;
            // Version 2 wrote every voxel, unobserved ones with weight 0; anything not positive
            // (NaN included) is unobserved, as it was when weights were f32.
            let voxel = if w > 0.0 {
                layer.voxel(d, w, [rgba[0], rgba[1], rgba[2]])
            } else {
                TsdfVoxel::default()
            };
            block.voxels.set(i, voxel);
        }
        for l in block.labels.iter_mut() {
            let mut h = [0u16; 4];
            for x in &mut h {
                *x = c.u16().ok_or_else(truncated)?;
            }
            *l = LabelVoxel::from_parts([h[0], h[1]], [h[2], h[3]]);
        }
        if layer.insert(index, block).is_some() {
            return Err(invalid(path, format!("block {index:?} appears twice")));
        }
    }
    let instances = read_instances(c, InstanceRecord::Votes)
        .filter(|_| c.is_empty())
        .ok_or_else(|| invalid(path, "malformed instance table"))?;
    Ok(StoredMap {
        config,
        layer,
        instances,
        class_names: BTreeMap::new(),
    })
}

/// Writes the map to `path` atomically.
pub(crate) fn save(
    path: &Path,
    config: &MapConfig,
    layer: &Layer,
    instances: &BTreeMap<u16, InstanceInfo>,
    class_names: &BTreeMap<u32, String>,
) -> Result<(), MapFileError> {
    voxpan_io::write_atomically(path, |out| {
        write_to(out, config, layer, instances, class_names)
    })
}

/// Reads a map written by [`save`] (or by an older voxpan, format version 2).
/// The format version of the map file at `path`, from its first 12 bytes; `None` when the
/// file does not begin as a voxpan map does.
pub fn map_file_version(path: &Path) -> Result<Option<u32>, MapFileError> {
    use std::io::Read;
    let mut head = [0u8; 12];
    let mut file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let mut filled = 0;
    while filled < head.len() {
        match file.read(&mut head[filled..]) {
            Ok(0) => return Ok(None),
            Ok(n) => filled += n,
            Err(e) => return Err(IoError::io(path, e)),
        }
    }
    Ok((&head[..8] == MAGIC).then(|| u32::from_le_bytes([head[8], head[9], head[10], head[11]])))
}

pub(crate) fn load(path: &Path) -> Result<StoredMap, MapFileError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    from_bytes(&bytes, path)
}

#[cfg(test)]
mod tests;
