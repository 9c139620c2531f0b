//! Groups of items the network segments one by one. A network trained on COCO names each
//! book; a map (and the flat's ground truth, `SM_Stack_of_Books_*`) holds a shelf's stack or
//! row as one object. Each frame's touching items of one group class become one segment
//! before association, so the items never read as objects told apart, and a row seen with
//! other items missed in other frames still continues one instance.

use voxpan_core::{DepthImage, LabelImage, Segment, is_valid_depth};

/// The frame's segments with the touching items of each group class joined: items of one
/// class (`is_group`) whose masks meet, with depths across the meeting no further apart than
/// `surface_step` (the truncation distance, within which integration fuses one surface),
/// become the segment of the smallest id among them (its score the highest of theirs).
/// `None` when nothing joins, so the frame is associated as given.
pub(crate) fn join_group_items(
    labels: &LabelImage,
    segments: &[Segment],
    depth: &DepthImage,
    surface_step: f32,
    is_group: impl Fn(u32) -> bool,
) -> Option<(LabelImage, Vec<Segment>)> {
    let items = segments
        .iter()
        .filter(|s| s.is_thing == Some(true) && s.class_id.is_some_and(&is_group))
        .count();
    if items < 2 || labels.dims() != depth.dims() {
        return None;
    }
    let top = segments.iter().map(|s| s.id as usize).max().unwrap_or(0);
    let mut class_of: Vec<Option<u32>> = vec![None; top + 1];
    for s in segments {
        if s.is_thing == Some(true)
            && let Some(class) = s.class_id.filter(|&c| is_group(c))
        {
            class_of[s.id as usize] = Some(class);
        }
    }
    let mut parent: Vec<u16> = (0..=top as u16).collect();
    let mut joined = false;
    let (width, height) = labels.dims();
    let (ids, z) = (labels.pixels(), depth.pixels());
    let group = |id: u16| class_of.get(id as usize).copied().flatten();
    for y in 0..height {
        for x in 0..width {
            let p = y * width + x;
            let a = ids[p];
            let Some(class) = group(a) else {
                continue;
            };
            for q in [
                (x + 1 < width).then_some(p + 1),
                (y + 1 < height).then_some(p + width),
            ]
            .into_iter()
            .flatten()
            {
                let b = ids[q];
                if b != a
                    && group(b) == Some(class)
                    && is_valid_depth(z[p])
                    && is_valid_depth(z[q])
                    && (z[p] - z[q]).abs() <= surface_step
                {
                    joined |= union(&mut parent, a, b);
                }
            }
        }
    }
    if !joined {
        return None;
    }
    let mut relabelled = labels.clone();
    for id in relabelled.pixels_mut() {
        if (*id as usize) <= top {
            *id = root(&parent, *id);
        }
    }
    let mut kept: Vec<Segment> = Vec::with_capacity(segments.len());
    for s in segments {
        let r = root(&parent, s.id);
        if r == s.id {
            kept.push(s.clone());
        }
    }
    for s in segments {
        let r = root(&parent, s.id);
        if r != s.id
            && let Some(k) = kept.iter_mut().find(|k| k.id == r)
        {
            k.score = match (k.score, s.score) {
                (Some(a), Some(b)) => Some(a.max(b)),
                (a, b) => a.or(b),
            };
        }
    }
    Some((relabelled, kept))
}

/// The smallest id of `id`'s set.
fn root(parent: &[u16], mut id: u16) -> u16 {
    while parent[id as usize] != id {
        id = parent[id as usize];
    }
    id
}

/// Joins the sets of `a` and `b` under the smaller root; whether they were apart.
fn union(parent: &mut [u16], a: u16, b: u16) -> bool {
    let (ra, rb) = (root(parent, a), root(parent, b));
    if ra == rb {
        return false;
    }
    parent[ra.max(rb) as usize] = ra.min(rb);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOOK: u32 = 7;
    const CUP: u32 = 3;

    fn thing(id: u16, class: u32, score: f32) -> Segment {
        Segment {
            id,
            class_id: Some(class),
            is_thing: Some(true),
            score: Some(score),
        }
    }

    /// A 6×2 image: columns hold segments `columns[x]` at depth `depths[x]`.
    fn frame(columns: [u16; 6], depths: [f32; 6]) -> (LabelImage, DepthImage) {
        (
            LabelImage::from_fn(6, 2, |x, _| columns[x]),
            DepthImage::from_fn(6, 2, |x, _| depths[x]),
        )
    }

    #[test]
    fn touching_books_become_one_segment_with_the_best_score() {
        let (labels, depth) = frame([1, 2, 2, 3, 0, 4], [1.0, 1.02, 1.02, 1.05, 0.0, 1.0]);
        let segments = [
            thing(1, BOOK, 0.5),
            thing(2, BOOK, 0.9),
            thing(3, BOOK, 0.4),
            thing(4, BOOK, 0.7),
        ];
        let (joined, kept) =
            join_group_items(&labels, &segments, &depth, 0.06, |c| c == BOOK).unwrap();
        assert_eq!(joined.row(0), &[1, 1, 1, 1, 0, 4]);
        assert_eq!(
            kept.iter().map(|s| (s.id, s.score)).collect::<Vec<_>>(),
            [(1, Some(0.9)), (4, Some(0.7))],
            "the book beyond the void column stays apart"
        );
    }

    #[test]
    fn items_at_different_depths_other_classes_and_stuff_stay_apart() {
        let (labels, depth) = frame([1, 2, 3, 4, 5, 5], [1.0, 1.5, 1.5, 1.5, 1.5, 1.5]);
        let mut stuff = thing(5, BOOK, 0.0);
        stuff.is_thing = Some(false);
        let segments = [
            thing(1, BOOK, 0.5),
            thing(2, BOOK, 0.5),
            thing(3, CUP, 0.5),
            thing(4, BOOK, 0.5),
            stuff,
        ];
        assert!(join_group_items(&labels, &segments, &depth, 0.06, |c| c == BOOK).is_none());
        let cups = [thing(1, CUP, 0.5), thing(2, CUP, 0.5)];
        let (labels, depth) = frame([1, 2, 0, 0, 0, 0], [1.0; 6]);
        assert!(
            join_group_items(&labels, &cups, &depth, 0.06, |c| c == BOOK).is_none(),
            "only group classes join"
        );
    }
}
