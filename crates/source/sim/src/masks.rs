//! Predicted masks with the errors a lightweight instance-segmentation network makes.

use std::collections::BTreeMap;

use voxpan_core::nalgebra::Point3;
use voxpan_core::{DepthImage, Intrinsics, LabelImage, Pose, Segment};

use crate::{Rand, Scene};

/// The error model: one strength per kind of error (0 = off, 1 = the strength voxpan's
/// synthetic figures use, 2 = worse). At 1 over-coverage is several times what Detectron2's
/// and YOLOv5s-seg's masks show on the flat sample; 0.1-0.2 matches them
/// (`tools/mask_purity.py`, docs/design/association.md).
///
/// The first five are the classic mix ([`MaskErrors::new`]). The last four are the failure
/// modes association meets in rooms it was not tuned on ([`MaskErrors::harder`]); their
/// decisions persist over [`PERSIST`] consecutive frames of a sequence, as a network repeats
/// its mistake on nearly the same view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskErrors {
    /// Things bleed `over_cover × 3..15` px onto the background behind and beside them.
    pub over_cover: f64,
    /// Boundary pixels flip to a neighbouring segment with probability `0.2 × jitter`.
    pub jitter: f64,
    /// About `2 × fragments` small spurious blobs of a random thing class per frame, each in
    /// one frame only.
    pub fragments: f64,
    /// The first two touching things predicted as one, in a share `0.3 × merges` of frames.
    pub merges: f64,
    /// Small things (under 400 px) missed with probability `0.5 × misses`.
    pub misses: f64,
    /// Class flicker: a segment takes a confusable class (chair and sofa, rug and floor, a
    /// table as the stuff `table-merged`) with probability `0.3 × flicker`.
    pub flicker: f64,
    /// A thing's mask cut across its longer side into two or three parts, with probability
    /// `0.3 × splits`.
    pub splits: f64,
    /// A group of small objects (books along a shelf board, one object of the ground truth)
    /// segmented item by item, with probability `0.5 × one_by_one`.
    pub one_by_one: f64,
    /// `4 × repeated_fragments` places on the scene's surfaces where the network sees a small
    /// thing that is not there, in about half the frames that see the place.
    pub repeated_fragments: f64,
    /// The stuff regions of one class in view predicted as one segment (two doors, two rugs,
    /// a door and a wall renamed `door`), in a share `min(1, stuff_per_class)` of frames. A
    /// panoptic network's fusion gives one segment per stuff class and image (Detectron2's
    /// masks of the flat sample never hold two of one class), so 1 is its format rather than
    /// an error of degree. Off in [`MaskErrors::harder`], which the figures measured before
    /// it use.
    pub stuff_per_class: f64,
}

/// Frames over which a harder mode's decision for one object holds.
pub const PERSIST: usize = 5;

/// Classes a network confuses with each class (see [`MaskErrors::flicker`]), by class id of
/// [`Scene::classes`].
fn confusions(class: u32) -> &'static [u32] {
    match class {
        0 => &[12],     // floor: rug
        1 => &[13],     // wall: door
        3 => &[14, 5],  // table: table-merged (stuff), shelf
        4 => &[6],      // chair: sofa
        6 => &[4],      // sofa: chair
        8 => &[9, 10],  // cup: ball, box
        9 => &[8],      // ball: cup
        10 => &[11, 8], // box: books, cup
        11 => &[10],    // books: box
        12 => &[0],     // rug: floor
        13 => &[1],     // door: wall
        _ => &[],
    }
}

/// The sequence a frame belongs to: what the harder modes need to make their errors persist
/// and to place repeated fragments in the world.
#[derive(Clone, Copy, Debug)]
pub struct SequenceFrame<'a> {
    pub seed: u64,
    pub index: usize,
    pub pose: &'a Pose,
    pub intrinsics: &'a Intrinsics,
}

/// What the renderer knows of a frame: true instances, which shape of its object each pixel
/// shows (1-based, 0 for none), and true depth.
#[derive(Clone, Copy, Debug)]
pub struct TrueView<'a> {
    pub instances: &'a LabelImage,
    pub parts: Option<&'a LabelImage>,
    pub depth: &'a DepthImage,
}

/// One predicted segment while the errors are made.
struct Predicted {
    class: u32,
    thing: bool,
    score: Option<f32>,
    /// The true instance it was predicted from (`None`: a fragment).
    source: Option<u16>,
}

