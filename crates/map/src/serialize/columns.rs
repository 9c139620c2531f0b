//! The block data of a version-3 map file, before compression: column by column, each
//! multi-byte number split into byte planes.
//!
//! 1. block indices, sorted, as differences from the previous block (3 × i32 planes);
//! 2. per block, a 512-bit mask of observed voxels (weight > 0); unobserved voxels are never
//!    written (integration leaves them at their defaults, so nothing is lost);
//! 3. for the observed voxels in block and voxel order: distance and weight (f32 planes),
//!    red, green, blue, and the two label slots (u16 planes).

use crate::layer::{Block, BlockIndex, LabelVoxel, Layer, TsdfVoxel, VOXELS_PER_BLOCK};

const MASK_BYTES: usize = VOXELS_PER_BLOCK / 8;
/// Bytes per observed voxel: distance, weight, colour, two (id, count) label slots.
const VOXEL_BYTES: usize = 4 + 4 + 3 + 8;

/// The payload of `blocks` blocks holding `observed` observed voxels.
pub(crate) fn encoded_len(blocks: usize, observed: usize) -> usize {
    blocks * (12 + MASK_BYTES) + observed * VOXEL_BYTES
}

/// The largest payload `blocks` blocks can encode to.
pub(crate) fn max_encoded_len(blocks: usize) -> usize {
    encoded_len(blocks, blocks * VOXELS_PER_BLOCK)
}

/// Appends the `N`-byte little-endian representations of `values` as `N` planes.
fn push_planes<const N: usize>(out: &mut Vec<u8>, values: &[[u8; N]]) {
    for plane in 0..N {
        out.extend(values.iter().map(|v| v[plane]));
    }
}

/// Reads `count` values of `N` bytes stored as planes.
fn read_planes<const N: usize>(bytes: &[u8], at: &mut usize, count: usize) -> Option<Vec<[u8; N]>> {
    let len = count.checked_mul(N)?;
    let planes = bytes.get(*at..*at + len)?;
    *at += len;
    Some(
        (0..count)
            .map(|i| std::array::from_fn(|p| planes[p * count + i]))
            .collect(),
    )
}

/// Encodes the blocks `indices` (sorted) of `layer`.
pub(crate) fn encode(layer: &Layer, indices: &[BlockIndex]) -> Vec<u8> {
    let blocks: Vec<&Block> = indices
        .iter()
        .map(|i| layer.get(i).expect("listed"))
        .collect();
    let mut out = Vec::new();
    let mut previous = [0i32; 3];
    let deltas: Vec<[i32; 3]> = indices
        .iter()
        .map(|i| {
            let d = std::array::from_fn(|a| i[a].wrapping_sub(previous[a]));
            previous = *i;
            d
        })
        .collect();
    for axis in 0..3 {
        let column: Vec<[u8; 4]> = deltas.iter().map(|d| d[axis].to_le_bytes()).collect();
        push_planes(&mut out, &column);
    }
    let mut observed: Vec<(TsdfVoxel, &LabelVoxel)> = Vec::new();
    for block in &blocks {
        let mut mask = [0u8; MASK_BYTES];
        for (i, (v, l)) in block.voxels.iter().zip(block.labels.iter()).enumerate() {
            if v.observed() {
                mask[i / 8] |= 1 << (i % 8);
                observed.push((v, l));
            }
        }
        out.extend_from_slice(&mask);
    }
    let column = |f: &dyn Fn(&(TsdfVoxel, &LabelVoxel)) -> [u8; 4]| -> Vec<[u8; 4]> {
        observed.iter().map(f).collect()
    };
    push_planes(&mut out, &column(&|(v, _)| layer.distance(v).to_le_bytes()));
    push_planes(&mut out, &column(&|(v, _)| v.weight().to_le_bytes()));
    for channel in 0..3 {
        out.extend(observed.iter().map(|(v, _)| v.color()[channel]));
    }
    for slot in 0..2 {
        let ids: Vec<[u8; 2]> = observed
            .iter()
            .map(|(_, l)| l.ids()[slot].to_le_bytes())
            .collect();
        let counts: Vec<[u8; 2]> = observed
            .iter()
            .map(|(_, l)| l.counts()[slot].to_le_bytes())
            .collect();
        push_planes(&mut out, &ids);
        push_planes(&mut out, &counts);
    }
    out
}

/// Fills `layer` with the `blocks` blocks encoded in `bytes`; the error says what is wrong.
pub(crate) fn decode(bytes: &[u8], blocks: usize, layer: &mut Layer) -> Result<(), String> {
    let mut at = 0;
    let truncated = || "truncated".to_owned();
    let mut axes: Vec<Vec<i32>> = Vec::with_capacity(3);
    for _ in 0..3 {
        let column = read_planes::<4>(bytes, &mut at, blocks).ok_or_else(truncated)?;
        axes.push(column.into_iter().map(i32::from_le_bytes).collect());
    }
    let mut previous = [0i32; 3];
    let indices: Vec<BlockIndex> = (0..blocks)
        .map(|b| {
            let index = std::array::from_fn(|a| previous[a].wrapping_add(axes[a][b]));
            previous = index;
            index
        })
        .collect();
    let masks = bytes
        .get(at..at + blocks * MASK_BYTES)
        .ok_or_else(truncated)?;
    at += blocks * MASK_BYTES;
    let observed: usize = masks.iter().map(|m| m.count_ones() as usize).sum();
    let distance = read_planes::<4>(bytes, &mut at, observed).ok_or_else(truncated)?;
    let weight = read_planes::<4>(bytes, &mut at, observed).ok_or_else(truncated)?;
    let mut color = Vec::with_capacity(3);
    for _ in 0..3 {
        color.push(bytes.get(at..at + observed).ok_or_else(truncated)?);
        at += observed;
    }
    let mut slots = Vec::with_capacity(4);
    for _ in 0..4 {
        let column = read_planes::<2>(bytes, &mut at, observed).ok_or_else(truncated)?;
        slots.push(
            column
                .into_iter()
                .map(u16::from_le_bytes)
                .collect::<Vec<_>>(),
        );
    }
    if at != bytes.len() {
        return Err(format!("{} bytes left over", bytes.len() - at));
    }
    let mut k = 0;
    for (b, index) in indices.into_iter().enumerate() {
        let mut block = Block::default();
        let mask = &masks[b * MASK_BYTES..(b + 1) * MASK_BYTES];
        for i in 0..VOXELS_PER_BLOCK {
            if mask[i / 8] >> (i % 8) & 1 == 0 {
                continue;
            }
            let (d, w) = (
                f32::from_le_bytes(distance[k]),
                f32::from_le_bytes(weight[k]),
            );
            if !(d.is_finite() && w.is_finite() && w > 0.0) {
                return Err(format!(
                    "voxel {i} of block {index:?}: distance {d}, weight {w}"
                ));
            }
            let voxel = layer.voxel(d, w, [color[0][k], color[1][k], color[2][k]]);
            block.voxels.set(i, voxel);
            block.labels[i] =
                LabelVoxel::from_parts([slots[0][k], slots[2][k]], [slots[1][k], slots[3][k]]);
            k += 1;
        }
        if layer.insert(index, block).is_some() {
            return Err(format!("block {index:?} appears twice"));
        }
    }
    Ok(())
}