/// Salts of the harder modes' random streams.
const FLICKER: u64 = 0x5f1c;
const SPLIT: u64 = 0x5b17;
const ONE_BY_ONE: u64 = 0x0b1b;
const SITES: u64 = 0x517e;

impl MaskErrors {
    /// The classic mix at `strength`; the harder modes off.
    pub fn new(strength: f64) -> Self {
        let s = strength.max(0.0);
        Self {
            over_cover: s,
            jitter: s,
            fragments: s,
            merges: s,
            misses: s,
            flicker: 0.0,
            splits: 0.0,
            one_by_one: 0.0,
            repeated_fragments: 0.0,
            stuff_per_class: 0.0,
        }
    }

    /// Every mode at `strength` but `stuff_per_class`.
    pub fn harder(strength: f64) -> Self {
        let s = strength.max(0.0);
        Self {
            flicker: s,
            splits: s,
            one_by_one: s,
            repeated_fragments: s,
            ..Self::new(s)
        }
    }

    /// Only over-coverage (for measuring refinement on exactly the error it targets).
    pub fn over_cover_only(strength: f64) -> Self {
        Self {
            over_cover: strength.max(0.0),
            ..Self::new(0.0)
        }
    }

    /// The modes by name, as `voxpan synth --error NAME=STRENGTH` spells them.
    pub const MODES: [&'static str; 10] = [
        "over-cover",
        "jitter",
        "fragments",
        "merges",
        "misses",
        "flicker",
        "splits",
        "one-by-one",
        "repeated-fragments",
        "stuff-per-class",
    ];

    /// The strength of mode `name` (one of [`Self::MODES`]).
    pub fn mode_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "over-cover" => &mut self.over_cover,
            "jitter" => &mut self.jitter,
            "fragments" => &mut self.fragments,
            "merges" => &mut self.merges,
            "misses" => &mut self.misses,
            "flicker" => &mut self.flicker,
            "splits" => &mut self.splits,
            "one-by-one" => &mut self.one_by_one,
            "repeated-fragments" => &mut self.repeated_fragments,
            "stuff-per-class" => &mut self.stuff_per_class,
            _ => return None,
        })
    }

    /// The largest bleed in pixels.
    pub fn max_bleed(&self) -> usize {
        (15.0 * self.over_cover).round() as usize
    }

    /// A network's label image and segment list for a frame whose true instances are
    /// `truth` (ids of `scene`) and true depth `depth`. Segment ids are shuffled per frame.
    pub fn predict(
        &self,
        truth: &LabelImage,
        depth: &DepthImage,
        scene: &Scene,
        rng: &mut Rand,
    ) -> (LabelImage, Vec<Segment>) {
        let (labels, segments, _) = self.predict_traced(truth, depth, scene, rng);
        (labels, segments)
    }

    /// Like [`MaskErrors::predict`], also returning, per segment, the true instance it was
    /// predicted from (`None` for spurious fragments).
    pub fn predict_traced(
        &self,
        truth: &LabelImage,
        depth: &DepthImage,
        scene: &Scene,
        rng: &mut Rand,
    ) -> (LabelImage, Vec<Segment>, Vec<Option<u16>>) {
        let view = TrueView {
            instances: truth,
            parts: None,
            depth,
        };
        self.predict_in_sequence(view, scene, rng, None)
    }

    /// The masks of frame `sequence` of a sequence (or of a lone frame: `None`, and then the
    /// harder modes draw afresh from `rng` in every frame, and make no repeated fragments).
    pub fn predict_in_sequence(
        &self,
        view: TrueView,
        scene: &Scene,
        rng: &mut Rand,
        sequence: Option<SequenceFrame>,
    ) -> (LabelImage, Vec<Segment>, Vec<Option<u16>>) {
        let truth = view.instances;
        let depth = view.depth;
        let (w, h) = truth.dims();
        let object_of: BTreeMap<u16, usize> = scene
            .objects
            .iter()
            .enumerate()
            .map(|(i, o)| (o.instance_id, i))
            .collect();
        // A harder mode's coin for one object: persistent within a sequence.
        let persistent = |salt: u64, id: u16, rng: &mut Rand| -> Rand {
            match sequence {
                Some(f) => Rand::stream(
                    f.seed ^ salt.wrapping_mul(0x2545_f491_4f6c_dd1d),
                    (u64::from(id) << 32) | (f.index / PERSIST) as u64,
                ),
                None => Rand::new(rng.index(0, usize::MAX) as u64),
            }
        };

        // Visible instances, their pixels and median depth.
        let mut pixels: BTreeMap<u16, Vec<usize>> = BTreeMap::new();
        for (i, &id) in truth.pixels().iter().enumerate() {
            if id != 0 {
                pixels.entry(id).or_default().push(i);
            }
        }
        // owner[i]: index into `segments`, or usize::MAX for void.
        let mut owner = vec![usize::MAX; w * h];
        let mut segments: Vec<Predicted> = Vec::new();
        let mut things: Vec<(usize, f32, u16)> = Vec::new();
        for (&id, list) in &pixels {
            let Some(&o) = object_of.get(&id) else {
                continue;
            };
            let object = &scene.objects[o];
            if object.is_thing
                && self.misses > 0.0
                && list.len() < 400
                && rng.chance((0.5 * self.misses).min(1.0))
            {
                continue; // missed: void
            }
            let score = object.is_thing.then(|| rng.range(0.55, 0.99) as f32);
            let (mut class, mut thing) = (object.class_id, object.is_thing);
            if self.flicker > 0.0 {
                let mut coin = persistent(FLICKER, id, rng);
                let options = confusions(class);
                if !options.is_empty() && coin.chance((0.3 * self.flicker).min(1.0)) {
                    class = options[coin.index(0, options.len())];
                    thing = Scene::classes()
                        .iter()
                        .find(|c| c.0 == class)
                        .is_some_and(|c| c.2);
                }
            }
            let first = segments.len();
            let new_segment = |segments: &mut Vec<Predicted>| {
                segments.push(Predicted {
                    class,
                    thing,
                    score: if thing { score.or(Some(0.6)) } else { None },
                    source: Some(id),
                });
                segments.len() - 1
            };
            new_segment(&mut segments);
            for &i in list {
                owner[i] = first;
            }
            // A group segmented item by item: one segment per shape of the object.
            let grouped = Scene::is_group(object.class_id)
                && self.one_by_one > 0.0
                && persistent(ONE_BY_ONE, id, rng).chance((0.5 * self.one_by_one).min(1.0));
            if let (true, Some(parts)) = (grouped, view.parts) {
                let mut of_part: BTreeMap<u16, usize> = BTreeMap::new();
                for &i in list {
                    let part = parts.pixels()[i];
                    let seg = match of_part.get(&part) {
                        Some(&seg) => seg,
                        None if of_part.is_empty() => first,
                        None => new_segment(&mut segments),
                    };
                    of_part.insert(part, seg);
                    owner[i] = seg;
                }
            } else if object.is_thing && self.splits > 0.0 {
                let mut coin = persistent(SPLIT, id, rng);
                if coin.chance((0.3 * self.splits).min(1.0)) {
                    split_across(list, w, &mut coin, &mut owner, first, || {
                        new_segment(&mut segments)
                    });
                }
            }
            if thing {
                let mut d: Vec<f32> = list.iter().map(|&i| depth.pixels()[i]).collect();
                d.sort_by(f32::total_cmp);
                let median = d[d.len() / 2];
                for seg in first..segments.len() {
                    things.push((seg, median, id));
                }
            }
        }

        if self.over_cover > 0.0 {
            let s = self.over_cover;
            // Far things first, so that a nearer thing's bleed wins where two overlap.
            things.sort_by(|a, b| b.1.total_cmp(&a.1));
            // Each segment grows from its own pixels (a split object's parts from theirs).
            let mut own: Vec<Vec<usize>> = vec![Vec::new(); segments.len()];
            for (i, &o) in owner.iter().enumerate() {
                if o != usize::MAX {
                    own[o].push(i);
                }
            }
            for &(seg, median, id) in &things {
                let r = (s * rng.range(3.0, 15.0)).round() as i64;
                let mut grown = Vec::new();
                for &i in &own[seg] {
                    let (x, y) = ((i % w) as i64, (i / w) as i64);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let (nx, ny) = (x + dx, y + dy);
                            if nx < 0
                                || ny < 0
                                || nx >= w as i64
                                || ny >= h as i64
                                || dx * dx + dy * dy > r * r
                            {
                                continue;
                            }
                            let j = ny as usize * w + nx as usize;
                            // Only the background: other surfaces behind the object's middle.
                            if truth.pixels()[j] != id && depth.pixels()[j] > median {
                                grown.push(j);
                            }
                        }
                    }
                }
                for j in grown {
                    owner[j] = seg;
                }
            }
        }

        if self.jitter > 0.0 {
            let before = owner.clone();
            for y in 1..h.saturating_sub(1) {
                for x in 1..w.saturating_sub(1) {
                    let i = y * w + x;
                    let neighbours = [i - 1, i + 1, i - w, i + w];
                    if let Some(&n) = neighbours.iter().find(|&&n| before[n] != before[i])
                        && rng.chance(0.2 * self.jitter)
                    {
                        owner[i] = before[n];
                    }
                }
            }
        }

        if self.merges > 0.0 && rng.chance((0.3 * self.merges).min(1.0)) {
            // Merge the first pair of touching things found.
            let thing_seg = |seg: usize| seg != usize::MAX && segments[seg].thing;
            'search: for y in 0..h {
                for x in 0..w.saturating_sub(1) {
                    let (a, b) = (owner[y * w + x], owner[y * w + x + 1]);
                    if a != b && thing_seg(a) && thing_seg(b) {
                        for o in owner.iter_mut().filter(|o| **o == b) {
                            *o = a;
                        }
                        break 'search;
                    }
                }
            }
        }

        let mut blob = |segments: &mut Vec<Predicted>,
                        (cx, cy): (i64, i64),
                        r: f64,
                        class: u32,
                        score: f32| {
            let seg = segments.len();
            segments.push(Predicted {
                class,
                thing: true,
                score: Some(score),
                source: None,
            });
            let ri = r.ceil() as i64;
            for dy in -ri..=ri {
                for dx in -ri..=ri {
                    let (x, y) = (cx + dx, cy + dy);
                    if x >= 0
                        && y >= 0
                        && x < w as i64
                        && y < h as i64
                        && ((dx * dx + dy * dy) as f64) <= r * r
                    {
                        owner[y as usize * w + x as usize] = seg;
                    }
                }
            }
        };
        let scale = (w as f64 / 640.0).max(0.25);
        if self.fragments > 0.0 {
            let count = (2.0 * self.fragments + rng.uniform()).floor() as usize;
            for _ in 0..count {
                let centre = (rng.index(0, w) as i64, rng.index(0, h) as i64);
                let r = rng.range(4.0, 12.0) * scale;
                let class = rng.index(3, 11) as u32;
                let score = rng.range(0.3, 0.6) as f32;
                blob(&mut segments, centre, r, class, score);
            }
        }
        if let (true, Some(frame)) = (self.repeated_fragments > 0.0, sequence) {
            for site in fragment_sites(scene, frame.seed, self.repeated_fragments) {
                let mut coin = Rand::stream(
                    frame.seed ^ SITES,
                    (site.index << 32) | (frame.index / PERSIST) as u64,
                );
                if !coin.chance(0.5) {
                    continue;
                }
                // The site as this camera sees it, if it is not hidden behind something.
                let local = frame.pose.inverse() * site.point;
                if local.z <= 0.1 {
                    continue;
                }
                let k = frame.intrinsics;
                let (u, v) = (
                    k.fx * local.x / local.z + k.cx,
                    k.fy * local.y / local.z + k.cy,
                );
                let (x, y) = (u.floor() as i64, v.floor() as i64);
                if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                    continue;
                }
                let seen = depth.pixels()[y as usize * w + x as usize] as f64;
                if (seen - local.z).abs() > 0.05 * local.z {
                    continue;
                }
                // Its size on the surface is fixed: nearer, it covers more pixels.
                let r = (site.radius * k.fx / local.z).max(1.5);
                blob(&mut segments, (x, y), r, site.class, 0.45);
            }
        }

        if self.stuff_per_class > 0.0 && rng.chance(self.stuff_per_class.min(1.0)) {
            join_stuff_by_class(&segments, &mut owner);
        }

        // Per-frame random ids for the segments that survived.
        let mut present = vec![false; segments.len()];
        for &o in &owner {
            if o != usize::MAX {
                present[o] = true;
            }
        }
        let survivors: Vec<usize> = (0..segments.len()).filter(|&i| present[i]).collect();
        let mut ids: Vec<u16> = (1..=survivors.len() as u16).collect();
        for i in (1..ids.len()).rev() {
            ids.swap(i, rng.index(0, i + 1));
        }
        let mut id_of = vec![0u16; segments.len()];
        for (k, &seg) in survivors.iter().enumerate() {
            id_of[seg] = ids[k];
        }
        let labels = LabelImage::from_vec(
            w,
            h,
            owner
                .iter()
                .map(|&o| if o == usize::MAX { 0 } else { id_of[o] })
                .collect(),
        )
        .expect("w*h pixels");
        let mut list: Vec<(Segment, Option<u16>)> = survivors
            .iter()
            .map(|&seg| {
                let p = &segments[seg];
                let segment = Segment {
                    id: id_of[seg],
                    class_id: Some(p.class),
                    is_thing: Some(p.thing),
                    score: p.score,
                };
                (segment, p.source)
            })
            .collect();
        list.sort_by_key(|(s, _)| s.id);
        let (list, sources) = list.into_iter().unzip();
        (labels, list, sources)
    }
}

/// Gives the pixels of every stuff segment (`owner`: segment per pixel, `usize::MAX` for
/// void) to the largest stuff segment of its class, as a panoptic network's fusion makes one
/// segment per stuff class; the others are left without pixels. The largest keeps its source.
fn join_stuff_by_class(segments: &[Predicted], owner: &mut [usize]) {
    let mut size = vec![0usize; segments.len()];
    for &o in owner.iter().filter(|&&o| o != usize::MAX) {
        size[o] += 1;
    }
    let mut largest: BTreeMap<u32, usize> = BTreeMap::new();
    for (k, p) in segments.iter().enumerate() {
        if !p.thing && size[k] > 0 {
            let keeper = largest.entry(p.class).or_insert(k);
            // Ties: the segment listed first.
            if size[k] > size[*keeper] {
                *keeper = k;
            }
        }
    }
    for o in owner.iter_mut().filter(|o| **o != usize::MAX) {
        if !segments[*o].thing {
            *o = largest[&segments[*o].class];
        }
    }
}

/// Cuts an object's pixels `list` (indices into an image `w` wide, all owned by segment
/// `first`) across the longer side of their bounding box into two or three parts; the parts
/// after the first go to segments made by `new_segment`.
fn split_across(
    list: &[usize],
    w: usize,
    coin: &mut Rand,
    owner: &mut [usize],
    first: usize,
    mut new_segment: impl FnMut() -> usize,
) {
    let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
    for &i in list {
        let p = [i % w, i / w];
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let axis = usize::from(hi[1] - lo[1] > hi[0] - lo[0]);
    let span = (hi[axis] - lo[axis]) as f64;
    if span < 4.0 {
        return;
    }
    let parts = 2 + coin.index(0, 2);
    let mut cuts: Vec<f64> = (1..parts)
        .map(|k| lo[axis] as f64 + span * (k as f64 + coin.range(-0.2, 0.2)) / parts as f64)
        .collect();
    cuts.sort_by(f64::total_cmp);
    let segs: Vec<usize> = std::iter::once(first)
        .chain((1..parts).map(|_| new_segment()))
        .collect();
    for &i in list {
        let c = [i % w, i / w][axis] as f64;
        owner[i] = segs[cuts.iter().filter(|&&cut| c >= cut).count()];
    }
}

/// A place where the network repeatedly sees a small thing that is not there.
struct Site {
    index: u64,
    point: Point3<f64>,
    /// Metres.
    radius: f64,
    class: u32,
}

/// `4 × strength` sites on the scene's surfaces (seeded by `seed`): where rays from the
/// middle of a room first meet a surface.
fn fragment_sites(scene: &Scene, seed: u64, strength: f64) -> Vec<Site> {
    let mut rng = Rand::stream(seed ^ SITES, u64::MAX);
    let count = (4.0 * strength).round() as usize;
    (0..count)
        .filter_map(|k| {
            let room = scene.rooms[rng.index(0, scene.rooms.len())];
            let origin = Point3::new(
                (room.min[0] + room.max[0]) / 2.0,
                (room.min[1] + room.max[1]) / 2.0,
                1.3,
            );
            let (azimuth, elevation) =
                (rng.range(0.0, std::f64::consts::TAU), rng.range(-0.6, 0.4));
            let dir = voxpan_core::nalgebra::Vector3::new(
                azimuth.cos() * elevation.cos(),
                azimuth.sin() * elevation.cos(),
                elevation.sin(),
            );
            let radius = rng.range(0.03, 0.08);
            let class = rng.index(3, 11) as u32;
            let hit = scene.intersect(&origin, &dir)?;
            Some(Site {
                index: k as u64,
                point: origin + dir * hit.t,
                radius,
                class,
            })
        })
        .collect()
}
