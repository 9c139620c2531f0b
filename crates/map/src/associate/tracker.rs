//! Instance tracking: per-frame segment ids mean nothing across frames, so each frame's
//! segments are matched to the map's instances.
//!
//! Evidence: for every sampled pixel, the instance label of the voxel its measured depth lands
//! in ([`observe`](super::observe)), past the integration range too (there the map holds what
//! closer frames left). Pixels are sampled on a coarse grid (`downscale`), except that a
//! segment too small for the grid to give it 16 samples reads every pixel of its own. For a
//! segment `s`: `a(s)` samples with a measurement, `o(s, i)` of them
//! on instance `i`, `m(s)` on any instance; for an instance: `r(i)` samples on it in the whole
//! frame.
//!
//! The rule (panoptic_mapping's projective tracking and Voxblox++'s voxel votes, with what the
//! flat and synthetic measurements showed):
//! - Books (see [`GROUPS`]) stand in rows a network segments book by book and a map holds
//!   as one object (the flat's ground truth labels each stack): before anything else, each
//!   frame's touching segments of such a class, with depths across the seam within the
//!   truncation distance, become one segment (see [`join_group_items`]). Such a segment
//!   also takes thing instances of other names it covers as its parts, and votes to merge
//!   them (see `gathers`): the row's books the network named `box` in other views.
//! - Segments only match instances of their kind; stuff only stuff of its class family
//!   (`wall`, `wall-brick`: see [`class_families`]), things of their class when
//!   `class_aware_things`.
//! - Stuff the map's voxels do not vouch for (seen where the map holds none of it yet) is
//!   spatial. The building's shell (`wall`, `floor`, `ceiling` families: one connected
//!   surface through every room) continues its family's instance: a wall seen in pieces stays
//!   one, as panoptic segmentation treats stuff and both ground truths agree. Other stuff (a
//!   door, a rug, a cabinet) continues only a same-family stuff instance whose surface lies
//!   in or beside the blocks the segment lands in ([`Surface::instances_near`]), else founds
//!   its own: two doors metres apart stay two. Either way, not an instance another segment
//!   of the same frame already continues (the largest goes first): then the segmenter says
//!   these are two regions (flat's TV wall beside its walls).
//! - A segment matches the compatible instance holding most of its mapped samples, when that
//!   instance holds at least `min_overlap` (½) of them. A thing must also explain most of
//!   the segment or most of the instance's visible part (`o ≥ ½ min(a, r)`): a new chair
//!   whose rim touches its neighbour does not become the neighbour. Stuff needs no more: a
//!   wall extending into unmapped space stays the wall.
//! - A non-shell stuff segment gives its instance only the pieces of its mask (4-connected
//!   in the image) that belong to it (see `detached_pieces`): one segment per stuff class
//!   also covers the other door in view, apart from this one.
//! - A segment no instance of its class takes may continue an instance of another class
//!   of its kind when the two cover each other (see `renamed`): networks rename objects and
//!   surfaces between frames (chair and toilet, bed and couch; floor and rug, wall and door),
//!   and each renaming founded an instance. A thing instance must also be unconfirmed or
//!   have been seen as the segment's class before; stuff must be explained as a whole, so a
//!   rug on the floor, which covers only part of it, founds its own instance. Stuff of
//!   another family lying on the shell where no other segment of the frame continues the
//!   shell is the shell under another name, new surface or not (see `match_renamed_shell`).
//! - Several segments may match one instance (a network splits walls and large objects).
//!   A thing segment that no instance holds most of, but whose compatible instances it
//!   covers most of together do, continues the largest of them (see `parts`): an object
//!   first segmented in pieces, then whole. A thing segment nothing vouches for that meets a
//!   segment of its class mostly across one continuous surface continues that segment's
//!   instance (see [`continue_cut_pieces`]): the network cut one object, and the piece lies
//!   where the map does not hold that object yet. Not where the map holds the piece itself as
//!   an object of another name (see `held_as_other`).
//! - Evidence per pair of instances: how often one segment covered most of both (a vote to
//!   merge) and how often the segmenter told them apart (each matched by its own segment,
//!   the two touching in the image; for two things of one class, anywhere in the frame
//!   where both are seen within the integration range).
//!   They merge after `merge_votes` (2) votes from different frames, when covered together
//!   more often than told apart (the older id stays). Two things of one class whose masks
//!   meet across one continuous surface, or are linked through a chain of such cuts, are not
//!   told apart: that is the network cutting an object. Splitting is never done: merges are
//!   rarer mistakes than splits. Only samples within the integration range vote (past it
//!   depth is noisy).
//! - Unmatched segments of at least `min_pixels` (8) with depth within the range found a new
//!   instance; smaller ones are not integrated. An instance is shown (meshes, instance lists,
//!   scores) once segments were matched to it in `min_observations` (2) frames: one-frame
//!   fragments stay hidden. (The map also hides instances too small, scattered, or overruled
//!   by a thing: see `PanopticMap::judge_instances`.)
//! - Stuff never overwrites a flush thing the network missed: stuff pixels that land on the
//!   voxels of a thing instance lying flush with its surroundings (see
//!   [`InstanceTracker::is_flush`]) that no segment of the frame continues are not integrated
//!   as stuff. Refinement cuts stuff masks off things standing clear of them, so stuff
//!   pixels on such a thing's voxels are its earlier masks' bleed and take them back; so
//!   they do where a segment continues the thing, outside that segment.
//! - A voxel holds two candidates; where the leader is stuff the segment cannot be, the
//!   sample speaks for the runner-up (see `support`): a thing first mapped as part of its
//!   wall keeps one instance until it leads. A shown thing whose masks' outlines lie mostly
//!   flush with their surroundings (see [`InstanceTracker::is_flush`]) takes the lead of the
//!   stuff-led voxels under the inside of its mask (see `super::claims`): otherwise the wall's
//!   masks of every frame that missed a picture outvote the picture's own.
//! - After the last frame the map is read whole (see [`InstanceTracker::consolidate`]):
//!   instances meeting along a seam join unless frames told them apart more often than they
//!   covered them together (for a thing and a stuff instance, also counting the masks of
//!   one that covered the other renamed). First, an instance seen in one frame only, founded
//!   by a segment that covered a settled thing of another class each way, joins that thing:
//!   one view's other name for it.

use std::collections::BTreeMap;

use rustc_hash::FxHashMap;

use voxpan_core::{LabelImage, Segment, label_runs};

use super::groups::join_group_items;
use super::observe::{Observation, Sample, Surface, count_on};
use crate::TrackingConfig;
use crate::layer::{BlockIndex, with_neighbours};

/// What the map knows about an instance.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct InstanceInfo {
    /// Votes per class id.
    pub class_votes: BTreeMap<u32, u32>,
    /// Votes for "thing" and "stuff".
    pub thing_votes: [u32; 2],
    /// Frames in which a segment was assigned to the instance.
    pub frames_seen: u32,
    /// Shown in outputs: re-observed often enough, or given by an identified segmentation.
    pub confirmed: bool,
    /// Frames in which no segment matched the instance while a segment of the building's
    /// shell (wall, floor, ceiling) covered most of it in view, seen at least as large as in
    /// a frame that matched it: the network saying the place is the wall.
    pub shell_covered: u32,
    /// The fewest samples the instance led in a frame that matched it (0: not yet known).
    pub smallest_matched_view: u32,
}

impl InstanceInfo {
    /// The most voted class (ties: the smallest id).
    pub fn class(&self) -> Option<u32> {
        self.class_votes
            .iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            .map(|(c, _)| *c)
    }

    pub fn is_thing(&self) -> bool {
        self.thing_votes[0] >= self.thing_votes[1] && self.thing_votes[0] > 0
    }

    /// Whether the frames say the instance is there: a thing must have been matched in more
    /// frames than the shell's segments covered it unmatched. A place where the network
    /// sees a small thing in some views and the wall in the others is not an object.
    pub fn earned(&self) -> bool {
        !self.is_thing() || self.frames_seen > self.shell_covered
    }

    /// Keeps `view` (samples led in a matched frame; 0: unknown) if it is the smallest known.
    fn note_matched_view(&mut self, view: u32) {
        if view > 0 && (self.smallest_matched_view == 0 || view < self.smallest_matched_view) {
            self.smallest_matched_view = view;
        }
    }

    /// Thing or stuff, when any segment said.
    pub(crate) fn kind(&self) -> Option<bool> {
        (self.thing_votes != [0, 0]).then(|| self.is_thing())
    }

    fn vote(&mut self, segment: &Segment) {
        if let Some(class) = segment.class_id {
            *self.class_votes.entry(class).or_default() += 1;
        }
        match segment.is_thing {
            Some(true) => self.thing_votes[0] += 1,
            Some(false) => self.thing_votes[1] += 1,
            None => {}
        }
    }

    fn absorb(&mut self, other: InstanceInfo) {
        for (class, votes) in other.class_votes {
            *self.class_votes.entry(class).or_default() += votes;
        }
        self.thing_votes[0] += other.thing_votes[0];
        self.thing_votes[1] += other.thing_votes[1];
        self.frames_seen += other.frames_seen;
        self.shell_covered += other.shell_covered;
        self.note_matched_view(other.smallest_matched_view);
        self.confirmed |= other.confirmed;
    }
}

/// What frames said about two instances: how often one segment covered both (most of the
/// other's visible part: the same object), and how often the segmenter told them apart (each
/// matched by its own segment; see [`InstanceTracker::record_apart`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct PairEvidence {
    together: u32,
    apart: u32,
    /// Frames in which a segment matched to one of the two covered most of the other, though
    /// the two could not merge frame by frame (of other classes or kinds), where that may say
    /// the other is the same object renamed (see [`InstanceTracker::says_renamed`]).
    together_renamed: u32,
    /// Of the `together` frames, those in which only a group's segment covered both, one of
    /// them of another name (see [`InstanceTracker::gathers`]).
    gathered: u32,
    /// Frames in which a segment that founded one of the two covered the other, a settled
    /// thing of another class, each way (see [`InstanceTracker::renamed`]): that thing under
    /// another name, if the new instance is never seen again.
    founded_over: u32,
}

/// What one frame's association did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct AssociationStats {
    /// Segments matched to an existing instance.
    pub matched: usize,
    /// Segments that founded a new instance.
    pub created: usize,
    /// Segments left out (too small to found an instance, or no instance id left).
    pub unassigned: usize,
    /// Instances merged into another this frame.
    pub merged: usize,
    /// Segments that would have founded an instance, but every 16-bit instance id is taken
    /// (counted in `unassigned` too; their voxels keep geometry and colour).
    pub out_of_ids: usize,
}

/// The frame's segments as map instances.
pub(crate) struct Assignment {
    /// Map instance per pixel (0 where nothing is integrated), at the labels' resolution.
    pub instances: LabelImage,
    pub stats: AssociationStats,
    /// `(from, into)`: instances to relabel in the map before integrating.
    pub merges: Vec<(u16, u16)>,
}

/// Keeps map instances and assigns frame segments to them.
#[derive(Clone, Debug, Default)]
pub(crate) struct InstanceTracker {
    pub config: TrackingConfig,
    pub instances: BTreeMap<u16, InstanceInfo>,
    next_id: u16,
    /// What frames said about each pair of instances `(older, younger)`.
    pairs: BTreeMap<(u16, u16), PairEvidence>,
    /// Per instance, its segments' outline samples summed over the frames that matched it:
    /// `[across one continuous surface, across a depth edge]` (see [`Self::is_flush`]). Not
    /// kept in map files: a loaded map counts afresh.
    outlines: FxHashMap<u16, [u32; 2]>,
    /// Class id → the id standing for its family (see [`class_families`]); classes not
    /// listed are their own family.
    families: Families,
    /// Per-id tables reused between frames (allocating and zeroing them each frame cost more
    /// than the matching).
    scratch: IdTables,
}

/// How many ids a u16 names: the length of every [`IdTables`] table.
const IDS: usize = u16::MAX as usize + 1;

/// Tables indexed by segment or instance id; entries are reset after each frame.
#[derive(Clone, Debug, Default)]
struct IdTables {
    /// Segment id → its index in the frame's list.
    slot: Vec<u32>,
    /// Instance id → samples it was seen on (their voxels' leading candidate).
    visible: Vec<u32>,
    /// Instance id → those of its `visible` samples within the integration range.
    visible_integrated: Vec<u32>,
    /// Instance id → samples whose voxels hold it as the runner-up.
    runner_up: Vec<u32>,
    /// Instance ids with `visible > 0` or `runner_up > 0`.
    seen: Vec<u16>,
    /// Segment id → the instance it becomes.
    target: Vec<u16>,
    /// Segment id → the instance its pixels on a thing's voxels become: `target`, or 0 for
    /// stuff (stuff must not overwrite things).
    target_on_thing: Vec<u16>,
    /// Instance id → a thing in view.
    thing: Vec<bool>,
}

impl IdTables {
    fn ready(&mut self) {
        if self.slot.len() != IDS {
            self.slot = vec![u32::MAX; IDS];
            self.visible = vec![0; IDS];
            self.visible_integrated = vec![0; IDS];
            self.runner_up = vec![0; IDS];
            self.target = vec![0; IDS];
            self.target_on_thing = vec![0; IDS];
            self.thing = vec![false; IDS];
        }
    }

    /// Resets what this frame set.
    fn clear(&mut self, segments: &[Segment]) {
        for s in segments {
            self.slot[s.id as usize] = u32::MAX;
            self.target[s.id as usize] = 0;
            self.target_on_thing[s.id as usize] = 0;
        }
        for &id in &self.seen {
            self.visible[id as usize] = 0;
            self.visible_integrated[id as usize] = 0;
            self.runner_up[id as usize] = 0;
            self.thing[id as usize] = false;
        }
        self.seen.clear();
    }

    /// Instance `i`'s samples in the frame, leading or runner-up, in pixels (`area` per
    /// sample).
    fn in_view(&self, i: u16, area: usize) -> usize {
        (self.visible[i as usize] + self.runner_up[i as usize]) as usize * area
    }
}

/// Class families (see [`class_families`]) and which of them are the building's shell.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Families {
    /// Class id → the smallest id of its family.
    pub head: BTreeMap<u32, u32>,
    /// The heads of the shell's families: walls, floors and ceilings.
    pub shell: std::collections::BTreeSet<u32>,
    /// The heads of the families of items a network segments one by one (see [`GROUPS`]).
    pub groups: std::collections::BTreeSet<u32>,
}

/// The families whose stuff is the building's shell: one connected surface, whose walls,
/// floors and ceilings meet at the edges every room shares. Other stuff (doors, rugs,
/// cabinets, counters) comes in separate pieces.
const SHELL: [&str; 3] = ["wall", "floor", "ceiling"];

/// The families of things that stand in groups a network segments item by item and a map
/// holds as one object: books along a shelf (the flat's ground truth labels each stack; COCO
/// names each `book`). See [`join_group_items`].
const GROUPS: [&str; 2] = ["book", "books"];

/// Groups classes whose names share their first word (split at `-`, `_` or a space, case
/// ignored): COCO panoptic's stuff comes in families named `<family>-<variant>` (`wall`,
/// `wall-brick`, `wall-tile`; `floor`, `floor-wood`), and a network flickers between members
/// of a family on one surface. Each class maps to the smallest id of its family.
pub(crate) fn class_families(names: &BTreeMap<u32, String>) -> Families {
    let mut first: BTreeMap<String, u32> = BTreeMap::new();
    let mut families = Families::default();
    for (&id, name) in names {
        let family = name
            .split(['-', '_', ' '])
            .next()
            .unwrap_or(name)
            .to_lowercase();
        if !first.contains_key(&family) {
            if SHELL.contains(&family.as_str()) {
                families.shell.insert(id);
            }
            if GROUPS.contains(&family.as_str()) {
                families.groups.insert(id);
            }
        }
        let head = *first.entry(family).or_insert(id);
        families.head.insert(id, head);
    }
    families
}

/// One segment's evidence, in pixels: a sample of the coarse grid stands for the `step²`
/// pixels around it, one of a small segment's own samples (see [`FINE_BELOW_SAMPLES`]) for
/// its pixel.
#[derive(Default)]
struct SegmentEvidence {
    /// Pixels with a measurement.
    measured: usize,
    /// Pixels whose measurement integration maps (within its range).
    integrated: usize,
    /// Those pixels per instance (0 excluded).
    on_integrated: Vec<(u16, usize)>,
    /// Pixels per instance (0 excluded); a segment lies on few instances, so a short list.
    on: Vec<(u16, usize)>,
    /// Pixels per (leader, runner-up) pair of their voxels, where both are instances.
    contested: Vec<(u16, u16, usize)>,
    /// Pixels.
    pixels: usize,
    /// The blocks its measurements within the integration range land in (consecutive repeats
    /// dropped; see [`SegmentEvidence::distinct_blocks`]).
    blocks: Vec<BlockIndex>,
}

impl SegmentEvidence {
    /// Pixels on any instance (the map's voxels say something about them).
    fn mapped(&self) -> usize {
        self.on.iter().map(|(_, n)| n).sum()
    }

    /// Pixels on voxels instance `i` leads.
    fn led_by(&self, i: u16) -> usize {
        self.on.iter().find(|(j, _)| *j == i).map_or(0, |(_, n)| *n)
    }

    /// Whether integration maps enough of the segment to found an instance: `min_pixels`
    /// pixels, with depth within its range.
    fn maps_enough(&self, min_pixels: usize) -> bool {
        self.pixels >= min_pixels && self.integrated >= min_pixels
    }

    /// The blocks the segment's surface lies in, each once.
    fn distinct_blocks(&self) -> Vec<BlockIndex> {
        let mut blocks = self.blocks.clone();
        blocks.sort_unstable();
        blocks.dedup();
        blocks
    }

    /// Adds `sample`, standing for `area` pixels.
    fn add(&mut self, sample: Sample, area: usize) {
        self.pixels += area;
        let Some(seen) = sample.label else {
            return;
        };
        self.measured += area;
        self.integrated += area * sample.integrated as usize;
        if sample.integrated && self.blocks.last() != Some(&sample.block) {
            self.blocks.push(sample.block);
        }
        if seen == 0 {
            return;
        }
        count_on(&mut self.on, seen, area);
        if sample.integrated {
            count_on(&mut self.on_integrated, seen, area);
        }
        if sample.challenger != 0 {
            let pair = (seen, sample.challenger);
            match self.contested.iter_mut().find(|(l, c, _)| (*l, *c) == pair) {
                Some((_, _, n)) => *n += area,
                None => self.contested.push((pair.0, pair.1, area)),
            }
        }
    }
}

impl InstanceTracker {
    pub fn new(config: TrackingConfig) -> Self {
        Self {
            config,
            instances: BTreeMap::new(),
            next_id: 1,
            pairs: BTreeMap::new(),
            outlines: FxHashMap::default(),
            families: Families::default(),
            scratch: IdTables::default(),
        }
    }

    /// Sets the class families stuff is matched by (see [`class_families`]).
    pub fn set_families(&mut self, families: Families) {
        self.families = families;
    }

    fn family(&self, class: u32) -> u32 {
        self.families.head.get(&class).copied().unwrap_or(class)
    }

    /// Whether stuff of `class` is the building's shell (see [`SHELL`]).
    fn is_shell(&self, class: u32) -> bool {
        self.families.shell.contains(&self.family(class))
    }

    /// Whether things of `class` stand in groups (see [`GROUPS`]).
    fn is_group(&self, class: u32) -> bool {
        self.families.groups.contains(&self.family(class))
    }

    /// The stuff instance seen most often as `class`'s family (the oldest of equals), if any
    /// was. Not the one *named* after the family: a floor whose segments the network called
    /// `rug` in most frames is named `rug` by its votes, and a floor segment in the next room
    /// would found a second floor.
    fn stuff_instance(&self, class: u32) -> Option<u16> {
        let family = self.family(class);
        self.instances
            .iter()
            .filter(|(_, i)| i.kind() == Some(false))
            .map(|(&id, i)| {
                let votes: u32 = i
                    .class_votes
                    .iter()
                    .filter(|&(&c, _)| self.family(c) == family)
                    .map(|(_, &v)| v)
                    .sum();
                (id, votes)
            })
            .filter(|&(_, votes)| votes > 0)
            .max_by(most_then_smallest_id)
            .map(|(id, _)| id)
    }

    /// A tracker that continues numbering after the highest of `instances`.
    pub fn with_instances(config: TrackingConfig, instances: BTreeMap<u16, InstanceInfo>) -> Self {
        let next_id = instances.keys().max().map_or(1, |&m| m.saturating_add(1));
        Self {
            config,
            instances,
            next_id,
            pairs: BTreeMap::new(),
            outlines: FxHashMap::default(),
            families: Families::default(),
            scratch: IdTables::default(),
        }
    }

    /// Takes the frame's segment ids as map instance ids (segments that already identify
    /// objects across frames): records their classes, confirms each id seen in
    /// `min_observations` frames, and returns the instance image (ids without a segment entry
    /// become 0).
    pub fn identified(&mut self, labels: &LabelImage, segments: &[Segment]) -> Assignment {
        let mut listed = vec![false; u16::MAX as usize + 1];
        let mut stats = AssociationStats::default();
        for segment in segments {
            // A frame counts once per id, however many segments carry it.
            let again = std::mem::replace(&mut listed[segment.id as usize], true);
            let info = self.instances.entry(segment.id).or_default();
            if !again {
                if info.frames_seen == 0 {
                    stats.created += 1;
                } else {
                    stats.matched += 1;
                }
                info.frames_seen += 1;
            }
            // Known identity does not make a once-seen detection an object: shown as tracked
            // instances are.
            info.confirmed |= info.frames_seen >= self.config.min_observations;
            info.vote(segment);
            self.next_id = self.next_id.max(segment.id.saturating_add(1));
        }
        Assignment {
            instances: labels.map(|&l| if listed[l as usize] { l } else { 0 }),
            stats,
            merges: Vec::new(),
        }
    }

    /// Labels a frame whose segments the map itself rendered (between keyframes): each
    /// segment id is the map instance it shows. Nothing is counted: the map seeing itself is
    /// no evidence for an instance, its class or its pairs (it would confirm every fragment
    /// and tell every neighbour apart). Ids the tracker no longer has are left out.
    pub fn carried(&self, labels: &LabelImage, segments: &[Segment]) -> Assignment {
        let mut listed = vec![false; u16::MAX as usize + 1];
        for segment in segments {
            listed[segment.id as usize] = self.instances.contains_key(&segment.id);
        }
        Assignment {
            instances: labels.map(|&l| if listed[l as usize] { l } else { 0 }),
            stats: AssociationStats::default(),
            merges: Vec::new(),
        }
    }

    /// Moves the pair evidence and the outline counts of instance `from` (merged away) to
    /// `into`, pooling counts.
    fn pool_pairs(&mut self, from: u16, into: u16) {
        pool_pair_keys(&mut self.pairs, from, into, |pooled, evidence| {
            pooled.together += evidence.together;
            pooled.apart += evidence.apart;
            pooled.together_renamed += evidence.together_renamed;
            pooled.gathered += evidence.gathered;
            pooled.founded_over += evidence.founded_over;
        });
        if let Some([continuous, edge]) = self.outlines.remove(&from) {
            let pooled = self.outlines.entry(into).or_default();
            pooled[0] = pooled[0].saturating_add(continuous);
            pooled[1] = pooled[1].saturating_add(edge);
        }
    }

    /// Whether thing instance `id` lies flush with what surrounds it: its masks' outlines, over
    /// every frame that matched it, met their neighbours across one continuous surface (depth
    /// steps within the TSDF truncation distance) more often than across a depth edge. A
    /// picture or a TV on its wall; not a chair, a table, or a shelf seen from the side.
    /// Refinement cannot cut a wall's mask off such a thing by depth, so in the frames where
    /// the network misses it the wall's mask covers it on the same voxels.
    pub fn is_flush(&self, id: u16) -> bool {
        self.outlines
            .get(&id)
            .is_some_and(|&[continuous, edge]| continuous > edge)
    }

    /// Adds this frame's outline samples to each matched instance (see [`Self::is_flush`]):
    /// the boundary between two segments matched to two instances counts for both.
    fn count_outlines(&mut self, touching: &[Touching], to_instance: &BTreeMap<u16, u16>) {
        for (i, j, t) in instances_meeting(touching, to_instance) {
            for id in [i, j] {
                let counts = self.outlines.entry(id).or_default();
                counts[0] = counts[0].saturating_add(t.continuous as u32);
                counts[1] = counts[1].saturating_add(t.across_edge as u32);
            }
        }
    }

    /// Merges the whole map calls for, once its frames are in (`touching`: pairs of instances
    /// whose surface voxels touch, with the voxel faces they share; `surface`: each instance's
    /// surface voxels). Frame by frame, two instances merge only when one segment covered
    /// both, so an object the network segmented in pieces never seen whole (a row of books
    /// segmented a book at a time, a refrigerator's sides seen in turn) stays in pieces. Here
    /// instances join where they meet along a seam, not at a point: the faces they share are
    /// at least the square root of the smaller one's surface voxels (the width of a patch of
    /// that many voxels: pieces of one object cut apart share their cut, two objects standing
    /// side by side touch at a few voxels), unless frames told them apart (each matched by
    /// its own segment; see [`Self::record_apart`]) more often than they covered them
    /// together. Class
    /// and kind do not enter: the pieces of one object the network named differently in turn
    /// (a table called `shelf`, or the stuff `table-merged`, for a few frames) are never told
    /// apart, while a cup on its table or a picture on its wall is, in every frame that
    /// segments both. A thing and a stuff instance also join when a mask matched to one
    /// covered most of the other, renamed (see [`Self::says_renamed`]), more often than
    /// frames told them apart: frame by frame that pair cannot merge, so `together` never
    /// counts it, and a table whose `table-merged` piece was once segmented beside it stayed
    /// two. The largest seam goes first; sizes, seams and evidence pool as
    /// instances join, so a chain cannot join two instances that were told apart. First,
    /// each one-frame guess joins the thing it named otherwise (see
    /// [`Self::join_renamed_guesses`]). Returns the merges `(from, into)` in the order made
    /// (the older id stays, but a guess joins its thing; the class is the pooled votes').
    pub fn consolidate(
        &mut self,
        touching: &FxHashMap<(u16, u16), u32>,
        surface: &FxHashMap<u16, usize>,
    ) -> Vec<(u16, u16)> {
        let mut seams: BTreeMap<(u16, u16), u32> =
            touching.iter().map(|(&pair, &n)| (pair, n)).collect();
        let mut sizes: BTreeMap<u16, usize> = surface.iter().map(|(&id, &n)| (id, n)).collect();
        let mut merges = self.join_renamed_guesses(&mut seams, &mut sizes);
        loop {
            let joins = |&(&(a, b), &faces): &(&(u16, u16), &u32)| {
                let (Some(i), Some(j)) = (self.instances.get(&a), self.instances.get(&b)) else {
                    return false;
                };
                let confirmed = i.confirmed && j.confirmed;
                let size = |id| sizes.get(&id).copied().unwrap_or(0);
                let seam = (faces as usize).pow(2) >= size(a).min(size(b));
                let evidence = self.pairs.get(&(a, b)).copied().unwrap_or_default();
                // Across kinds, also what frame-by-frame matching could not count.
                let across = i.kind() != j.kind() && evidence.together_renamed > evidence.apart;
                // A tie joins on covers by one name only: a group's segment gathering a
                // thing of another name must outvote the frames that told the two apart.
                let together = evidence.together.saturating_sub(evidence.gathered)
                    >= evidence.apart
                    || evidence.together > evidence.apart
                    || across;
                confirmed && seam && together
            };
            let Some((&(into, from), _)) = seams
                .iter()
                .filter(joins)
                .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            else {
                return merges;
            };
            let info = self.instances.remove(&from).expect("joins");
            self.instances.get_mut(&into).expect("joins").absorb(info);
            self.pool_pairs(from, into);
            let moved = sizes.remove(&from).unwrap_or(0);
            *sizes.entry(into).or_default() += moved;
            pool_pair_keys(&mut seams, from, into, |pooled, faces| *pooled += faces);
            merges.push((from, into));
        }
    }

    /// Joins each unconfirmed instance whose founding segment covered a settled thing of
    /// another class each way (`founded_over`), whose surface it meets, and from which that
    /// frame did not tell it apart, into that thing: a network naming a table `shelf` for one
    /// view is not an object, but the surface that view added to the table is the table's.
    /// Hidden, the guess left that surface unlabelled: on the three-room draws, the share of
    /// the true things' surface left unlabelled falls from 8.4 % to 6.2 % with the join (1.7 %
    /// under correct association). Confirmed (seen again), it stays an object of its own, as
    /// the chair in its sofa's mask does. The guess's seams and pair evidence go
    /// with it, not to the thing: they are where its mask over-reached (pooled, they joined
    /// two chairs it bridged, and a chair to its sofa).
    fn join_renamed_guesses(
        &mut self,
        seams: &mut BTreeMap<(u16, u16), u32>,
        sizes: &mut BTreeMap<u16, usize>,
    ) -> Vec<(u16, u16)> {
        let guesses: Vec<(u16, u16)> = self
            .pairs
            .iter()
            .filter(|(pair, e)| e.founded_over > 0 && e.apart == 0 && seams.contains_key(pair))
            .filter_map(|(&(a, b), _)| {
                let (i, j) = (self.instances.get(&a)?, self.instances.get(&b)?);
                match (i.confirmed, j.confirmed) {
                    (false, true) => Some((a, b)),
                    (true, false) => Some((b, a)),
                    _ => None,
                }
            })
            .collect();
        let mut merges = Vec::new();
        for (guess, thing) in guesses {
            let Some(info) = self.instances.remove(&guess) else {
                continue;
            };
            self.instances.get_mut(&thing).expect("listed").absorb(info);
            self.outlines.remove(&guess);
            let moved = sizes.remove(&guess).unwrap_or(0);
            *sizes.entry(thing).or_default() += moved;
            merges.push((guess, thing));
        }
        // Dropped in one sweep each: a guess's pairs and seams are read no more.
        let joined: std::collections::BTreeSet<u16> = merges.iter().map(|&(g, _)| g).collect();
        let kept = |&(a, b): &(u16, u16)| !joined.contains(&a) && !joined.contains(&b);
        self.pairs.retain(|pair, _| kept(pair));
        seams.retain(|pair, _| kept(pair));
        merges
    }

    /// Whether segment `s` may continue instance `i`.
    fn compatible(&self, s: &Segment, i: &InstanceInfo) -> bool {
        let kind = i.kind();
        if let (Some(a), Some(b)) = (s.is_thing, kind)
            && a != b
        {
            return false;
        }
        match (s.is_thing.or(kind), s.class_id, i.class()) {
            (_, None, _) | (_, _, None) => true,
            (Some(true), Some(a), Some(b)) => !self.config.class_aware_things || a == b,
            // Stuff (or unknown kind): the same class family.
            (_, Some(a), Some(b)) => self.family(a) == self.family(b),
        }
    }

    /// Whether group segment `s` (see [`GROUPS`]) votes to join thing instance `i` it covers,
    /// whatever `i`'s name: items of a row the network named otherwise in other views (books
    /// called `box`) are the row's. A thing beside the row that the network segments apart
    /// is told apart in those frames; such votes must outnumber those frames, also where
    /// consolidation joins a tie (see [`PairEvidence::gathered`]).
    fn gathers(&self, s: &Segment, i: &InstanceInfo) -> bool {
        s.is_thing == Some(true)
            && s.class_id.is_some_and(|c| self.is_group(c))
            && i.kind() == Some(true)
    }

    /// Whether segment `s` may continue the map's instance `id`.
    fn compatible_with(&self, s: &Segment, id: u16) -> bool {
        self.instances
            .get(&id)
            .is_some_and(|info| self.compatible(s, info))
    }

    /// The samples that vouch for each instance, as segment `s` reads them: a voxel speaks
    /// for its leading candidate, or for its runner-up when the leader is stuff that `s`
    /// cannot be and the runner-up is what `s` may be. A clock or a journal first mapped as
    /// part of its wall is the wall's runner-up on its voxels until it has been seen more
    /// often than the wall was; reading only leaders, every frame would found a new clock,
    /// none of which ever leads. A thing under another thing (a cup on a table) is left to
    /// the leader: there a network's class flickering between two labels of one object (bed,
    /// couch) looks the same, and reading past the leader split that object in two (measured).
    /// Stuff reads past a leader only that another segment of the frame continues
    /// (`continued`): then the segmenter says the two are regions side by side (a rug first
    /// mapped as the floor, the floor around it segmented apart). A stuff segment over a
    /// leader nothing else continues is that surface renamed (a wall called `door` for a
    /// few frames); reading its runner-up there let the renamed region take over the wall.
    fn support(&self, s: &Segment, e: &SegmentEvidence, continued: &[u16]) -> Vec<(u16, usize)> {
        let mut support = e.on.clone();
        for &(leader, challenger, n) in &e.contested {
            let leader_is_stuff = self
                .instances
                .get(&leader)
                .is_some_and(|i| i.kind() == Some(false));
            if !leader_is_stuff
                || (s.is_thing != Some(true) && !continued.contains(&leader))
                || self.compatible_with(s, leader)
                || !self.compatible_with(s, challenger)
            {
                continue;
            }
            if let Some((_, m)) = support.iter_mut().find(|(i, _)| *i == leader) {
                *m -= n;
            }
            match support.iter_mut().find(|(i, _)| *i == challenger) {
                Some((_, m)) => *m += n,
                None => support.push((challenger, n)),
            }
        }
        support
    }

    /// The instance of another class that segment `s` continues: a network names one
    /// object or surface differently from frame to frame (chair and toilet, bed and couch;
    /// floor and rug, wall and door). Only where segment and instance cover each other (the
    /// instance holds `min_overlap` of the segment's `mapped` samples, and the segment covers
    /// that share of the instance's `shown(id)` samples): a rug on a floor, or a door in a
    /// wall, covers only part of the floor or wall in view, and founds its own instance.
    /// Stuff must be explained as a whole (`min_overlap` of its `measured` samples, mapped or
    /// not): a floor seen around a rug mapped before it is not the rug renamed.
    /// A thing also needs its instance's class not to be a settled other one: still
    /// unconfirmed (one frame's guess), or seen as `s`'s class before. A settled thing under a
    /// segment of another class is the network joining neighbours (a chair merged into its
    /// sofa's mask), which class-aware matching exists to keep apart; `settled_too` lifts
    /// that condition, to name what a founding segment covered (see [`Self::decide`]).
    fn renamed(
        &self,
        s: &Segment,
        support: &[(u16, usize)],
        mapped: usize,
        measured: usize,
        shown: impl Fn(u16) -> usize,
        settled_too: bool,
    ) -> Option<(u16, usize)> {
        let thing = match s.is_thing {
            Some(true) if self.config.class_aware_things => true,
            Some(false) => false,
            _ => return None,
        };
        let min_overlap = self.config.min_overlap;
        support
            .iter()
            .filter(|(i, _)| {
                let info = &self.instances[i];
                let seen_as_s = s
                    .class_id
                    .is_some_and(|c| info.class_votes.contains_key(&c));
                info.kind() == Some(thing)
                    && !self.compatible(s, info)
                    && (!thing || !info.confirmed || seen_as_s || settled_too)
            })
            .max_by(|a, b| most_then_smallest_id(a, b))
            .copied()
            .filter(|&(i, n)| {
                let explained = if thing { mapped } else { measured };
                n as f64 >= min_overlap * explained as f64
                    && n as f64 >= min_overlap * shown(i) as f64
            })
    }

    /// The instance a thing segment continues when the map holds its object in parts: the
    /// compatible thing instances the segment covers most of together hold `min_overlap` of
    /// its `mapped` samples, though none does alone (a chair first segmented in pieces, a
    /// shelf's books first segmented one by one, then seen whole). A part is covered when the
    /// segment's samples on it, as leader or runner-up of their voxels, are `min_overlap` of
    /// its `shown(id)` samples (counted the same way over the frame). The largest part is
    /// continued; the segment's merge votes join the others to it. Founding an instance
    /// instead added one more to the parts in every such frame, none of which a later whole
    /// segment could continue either.
    fn parts(
        &self,
        s: &Segment,
        e: &SegmentEvidence,
        support: &[(u16, usize)],
        mapped: usize,
        shown: impl Fn(u16) -> usize,
    ) -> Option<(u16, usize)> {
        if s.is_thing != Some(true) {
            return None;
        }
        let min_overlap = self.config.min_overlap;
        let covered = |i: u16| {
            let leading = e.led_by(i);
            let runner_up: usize = e
                .contested
                .iter()
                .filter(|(_, c, _)| *c == i)
                .map(|(_, _, n)| n)
                .sum();
            leading + runner_up
        };
        let parts: Vec<(u16, usize)> = support
            .iter()
            .filter(|&&(i, _)| {
                let info = &self.instances[&i];
                info.kind() == Some(true)
                    && (self.compatible(s, info) || self.gathers(s, info))
                    && covered(i) as f64 >= min_overlap * shown(i) as f64
            })
            .copied()
            .collect();
        let held: usize = parts.iter().map(|(_, n)| n).sum();
        if parts.len() < 2 || (held as f64) < min_overlap * mapped as f64 {
            return None;
        }
        parts.into_iter().max_by(most_then_smallest_id)
    }

    /// Maps the frame's `segments` (ids in `labels`) to map instances, given what the map
    /// says about the frame's measured surface (`observed`, sampled on the coarse grid from
    /// `surface`, which small segments read every pixel of theirs from).
    pub fn assign(
        &mut self,
        labels: &LabelImage,
        segments: &[Segment],
        observed: &Observation,
        surface: &mut Surface,
    ) -> Assignment {
        let joined = join_group_items(
            labels,
            segments,
            surface.depth(),
            observed.surface_step,
            |c| self.is_group(c),
        );
        let (labels, segments) = match &joined {
            Some((labels, segments)) => (labels, segments.as_slice()),
            None => (labels, segments),
        };
        let mut tables = std::mem::take(&mut self.scratch);
        tables.ready();
        let assignment = self.assign_with(labels, segments, observed, surface, &mut tables);
        tables.clear(segments);
        self.scratch = tables;
        assignment
    }

    /// The frame's association, phase by phase: evidence per segment, the segments the map's
    /// voxels vouch for, stuff seen where the map holds none of it yet, what each segment
    /// becomes, what the frame said about pairs of instances, the merges that evidence
    /// calls for, and the instance image.
    fn assign_with(
        &mut self,
        labels: &LabelImage,
        segments: &[Segment],
        observed: &Observation,
        surface: &mut Surface,
        tables: &mut IdTables,
    ) -> Assignment {
        let evidence = gather_evidence(labels, segments, observed, surface, tables);
        let touching = touching_segments(labels, observed);
        let mut matched = self.match_vouched(segments, &evidence, tables, observed.step);
        self.match_spatial_stuff(segments, &evidence, surface, &mut matched);
        continue_cut_pieces(
            segments,
            &touching,
            tables,
            |k, i| {
                let shown = |j: u16| tables.in_view(j, observed.step * observed.step);
                self.held_as_other(&segments[k], &evidence[k], i, shown)
            },
            &mut matched,
        );
        let detached = self.detached_pieces(labels, segments, observed, surface, &matched, tables);
        let mut decided = self.decide(
            segments,
            &evidence,
            matched,
            &detached.only_off,
            tables,
            observed.step,
        );
        let within_range = self.within_range(segments, &evidence, &decided.to_instance);
        self.record_apart(&touching, &decided.to_instance, &within_range);
        self.count_outlines(&touching, &decided.to_instance);
        self.count_once(std::mem::take(&mut decided.covered_renamed), |e| {
            &mut e.together_renamed
        });
        for pair in std::mem::take(&mut decided.founded_over) {
            self.pairs.entry(pair).or_default().founded_over += 1;
        }
        self.count_once(std::mem::take(&mut decided.gathered), |e| &mut e.gathered);
        let applied = self.merge_voted(decided.votes, &mut decided.to_instance);
        decided.stats.merged = applied.len();
        let mut instances =
            self.instance_image(labels, segments, observed, &decided.to_instance, tables);
        let pixels = instances.pixels_mut();
        for p in detached.pixels {
            pixels[p] = 0;
        }
        Assignment {
            instances,
            stats: decided.stats,
            merges: applied,
        }
    }

    /// Adds one to `count` of each pair in `pairs` (repeats allowed): a frame is one piece of
    /// evidence however many of its segments said it.
    fn count_once(
        &mut self,
        mut pairs: Vec<(u16, u16)>,
        count: impl Fn(&mut PairEvidence) -> &mut u32,
    ) {
        pairs.sort_unstable();
        pairs.dedup();
        for pair in pairs {
            *count(self.pairs.entry(pair).or_default()) += 1;
        }
    }

    /// For each segment, the compatible instance the map's voxels vouch for: the one holding
    /// most of its mapped samples, when it holds `min_overlap` of them (a thing's must also
    /// explain the segment or the instance's visible part), else a renamed instance or the
    /// object's parts (see [`Self::renamed`], [`Self::parts`]). Stuff left unmatched is read
    /// again once the frame's other segments are matched: past the leaders they continue
    /// (see [`Self::support`]), or as the shell under another name (see
    /// [`Self::match_renamed_shell`]).
    fn match_vouched(
        &self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        tables: &IdTables,
        step: usize,
    ) -> Vec<Option<u16>> {
        let area = step * step;
        let shown = |i: u16| tables.in_view(i, area);
        let mut matched: Vec<Option<u16>> = segments
            .iter()
            .zip(evidence)
            .map(|(s, e)| self.vouched(s, e, &[], shown))
            .collect();
        let ceded = self.cede_to_one_class(segments, evidence, &mut matched);
        let continued: Vec<u16> = matched.iter().flatten().copied().collect();
        for (k, ((s, e), m)) in segments.iter().zip(evidence).zip(&mut matched).enumerate() {
            if m.is_none() && s.is_thing != Some(true) {
                *m = self
                    .vouched(s, e, &continued, shown)
                    .filter(|&i| !ceded.contains(&(k, i)));
            }
        }
        self.match_renamed_shell(segments, evidence, shown, &ceded, &mut matched);
        matched
    }

    /// Stuff of another family still unmatched that lies on the building's shell (a floor, a
    /// wall) where no other segment of the frame continues it: the network names the shell in
    /// view otherwise (a room's floor called `rug` as the camera turns to it). It continues
    /// that shell instance when the instance holds `min_overlap` of its mapped samples and
    /// it covers that share of the instance in view. [`Self::renamed`] asks stuff to be
    /// explained as a whole, new surface included, so a view mostly of floor no frame has
    /// mapped founded a `rug` that took the new floor, and later the room's real rug with it.
    /// A rug beside floor the frame segments as floor is not affected: that floor segment
    /// continues the shell.
    fn match_renamed_shell(
        &self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        shown: impl Fn(u16) -> usize,
        ceded: &[(usize, u16)],
        matched: &mut [Option<u16>],
    ) {
        let continued: Vec<u16> = matched.iter().flatten().copied().collect();
        let min_overlap = self.config.min_overlap;
        for (k, ((s, e), m)) in segments.iter().zip(evidence).zip(matched).enumerate() {
            let (None, Some(false), Some(class)) = (*m, s.is_thing, s.class_id) else {
                continue;
            };
            if self.is_shell(class) {
                continue;
            }
            let mapped = e.mapped();
            *m =
                e.on.iter()
                    .filter(|&&(j, _)| {
                        let info = &self.instances[&j];
                        info.kind() == Some(false)
                            && info.class().is_some_and(|c| self.is_shell(c))
                            && !continued.contains(&j)
                            && !ceded.contains(&(k, j))
                    })
                    .max_by(|a, b| most_then_smallest_id(a, b))
                    .filter(|&&(j, n)| {
                        n as f64 >= min_overlap * mapped as f64
                            && n as f64 >= min_overlap * shown(j) as f64
                    })
                    .map(|&(j, _)| j);
        }
    }

    /// Where stuff segments of several classes continue one stuff instance, the segmenter
    /// says that surface is several regions (a rug and the floor around it, first mapped as
    /// one floor): the class of the segment that holds most of the instance's samples keeps
    /// it (with any other segment of that class: a region cut in parts), and the others let
    /// go of it, to continue another instance or found one. Not the instance's own class
    /// keeps it: where that separates anything, the network has swapped two names (the rug
    /// called `floor` while the floor is called `rug`), and the floor would go to the rug.
    /// Returns `(segment index, instance)` for each segment that let go.
    fn cede_to_one_class(
        &self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        matched: &mut [Option<u16>],
    ) -> Vec<(usize, u16)> {
        let mut by_instance: BTreeMap<u16, Vec<usize>> = BTreeMap::new();
        for (k, m) in matched.iter().enumerate() {
            if let Some(i) = *m
                && segments[k].is_thing == Some(false)
                && self.instances[&i].kind() == Some(false)
            {
                by_instance.entry(i).or_default().push(k);
            }
        }
        let mut ceded = Vec::new();
        for (i, ks) in by_instance {
            let class = |k: usize| segments[k].class_id;
            if ks.iter().all(|&k| class(k) == class(ks[0])) {
                continue;
            }
            let on = |k: usize| evidence[k].led_by(i);
            // Ties: the first segment listed.
            let keeper = ks
                .iter()
                .copied()
                .max_by(|&a, &b| on(a).cmp(&on(b)).then(b.cmp(&a)))
                .map(class)
                .expect("two or more");
            for k in ks {
                if class(k) != keeper {
                    matched[k] = None;
                    ceded.push((k, i));
                }
            }
        }
        ceded
    }

    /// The instance the map's voxels vouch for segment `s` (see [`Self::match_vouched`]),
    /// reading stuff leaders in `continued` past (see [`Self::support`]).
    fn vouched(
        &self,
        s: &Segment,
        e: &SegmentEvidence,
        continued: &[u16],
        shown: impl Fn(u16) -> usize + Copy,
    ) -> Option<u16> {
        let min_overlap = self.config.min_overlap;
        let mapped = e.mapped();
        let support = self.support(s, e, continued);
        let candidate = support
            .iter()
            .filter(|(i, _)| self.compatible_with(s, *i))
            .max_by(|a, b| most_then_smallest_id(a, b))
            .copied();
        let accepted = candidate.filter(|&(i, n)| {
            let majority = n as f64 >= min_overlap * mapped as f64;
            let thing = s.is_thing.or(self.instances[&i].kind()) == Some(true);
            let explains = n as f64 >= min_overlap * e.measured.min(shown(i)) as f64;
            majority && (!thing || explains)
        });
        accepted
            .or_else(|| self.renamed(s, &support, mapped, e.measured, shown, false))
            .or_else(|| self.parts(s, e, &support, mapped, shown))
            .map(|(i, _)| i)
    }

    /// Stuff seen where the map has none of it yet. The shell (walls, floors, ceilings)
    /// continues its family's instance: one connected surface through every room, seen in
    /// pieces. Other stuff continues a stuff instance of its family whose surface it meets
    /// (in or beside the blocks it lands in): a door, a rug or a cabinet is its own piece,
    /// never one across the flat. Either way, not an instance another segment of this frame
    /// already continues (the segmenter then says these are two regions); the largest segment
    /// goes first.
    fn match_spatial_stuff(
        &self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        surface: &mut Surface,
        matched: &mut [Option<u16>],
    ) {
        let mut claimed: Vec<u16> = matched.iter().flatten().copied().collect();
        let mut by_size: Vec<usize> = (0..segments.len()).collect();
        by_size.sort_by_key(|&k| std::cmp::Reverse(evidence[k].pixels));
        for k in by_size {
            let s = &segments[k];
            let (None, Some(false), Some(class)) = (matched[k], s.is_thing, s.class_id) else {
                continue;
            };
            matched[k] = if self.is_shell(class) {
                self.stuff_instance(class).filter(|i| !claimed.contains(i))
            } else {
                let near = surface.instances_near(&evidence[k].distinct_blocks());
                near.into_iter()
                    .filter(|&(i, _)| {
                        !claimed.contains(&i)
                            && self.compatible_with(s, i)
                            && self.instances[&i].kind() == Some(false)
                    })
                    .max_by(most_then_smallest_id)
                    .map(|(i, _)| i)
            };
            claimed.extend(matched[k]);
        }
    }

    /// What each segment becomes: its matched instance (voting its class and, for the other
    /// compatible instances it covers most of, to merge), a new instance (noting the settled
    /// thing of another class it covers each way, if any), or nothing (too small, or no id
    /// left). Counts the frame in every instance a segment continued.
    fn decide(
        &mut self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        matched: Vec<Option<u16>>,
        only_off: &[(u16, u16)],
        tables: &IdTables,
        step: usize,
    ) -> Decided {
        let min_overlap = self.config.min_overlap;
        let area = step * step;
        let mut decided = Decided::default();
        let mut seen_this_frame: Vec<u16> = Vec::new();
        for ((s, e), decision) in segments.iter().zip(evidence).zip(matched) {
            match decision {
                Some(i) => {
                    decided.to_instance.insert(s.id, i);
                    decided.stats.matched += 1;
                    // Other compatible instances this segment covers most of: the same object.
                    // Merges are never undone, so only samples within the integration range
                    // vote: past it depth is noisy, and networks join neighbours more often.
                    for &(j, n) in &e.on_integrated {
                        let r = tables.visible_integrated[j as usize] as usize;
                        let joins =
                            r >= MIN_MERGE_SAMPLES && n as f64 >= min_overlap * (r * area) as f64;
                        if j == i || !joins || only_off.binary_search(&(s.id, j)).is_ok() {
                            continue;
                        }
                        let (info, pair) = (&self.instances[&j], (i.min(j), i.max(j)));
                        if self.compatible(s, info) {
                            decided.votes.push(pair);
                        } else if self.gathers(s, info) {
                            decided.votes.push(pair);
                            decided.gathered.push(pair);
                        } else if self.says_renamed(s, j) {
                            decided.covered_renamed.push(pair);
                        }
                    }
                    self.instances.get_mut(&i).expect("candidate").vote(s);
                    seen_this_frame.push(i);
                }
                // Only what integration can map founds an instance: enough pixels with depth
                // within its range (a segment seen only from afar would found an instance
                // without voxels, and another one in every later frame).
                None if e.maps_enough(self.config.min_pixels) && self.next_id == u16::MAX => {
                    decided.stats.out_of_ids += 1;
                    decided.stats.unassigned += 1;
                }
                None if e.maps_enough(self.config.min_pixels) => {
                    let id = self.next_id;
                    self.next_id += 1;
                    if s.is_thing == Some(true) {
                        let support = self.support(s, e, &[]);
                        let shown = |i: u16| tables.in_view(i, area);
                        if let Some((j, _)) =
                            self.renamed(s, &support, e.mapped(), e.measured, shown, true)
                        {
                            decided.founded_over.push((id.min(j), id.max(j)));
                        }
                    }
                    let info = self.instances.entry(id).or_default();
                    info.vote(s);
                    decided.to_instance.insert(s.id, id);
                    seen_this_frame.push(id);
                    decided.stats.created += 1;
                }
                None => decided.stats.unassigned += 1,
            }
        }
        seen_this_frame.sort_unstable();
        seen_this_frame.dedup();
        self.count_shell_covered(segments, evidence, &seen_this_frame, tables, area);
        for id in seen_this_frame {
            let info = self.instances.get_mut(&id).expect("assigned");
            info.note_matched_view(tables.visible[id as usize]);
            info.frames_seen += 1;
            info.confirmed |= info.frames_seen >= self.config.min_observations;
        }
        decided
    }

    /// Counts the frame's shell covers (see [`InstanceInfo::shell_covered`]): an instance in
    /// view that no segment matched (`matched`, sorted), a shell segment covering
    /// `min_overlap` of the samples it leads, and those samples at least as many as in the
    /// smallest view a segment matched it in. Smaller views do not count: networks miss small
    /// things at range, and a picture found close up and left inside its wall's segment from
    /// farther away is still a picture.
    fn count_shell_covered(
        &mut self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        matched: &[u16],
        tables: &IdTables,
        area: usize,
    ) {
        let shell: Vec<&SegmentEvidence> = segments
            .iter()
            .zip(evidence)
            .filter(|(s, _)| {
                s.is_thing == Some(false) && s.class_id.is_some_and(|c| self.is_shell(c))
            })
            .map(|(_, e)| e)
            .collect();
        if shell.is_empty() {
            return;
        }
        for &id in &tables.seen {
            let view = tables.visible[id as usize];
            let seen_as_large = self.instances.get(&id).is_some_and(|info| {
                info.smallest_matched_view > 0 && view >= info.smallest_matched_view
            });
            if !seen_as_large || matched.binary_search(&id).is_ok() {
                continue;
            }
            let leading = view as usize * area;
            let covered = shell.iter().any(|e| {
                e.on.iter()
                    .any(|&(i, n)| i == id && n as f64 >= self.config.min_overlap * leading as f64)
            });
            if covered && let Some(info) = self.instances.get_mut(&id) {
                info.shell_covered += 1;
            }
        }
    }

    /// Whether the map holds segment `s` as an object other than instance `i` under another
    /// name: an instance `j` that `s` cannot continue and that `s` covers each way (`j` holds
    /// `min_overlap` of the segment's mapped samples, the segment that share of `j`'s
    /// `shown(j)` samples), unless `i` was once seen as `j`'s class. A book lying on its
    /// shelf's voxels (first mapped inside the shelf's mask) covers only a little of the
    /// shelf, and is not held so. A book of a row the network names `box` and `books` by
    /// turns, on a `box` instance beside a neighbour once seen as `box` too, is a piece of the
    /// row, as the cut says.
    fn held_as_other(
        &self,
        s: &Segment,
        e: &SegmentEvidence,
        i: u16,
        shown: impl Fn(u16) -> usize,
    ) -> bool {
        let min_overlap = self.config.min_overlap;
        let mapped = e.mapped();
        let i_seen_as = |class: Option<u32>| {
            class.is_some_and(|c| self.instances[&i].class_votes.contains_key(&c))
        };
        e.on.iter().any(|&(j, n)| {
            j != i
                && n as f64 >= min_overlap * mapped as f64
                && n as f64 >= min_overlap * shown(j) as f64
                && !self.compatible_with(s, j)
                && !i_seen_as(self.instances[&j].class())
        })
    }

    /// Whether segment `s` covering most of the visible part of instance `j`, which it cannot
    /// continue, may say `j` is the same object renamed: when `s` is a thing (a stuff piece
    /// inside a thing's mask is that thing, named as stuff in other frames: a table's
    /// `table-merged`), or when `s`'s class shares `j`'s class family (the same renaming seen
    /// from the other side). A stuff mask of another family over a thing is the network
    /// missing the thing (a wall's mask over its picture): counting it joined flat's TV and
    /// clock into their wall (measured). A thing's mask over another thing may be that too
    /// (a table's over its cup: reading the count for two things joined them, one room seed 4
    /// −1.8), so consolidation reads it only for a thing and a stuff instance.
    fn says_renamed(&self, s: &Segment, j: u16) -> bool {
        let Some(b) = self.instances.get(&j) else {
            return false;
        };
        let same_family = match (s.class_id, b.class()) {
            (Some(c), Some(d)) => self.family(c) == self.family(d),
            _ => false,
        };
        s.is_thing == Some(true) || same_family
    }

    /// The instances a segment of the frame continued or founded that integration maps enough
    /// of to found one (see [`SegmentEvidence::maps_enough`]), sorted: the instances this
    /// frame sees near enough to map.
    fn within_range(
        &self,
        segments: &[Segment],
        evidence: &[SegmentEvidence],
        to_instance: &BTreeMap<u16, u16>,
    ) -> Vec<u16> {
        let mut within: Vec<u16> = segments
            .iter()
            .zip(evidence)
            .filter(|(_, e)| e.maps_enough(self.config.min_pixels))
            .filter_map(|(s, _)| to_instance.get(&s.id).copied())
            .collect();
        within.sort_unstable();
        within.dedup();
        within
    }

    /// Counts the pairs of instances the segmenter told apart this frame: matched by two
    /// segments that touch (`to_instance`: segment id to instance), and for two things of one
    /// class by two segments anywhere in the frame (the network seeing two objects; counted
    /// only where masks touched, two chairs with the wall between them merged for good on two
    /// frames' masks that joined them), unless a chain of cuts links the two (see
    /// [`cut_objects`]). Not touching, two things are told apart only where both are seen
    /// within the integration range (`within_range`, sorted): past it a network cuts what it
    /// sees small, across holes in the depth that hide the cut, and those frames, which map
    /// nothing, outnumbered the close views that joined a lamp's two instances. Merge votes
    /// likewise count only samples within the range. Two things of one class, or two stuff
    /// regions of one family, whose masks meet mostly across one continuous surface (depth
    /// steps within the TSDF's truncation distance) are not told apart: that boundary is the
    /// network cutting one object or region (a thing split in parts, a row of books segmented
    /// book by book); counted, it kept apart for good the parts every view cut. Across a depth
    /// edge, or between two classes (a cup on its plate, a door flush with its wall), the
    /// boundary says two.
    fn record_apart(
        &mut self,
        touching: &[Touching],
        to_instance: &BTreeMap<u16, u16>,
        within_range: &[u16],
    ) {
        // The class of a thing instance, `None` for stuff.
        let thing_class = |id: u16| {
            let info = self.instances.get(&id)?;
            info.is_thing().then(|| info.class())?
        };
        let stuff_family = |id: u16| {
            let info = self.instances.get(&id)?;
            (info.kind() == Some(false)).then(|| info.class().map(|c| self.family(c)))?
        };
        // The instance pairs whose segments touch, and whether that boundary is a cut.
        let mut met: Vec<((u16, u16), bool)> = instances_meeting(touching, to_instance)
            .map(|(i, j, t)| {
                let one_class = thing_class(i).is_some_and(|c| thing_class(j) == Some(c))
                    || stuff_family(i).is_some_and(|f| stuff_family(j) == Some(f));
                ((i.min(j), i.max(j)), one_class && t.cut())
            })
            .collect();
        met.sort_unstable();
        let mut apart: Vec<(u16, u16)> = met
            .iter()
            .filter(|(_, cut)| !cut)
            .map(|&(pair, _)| pair)
            .collect();
        // Things of one class matched by separate segments are told apart whether or not the
        // masks touch: the pairs frame-by-frame votes can merge. Where they touch, the
        // boundary was read above, a cut included; where a chain of cuts links them, they are
        // pieces of one object the network cut.
        let mut things: Vec<(u32, u16)> = to_instance
            .values()
            .filter_map(|&i| Some((thing_class(i)?, i)))
            .collect();
        things.sort_unstable();
        things.dedup();
        let object = cut_objects(&met, &apart);
        let near = |id: u16| within_range.binary_search(&id).is_ok();
        for class in things.chunk_by(|a, b| a.0 == b.0) {
            for (k, &(_, i)) in class.iter().enumerate() {
                for &(_, j) in &class[k + 1..] {
                    let pair = (i.min(j), i.max(j));
                    if met.binary_search_by_key(&pair, |&(p, _)| p).is_err()
                        && object(i) != object(j)
                        && near(i)
                        && near(j)
                    {
                        apart.push(pair);
                    }
                }
            }
        }
        apart.sort_unstable();
        apart.dedup();
        for pair in apart {
            self.pairs.entry(pair).or_default().apart += 1;
        }
    }

    /// Counts this frame's `votes` (each pair once) and merges the pairs voted often enough,
    /// where covering both is what the frames said more often than telling them apart; the
    /// frame's segments follow (`to_instance`). Returns the merges `(from, into)` as applied.
    fn merge_voted(
        &mut self,
        mut votes: Vec<(u16, u16)>,
        to_instance: &mut BTreeMap<u16, u16>,
    ) -> Vec<(u16, u16)> {
        votes.sort_unstable();
        votes.dedup();
        let mut merges = Vec::new();
        for pair in votes {
            let evidence = self.pairs.entry(pair).or_default();
            evidence.together += 1;
            if evidence.together >= self.config.merge_votes && evidence.together > evidence.apart {
                merges.push((pair.1, pair.0));
            }
        }
        let mut applied: Vec<(u16, u16)> = Vec::new();
        for (from, into) in merges {
            // Earlier merges this frame may have moved either side.
            let resolve = |mut id: u16| {
                while let Some(&(_, to)) = applied.iter().find(|(f, _)| *f == id) {
                    id = to;
                }
                id
            };
            let (from, into) = (resolve(from), resolve(into));
            if from == into {
                continue;
            }
            let (from, into) = (from.max(into), from.min(into));
            if let Some(info) = self.instances.remove(&from) {
                self.instances.get_mut(&into).expect("known").absorb(info);
            }
            self.pool_pairs(from, into);
            for target in to_instance.values_mut() {
                if *target == from {
                    *target = into;
                }
            }
            applied.push((from, into));
        }
        applied
    }

    /// The pieces (4-connected in the image) of non-shell stuff segments that are not part of
    /// the instance each continues (`matched`) or founds (unmatched), left unlabelled this
    /// frame. A door, a rug or a cabinet is one connected piece of surface, but a network's
    /// one segment per stuff class also covers the other door in view; given the instance,
    /// that piece makes the other door's voxels vouch for it, and the two join for good. A
    /// piece is part of an instance the map held before the frame where it lies on the
    /// instance's voxels, in or beside its blocks, or beside the blocks of a piece that is
    /// part of it; of an instance the frame founds wherever it is measured (flat's kitchen is
    /// first seen in a `cabinet` mask that is mostly wall, so no piece can be told the
    /// founder). Either way a piece needs a measurement within the integration range:
    /// without one its pixels are mapped only at the depth hole filling borrows from its
    /// neighbours, other surfaces. A detached piece says nothing of the instance either: the
    /// instances seen only on a segment's detached pieces get no vote to merge from it.
    fn detached_pieces(
        &self,
        labels: &LabelImage,
        segments: &[Segment],
        observed: &Observation,
        surface: &mut Surface,
        matched: &[Option<u16>],
        tables: &IdTables,
    ) -> Detached {
        let mut detached = Detached::default();
        let wanted: Vec<bool> = segments
            .iter()
            .map(|s| s.is_thing == Some(false) && s.class_id.is_some_and(|c| !self.is_shell(c)))
            .collect();
        if !wanted.contains(&true) {
            return detached;
        }
        let dims = labels.dims();
        let (width, step) = (dims.0, observed.step);
        let all_pieces = segment_pieces(labels, &tables.slot, &wanted);
        for ((s, pieces), &continued) in segments.iter().zip(all_pieces).zip(matched) {
            if pieces.len() < 2 {
                continue;
            }
            let mut blocks: Vec<Vec<BlockIndex>> = Vec::with_capacity(pieces.len());
            let mut part: Vec<bool> = Vec::with_capacity(pieces.len());
            let mut seen: Vec<Vec<u16>> = Vec::with_capacity(pieces.len());
            for piece in &pieces {
                // The coarse grid's samples in the piece; a piece between them reads its own.
                let mut samples: Vec<Sample> = Vec::new();
                for run in piece {
                    let sy = run.y / step;
                    if observed.pixel(0, sy, dims).1 != run.y {
                        continue;
                    }
                    for sx in run.x.start / step..=(run.x.end - 1) / step {
                        if run.x.contains(&observed.pixel(sx, sy, dims).0) {
                            samples.push(observed.samples[sy * observed.width + sx]);
                        }
                    }
                }
                if samples.is_empty() {
                    for run in piece {
                        samples.extend(run.x.clone().map(|x| surface.sample(x, run.y)));
                    }
                }
                let mut measured: Vec<BlockIndex> = samples
                    .iter()
                    .filter(|x| x.label.is_some() && x.integrated)
                    .map(|x| x.block)
                    .collect();
                measured.sort_unstable();
                measured.dedup();
                let mut on: Vec<u16> = samples
                    .iter()
                    .filter_map(|x| x.label.filter(|&l| l != 0))
                    .collect();
                on.sort_unstable();
                on.dedup();
                let belongs = match continued {
                    None => true,
                    Some(i) => {
                        samples
                            .iter()
                            .any(|x| x.label == Some(i) || x.challenger == i)
                            || surface.instance_near(i, &measured)
                    }
                };
                part.push(!measured.is_empty() && belongs);
                blocks.push(measured);
                seen.push(on);
            }
            // New surface reached through another piece: a rug seen further on, cut in two by
            // a chair leg.
            let mut reach: rustc_hash::FxHashSet<BlockIndex> = (0..pieces.len())
                .filter(|&x| part[x])
                .flat_map(|x| blocks[x].iter().copied())
                .collect();
            loop {
                let reached: Vec<usize> = (0..pieces.len())
                    .filter(|&x| {
                        !part[x]
                            && blocks[x]
                                .iter()
                                .any(|&b| with_neighbours(b).any(|n| reach.contains(&n)))
                    })
                    .collect();
                if reached.is_empty() {
                    break;
                }
                for x in reached {
                    part[x] = true;
                    reach.extend(blocks[x].iter().copied());
                }
            }
            let kept: Vec<u16> = (0..pieces.len())
                .filter(|&x| part[x])
                .flat_map(|x| seen[x].iter().copied())
                .collect();
            for x in (0..pieces.len()).filter(|&x| !part[x]) {
                for run in &pieces[x] {
                    detached
                        .pixels
                        .extend(run.x.clone().map(|px| run.y * width + px));
                }
                for &j in &seen[x] {
                    if !kept.contains(&j) {
                        detached.only_off.push((s.id, j));
                    }
                }
            }
        }
        detached.only_off.sort_unstable();
        detached.only_off.dedup();
        detached
    }

    /// The frame's instance image (`to_instance`: segment id to instance). Stuff never
    /// overwrites a flush thing in view (see [`Self::is_flush`]) that no segment of this
    /// frame continues: the network missed it, and refinement cannot cut a stuff mask off a
    /// surface at its own depth. Off a thing standing clear of it refinement does cut it, so
    /// stuff landing on such a thing's voxels is where the thing's earlier masks bled (a
    /// false fragment on the wall joined into the table in front of it) and takes them back.
    /// Where a segment does continue a thing, what lies outside it is the segmenter saying
    /// the thing does not reach there, and the stuff around may take those voxels back.
    fn instance_image(
        &self,
        labels: &LabelImage,
        segments: &[Segment],
        observed: &Observation,
        to_instance: &BTreeMap<u16, u16>,
        tables: &mut IdTables,
    ) -> LabelImage {
        let step = observed.step;
        for s in segments {
            if let Some(&i) = to_instance.get(&s.id) {
                tables.target[s.id as usize] = i;
                tables.target_on_thing[s.id as usize] =
                    if s.is_thing == Some(false) { 0 } else { i };
            }
        }
        // Thing instances in view looked up once each, not once per sample.
        let thing = &mut tables.thing;
        for &id in &tables.seen {
            thing[id as usize] =
                self.instances.get(&id).is_some_and(|i| i.is_thing()) && self.is_flush(id);
        }
        for &id in to_instance.values() {
            thing[id as usize] = false;
        }
        let thing_sample: Vec<bool> = observed
            .samples
            .iter()
            .map(|s| s.label.is_some_and(|id| thing[id as usize]))
            .collect();
        // Whole-id-range tables: a u16 label indexes them without bounds checks.
        let table: fn(&[u16]) -> &[u16; IDS] = |t| t.try_into().expect("ready");
        let (target, target_on_thing) = (table(&tables.target), table(&tables.target_on_thing));
        let (lw, lh) = labels.dims();
        let mut pixels = Vec::with_capacity(lw * lh);
        for (y, row) in labels.pixels().chunks_exact(lw).enumerate() {
            let start = (y / step) * observed.width;
            let samples = &thing_sample[start..start + observed.width];
            // A sample covers `step` pixels of the row: which table applies is decided once
            // for them.
            for (run, &on_thing) in row.chunks(step).zip(samples) {
                let to = if on_thing { target_on_thing } else { target };
                pixels.extend(run.iter().map(|&l| to[l as usize]));
            }
        }
        LabelImage::from_vec(lw, lh, pixels).expect("a pixel per label")
    }
}

/// Two segments that touch in the image (smaller id first), with how many neighbouring
/// samples across their boundary lie on one continuous surface and how many across a depth
/// edge.
struct Touching {
    segments: (u16, u16),
    continuous: usize,
    across_edge: usize,
}

/// The frame's touching segments matched to two different instances (`to_instance`: segment
/// id to instance): the two instances, and how their segments meet.
fn instances_meeting<'a>(
    touching: &'a [Touching],
    to_instance: &'a BTreeMap<u16, u16>,
) -> impl Iterator<Item = (u16, u16, &'a Touching)> {
    touching.iter().filter_map(|t| {
        let (a, b) = t.segments;
        let (&i, &j) = (to_instance.get(&a)?, to_instance.get(&b)?);
        (i != j).then_some((i, j, t))
    })
}

impl Touching {
    /// Whether the two meet mostly across one continuous surface: between two things of one
    /// class, the network cutting one object.
    fn cut(&self) -> bool {
        self.continuous > self.across_edge
    }
}

/// The frame's instances linked through boundaries that are cuts (`met`: pairs of instances
/// whose segments touch, and whether that boundary is a cut; `apart`: the pairs counted told
/// apart, sorted), as a function from instance to the smallest instance of its chain. Two
/// segments of one class that do not touch but are linked so (a row of books segmented book
/// by book, a chair cut in three whose middle part went to a third instance) are pieces of one
/// object the network cut, not two objects.
fn cut_objects(met: &[((u16, u16), bool)], apart: &[(u16, u16)]) -> impl Fn(u16) -> u16 + use<> {
    let mut parent: BTreeMap<u16, u16> = BTreeMap::new();
    let root = |parent: &BTreeMap<u16, u16>, mut id: u16| {
        while let Some(&up) = parent.get(&id) {
            id = up;
        }
        id
    };
    for &(pair, cut) in met {
        if cut && apart.binary_search(&pair).is_err() {
            let (a, b) = (root(&parent, pair.0), root(&parent, pair.1));
            if a != b {
                parent.insert(a.max(b), a.min(b));
            }
        }
    }
    move |id| root(&parent, id)
}

/// Thing segments nothing vouched for (see [`InstanceTracker::match_vouched`]) that meet a
/// segment of their class mostly across one continuous surface continue that segment's
/// instance (`matched`, by segment; `touching`, the frame's segments that touch; `tables.slot`,
/// segment id to index). The network cut one object, and the piece lies where the map does not
/// hold the object yet (a table's far end coming into view, a chair's legs over the floor):
/// founding an instance for it left a false object whenever the pieces never joined. The
/// same boundary does not tell the two instances apart either (see
/// [`InstanceTracker::record_apart`]). A piece continues through a chain of such pieces, but
/// not where `held_as_other(piece, instance)` says the map holds it as an object it cannot be
/// (a shelf's mask called `books` for a frame, touching the books on it, took the shelf's
/// surface for one book).
fn continue_cut_pieces(
    segments: &[Segment],
    touching: &[Touching],
    tables: &IdTables,
    held_as_other: impl Fn(usize, u16) -> bool,
    matched: &mut [Option<u16>],
) {
    let cuts: Vec<(usize, usize)> = touching
        .iter()
        .filter(|t| t.cut())
        .filter_map(|t| {
            // Labels no listed segment holds have no slot (and no match).
            let index = |id: u16| {
                let k = tables.slot[id as usize] as usize;
                (k < segments.len()).then_some(k)
            };
            Some((index(t.segments.0)?, index(t.segments.1)?))
        })
        .filter(|&(a, b)| {
            let (a, b) = (&segments[a], &segments[b]);
            a.is_thing == Some(true)
                && b.is_thing == Some(true)
                && a.class_id.is_some()
                && a.class_id == b.class_id
        })
        .collect();
    let mut changed = true;
    while changed {
        changed = false;
        for &(a, b) in &cuts {
            let (piece, i) = match (matched[a], matched[b]) {
                (Some(i), None) => (b, i),
                (None, Some(i)) => (a, i),
                _ => continue,
            };
            if !held_as_other(piece, i) {
                matched[piece] = Some(i);
                changed = true;
            }
        }
    }
}

/// What [`InstanceTracker::decide`] made of the frame's segments.
#[derive(Default)]
struct Decided {
    /// Segment id to the instance it becomes.
    to_instance: BTreeMap<u16, u16>,
    stats: AssociationStats,
    /// Pairs of instances one segment covered most of (smaller id first; repeats allowed).
    votes: Vec<(u16, u16)>,
    /// Pairs of instances one segment covered most of though they cannot merge frame by
    /// frame, where that says "the same object renamed" (see [`InstanceTracker::says_renamed`]).
    covered_renamed: Vec<(u16, u16)>,
    /// Of `votes`, the pairs a group's segment covered, one of them of another name.
    gathered: Vec<(u16, u16)>,
    /// Pairs of a new instance and the settled thing of another class its founding segment
    /// covered each way.
    founded_over: Vec<(u16, u16)>,
}

/// What [`InstanceTracker::detached_pieces`] leaves out of a frame's instance image.
#[derive(Default)]
struct Detached {
    /// Row-major pixel indices.
    pixels: Vec<usize>,
    /// `(segment id, instance)`: instances seen only on the segment's detached pieces
    /// (sorted).
    only_off: Vec<(u16, u16)>,
}

/// Evidence per segment (in its list's order), and each instance's samples in the frame
/// (`tables.visible`, `visible_integrated`, `runner_up`, listed in `tables.seen`). Segments
/// read on the coarse grid, except that small ones read every pixel of theirs from `surface`:
/// the grid gives a segment of a few dozen pixels (a plate, a lamp across the room) one sample
/// or none.
fn gather_evidence(
    labels: &LabelImage,
    segments: &[Segment],
    observed: &Observation,
    surface: &mut Surface,
    tables: &mut IdTables,
) -> Vec<SegmentEvidence> {
    let step = observed.step;
    let area = step * step;
    let slot = &mut tables.slot;
    for (k, s) in segments.iter().enumerate() {
        slot[s.id as usize] = k as u32;
    }
    let mut evidence: Vec<SegmentEvidence> = segments
        .iter()
        .map(|_| SegmentEvidence::default())
        .collect();
    let visible = &mut tables.visible;
    let visible_integrated = &mut tables.visible_integrated;
    let runner_up = &mut tables.runner_up;
    let dims = labels.dims();
    for sy in 0..observed.height {
        for sx in 0..observed.width {
            let (x, y) = observed.pixel(sx, sy, dims);
            let segment = evidence.get_mut(slot[*labels.get(x, y) as usize] as usize);
            let sample = observed.samples[sy * observed.width + sx];
            if let Some(seen) = sample.label.filter(|&l| l != 0) {
                list_first_sight(seen, visible, runner_up, &mut tables.seen);
                visible[seen as usize] += 1;
                visible_integrated[seen as usize] += sample.integrated as u32;
                if sample.challenger != 0 {
                    list_first_sight(sample.challenger, visible, runner_up, &mut tables.seen);
                    runner_up[sample.challenger as usize] += 1;
                }
            }
            if let Some(e) = segment {
                e.add(sample, area);
            }
        }
    }
    // Small by the coarse grid's count, so that frames without them cost no pass over the
    // labels.
    let small: Vec<bool> = evidence
        .iter()
        .map(|e| area > 1 && e.pixels < FINE_BELOW_SAMPLES * area)
        .collect();
    if small.contains(&true) {
        for (k, extent) in segment_extents(labels, slot, &small)
            .into_iter()
            .enumerate()
        {
            let Some(extent) = extent else {
                continue;
            };
            let id = segments[k].id;
            let e = &mut evidence[k];
            *e = SegmentEvidence::default();
            for y in extent.y.clone() {
                for x in extent.x.clone() {
                    if *labels.get(x, y) == id {
                        e.add(surface.sample(x, y), 1);
                    }
                }
            }
        }
    }
    evidence
}

/// Orders `(instance, count)` pairs for `max_by`: the larger count wins, ties go to the
/// smaller id (the older instance).
fn most_then_smallest_id<N: Ord>(a: &(u16, N), b: &(u16, N)) -> std::cmp::Ordering {
    a.1.cmp(&b.1).then(b.0.cmp(&a.0))
}

/// Re-keys what `pairs` holds about instance `from` (merged away) to `into`: each pair with
/// `from` becomes the pair with `into`, `add`ed to what that pair held; the pair of the two
/// goes.
fn pool_pair_keys<V: Copy + Default>(
    pairs: &mut BTreeMap<(u16, u16), V>,
    from: u16,
    into: u16,
    add: impl Fn(&mut V, V),
) {
    let moved: Vec<((u16, u16), V)> = pairs
        .iter()
        .filter(|((a, b), _)| *a == from || *b == from)
        .map(|(&k, &v)| (k, v))
        .collect();
    for ((a, b), value) in moved {
        pairs.remove(&(a, b));
        let other = if a == from { b } else { a };
        if other != into {
            add(
                pairs.entry((other.min(into), other.max(into))).or_default(),
                value,
            );
        }
    }
}

/// The pairs of segment ids that touch in `labels` (each pair once, smaller id first), read on
/// the association grid of `observed`: a sample and its right and lower neighbours.
fn touching_segments(labels: &LabelImage, observed: &Observation) -> Vec<Touching> {
    let (width, height) = (observed.width, observed.height);
    let at = |sx: usize, sy: usize| {
        let (x, y) = observed.pixel(sx, sy, labels.dims());
        (*labels.get(x, y), &observed.samples[sy * width + sx])
    };
    // One entry per neighbouring pair of samples on two segments: (segments, continuous).
    let mut meetings: Vec<((u16, u16), Option<bool>)> = Vec::new();
    for sy in 0..height {
        for sx in 0..width {
            let (a, sample_a) = at(sx, sy);
            if a == 0 {
                continue;
            }
            for (nx, ny) in [(sx + 1, sy), (sx, sy + 1)] {
                if nx < width && ny < height {
                    let (b, sample_b) = at(nx, ny);
                    if b != 0 && b != a {
                        let continuous = observed.continuous(sample_a, sample_b);
                        meetings.push(((a.min(b), a.max(b)), continuous));
                    }
                }
            }
        }
    }
    meetings.sort_unstable_by_key(|&(pair, _)| pair);
    meetings
        .chunk_by(|x, y| x.0 == y.0)
        .map(|run| Touching {
            segments: run[0].0,
            continuous: run.iter().filter(|m| m.1 == Some(true)).count(),
            across_edge: run.iter().filter(|m| m.1 == Some(false)).count(),
        })
        .collect()
}

/// Segments with fewer samples of the coarse grid than this read every pixel of theirs. A
/// segment's match is a majority of its samples: with 16 the share of a segment's samples on an
/// instance is known to about an eighth (½ / √16), so a majority of ½ is told from a quarter or
/// three quarters. Larger segments keep the grid's samples; the extra reads are the small
/// segments' own pixels (and a scan of their bounding boxes).
const FINE_BELOW_SAMPLES: usize = 16;

/// A run of one segment's pixels along row `y`.
struct Run {
    y: usize,
    x: std::ops::Range<usize>,
}

/// The 4-connected pieces of each segment whose index is `wanted` (`slot`: segment id → its
/// index, or `u32::MAX`), each as runs of equal labels along rows, joined where runs of
/// neighbouring rows overlap.
fn segment_pieces(labels: &LabelImage, slot: &[u32], wanted: &[bool]) -> Vec<Vec<Vec<Run>>> {
    fn root(parent: &mut [usize], mut r: usize) -> usize {
        while parent[r] != r {
            parent[r] = parent[parent[r]];
            r = parent[r];
        }
        r
    }
    let width = labels.dims().0;
    let mut runs: Vec<(usize, Run)> = Vec::new();
    let mut parent: Vec<usize> = Vec::new();
    // Per segment: its runs in the row before the current one, in this row, and which row
    // that is.
    let mut above: Vec<Vec<usize>> = vec![Vec::new(); wanted.len()];
    let mut here: Vec<Vec<usize>> = vec![Vec::new(); wanted.len()];
    let mut here_row: Vec<usize> = vec![usize::MAX; wanted.len()];
    for (y, row) in labels.pixels().chunks_exact(width).enumerate() {
        for (id, x) in label_runs(row) {
            let k = slot[id as usize] as usize;
            if !wanted.get(k).copied().unwrap_or(false) {
                continue;
            }
            if here_row[k] != y {
                if here_row[k].wrapping_add(1) == y {
                    std::mem::swap(&mut above[k], &mut here[k]);
                } else {
                    above[k].clear();
                }
                here[k].clear();
                here_row[k] = y;
            }
            let r = runs.len();
            parent.push(r);
            for &a in &above[k] {
                let over = &runs[a].1.x;
                if over.start < x.end && x.start < over.end {
                    let (ra, rr) = (root(&mut parent, a), root(&mut parent, r));
                    parent[ra.max(rr)] = ra.min(rr);
                }
            }
            here[k].push(r);
            runs.push((k, Run { y, x }));
        }
    }
    let mut pieces: Vec<Vec<Vec<Run>>> = (0..wanted.len()).map(|_| Vec::new()).collect();
    let mut piece_of_root: FxHashMap<usize, usize> = FxHashMap::default();
    for (r, (k, run)) in runs.into_iter().enumerate() {
        let top = root(&mut parent, r);
        let p = *piece_of_root.entry(top).or_insert_with(|| {
            pieces[k].push(Vec::new());
            pieces[k].len() - 1
        });
        pieces[k][p].push(run);
    }
    pieces
}

/// Where a segment lies in the label image: its bounding box.
#[derive(Clone, Debug)]
struct Extent {
    x: std::ops::RangeInclusive<usize>,
    y: std::ops::RangeInclusive<usize>,
}

/// The bounding box of each segment whose index is `wanted` (`slot`: segment id → its index,
/// or `u32::MAX`); `None` for the others and for segments without a pixel. Found by runs of
/// equal labels along rows.
fn segment_extents(labels: &LabelImage, slot: &[u32], wanted: &[bool]) -> Vec<Option<Extent>> {
    let mut extents: Vec<Option<Extent>> = vec![None; wanted.len()];
    let width = labels.dims().0;
    for (y, row) in labels.pixels().chunks_exact(width).enumerate() {
        for (id, run) in label_runs(row) {
            let (start, end) = (run.start, run.end - 1);
            let k = slot[id as usize] as usize;
            if let Some(extent) = extents.get_mut(k).filter(|_| wanted[k]) {
                match extent {
                    Some(e) => {
                        e.x = (*e.x.start()).min(start)..=(*e.x.end()).max(end);
                        e.y = *e.y.start()..=y;
                    }
                    None => {
                        *extent = Some(Extent {
                            x: start..=end,
                            y: y..=y,
                        })
                    }
                }
            }
        }
    }
    extents
}

/// Lists instance `id` in `seen` on the frame's first sample of it, as leader or runner-up
/// (before either count is raised).
fn list_first_sight(id: u16, visible: &[u32], runner_up: &[u32], seen: &mut Vec<u16>) {
    if visible[id as usize] == 0 && runner_up[id as usize] == 0 {
        seen.push(id);
    }
}

/// An instance must be visible on at least this many samples for a segment to vote to merge
/// it: with 4×4-pixel samples, 64 pixels — less is a sliver at the segment's edge.
const MIN_MERGE_SAMPLES: usize = 4;

#[cfg(test)]
mod tests {
    use super::*;

    /// A confirmed instance seen as `class`, a thing or stuff.
    fn confirmed(class: u32, thing: bool) -> InstanceInfo {
        InstanceInfo {
            class_votes: [(class, 5)].into(),
            thing_votes: if thing { [5, 0] } else { [0, 5] },
            frames_seen: 5,
            confirmed: true,
            ..InstanceInfo::default()
        }
    }

    /// A tracker knowing a table (thing, 40), its stuff `table-merged` (41), a wall (stuff, 1)
    /// and a tv (thing, 62), each in its family but the two tables.
    fn tracker_with(instances: &[(u16, InstanceInfo)]) -> InstanceTracker {
        let mut tracker = InstanceTracker::with_instances(
            TrackingConfig::default(),
            instances.iter().cloned().collect(),
        );
        let names = [(1, "wall"), (40, "table"), (41, "table-merged"), (62, "tv")];
        let names = names.map(|(c, n)| (c, n.to_owned())).into();
        tracker.set_families(class_families(&names));
        tracker
    }

    fn segment(class: u32, thing: bool) -> Segment {
        Segment {
            id: 1,
            class_id: Some(class),
            is_thing: Some(thing),
            score: None,
        }
    }

    #[test]
    fn a_mask_over_an_instance_it_cannot_continue_says_renamed_only_for_its_own_object() {
        let tracker = tracker_with(&[
            (1, confirmed(40, true)),
            (2, confirmed(41, false)),
            (3, confirmed(62, true)),
        ]);
        // A table's mask over the stuff `table-merged` piece of it.
        assert!(tracker.says_renamed(&segment(40, true), 2));
        // A `table-merged` mask over the table: the same family.
        assert!(tracker.says_renamed(&segment(41, false), 1));
        // A wall's mask over a tv is the network missing the tv.
        assert!(!tracker.says_renamed(&segment(1, false), 3));
    }

    /// Consolidates instances 1 and 2, meeting along a long seam, with `evidence` for the pair.
    fn joins(a: InstanceInfo, b: InstanceInfo, evidence: PairEvidence) -> bool {
        let mut tracker = tracker_with(&[(1, a), (2, b)]);
        tracker.pairs.insert((1, 2), evidence);
        let touching = [((1, 2), 100)].into_iter().collect();
        let surface = [(1, 400), (2, 300)].into_iter().collect();
        !tracker.consolidate(&touching, &surface).is_empty()
    }

    #[test]
    fn a_thing_and_its_stuff_piece_covered_together_more_often_than_apart_join() {
        let table = || confirmed(40, true);
        let piece = || confirmed(41, false);
        let evidence = |apart, together_renamed| PairEvidence {
            together: 0,
            apart,
            together_renamed,
            ..PairEvidence::default()
        };
        assert!(joins(table(), piece(), evidence(2, 3)));
        assert!(
            !joins(table(), piece(), evidence(3, 3)),
            "a tie is not more often"
        );
        assert!(joins(table(), piece(), evidence(0, 0)), "never told apart");
        // Between two things the count is a mask over-covering its neighbour (a table's over
        // its cup) as often as a renaming: it is not read.
        let cup = confirmed(62, true);
        assert!(!joins(table(), cup, evidence(1, 5)));
    }

    #[test]
    fn a_group_gathering_a_thing_of_another_name_must_outvote_its_telling_apart() {
        // A table and a tv meeting along a seam: covered together in one frame and told
        // apart in one, a tie, which joins two things covered by their own class's masks.
        let tie = |gathered| PairEvidence {
            together: 1,
            apart: 1,
            gathered,
            ..PairEvidence::default()
        };
        assert!(joins(confirmed(40, true), confirmed(62, true), tie(0)));
        // The cover was a row of books' segment gathering the tv: the tie does not join.
        assert!(!joins(confirmed(40, true), confirmed(62, true), tie(1)));
        let more = PairEvidence {
            together: 2,
            ..tie(1)
        };
        assert!(joins(confirmed(40, true), confirmed(62, true), more));
    }

    /// A `w`×`h` label image of ids below `ids`: diagonal bands `band` pixels wide and high,
    /// a quarter of the pixels speckled at random (seeded by `seed`).
    fn speckled_bands(w: usize, h: usize, seed: u32, ids: u32, band: (usize, usize)) -> Vec<u16> {
        let mut state = seed;
        (0..w * h)
            .map(|i| {
                state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                let (x, y) = (i % w, i / w);
                match (state >> 16) % 4 {
                    0 => ((state >> 8) % ids) as u16,
                    _ => ((x / band.0 + y / band.1) as u32 % ids) as u16,
                }
            })
            .collect()
    }

    #[test]
    fn segment_pieces_match_a_flood_fill() {
        // Speckle over bands: pieces of every shape, U shapes whose arms join rows later.
        let (w, h) = (41, 29);
        let pixels = speckled_bands(w, h, 777, 4, (5, 6));
        let labels = LabelImage::from_vec(w, h, pixels.clone()).unwrap();
        let listed = [2u16, 1, 3];
        let mut slot = vec![u32::MAX; IDS];
        for (k, &id) in listed.iter().enumerate() {
            slot[id as usize] = k as u32;
        }
        let wanted = [true, true, false];
        let pieces = segment_pieces(&labels, &slot, &wanted);
        assert!(pieces[2].is_empty(), "segment 3 is not wanted");
        // The reference: a 4-connected flood fill from every pixel not yet reached.
        let mut component = vec![usize::MAX; w * h];
        let mut sizes = Vec::new();
        for start in 0..w * h {
            if component[start] != usize::MAX {
                continue;
            }
            let (c, id) = (sizes.len(), pixels[start]);
            let (mut stack, mut size) = (vec![start], 0);
            component[start] = c;
            while let Some(p) = stack.pop() {
                size += 1;
                let (x, y) = (p % w, p / w);
                let around = [
                    (x > 0).then(|| p - 1),
                    (x + 1 < w).then(|| p + 1),
                    (y > 0).then(|| p - w),
                    (y + 1 < h).then(|| p + w),
                ];
                for n in around.into_iter().flatten() {
                    if component[n] == usize::MAX && pixels[n] == id {
                        component[n] = c;
                        stack.push(n);
                    }
                }
            }
            sizes.push(size);
        }
        for (k, &id) in listed.iter().enumerate().filter(|&(k, _)| wanted[k]) {
            let mut found: Vec<usize> = Vec::new();
            for piece in &pieces[k] {
                let at: Vec<usize> = piece
                    .iter()
                    .flat_map(|run| run.x.clone().map(move |x| run.y * w + x))
                    .collect();
                assert!(at.iter().all(|&p| pixels[p] == id));
                let c = component[at[0]];
                assert!(
                    at.iter().all(|&p| component[p] == c),
                    "two components in one piece"
                );
                assert_eq!(at.len(), sizes[c], "a component cut in pieces");
                found.push(c);
            }
            let mut expected: Vec<usize> = (0..w * h)
                .filter(|&p| pixels[p] == id)
                .map(|p| component[p])
                .collect();
            expected.sort_unstable();
            expected.dedup();
            found.sort_unstable();
            assert_eq!(found, expected, "segment {id}");
            assert!(found.len() > 3, "segment {id} in few pieces: a weak test");
        }
    }

    #[test]
    fn segment_extents_bound_every_wanted_segment() {
        // Blobs and speckle: runs of every length, segments split across rows and columns.
        let (w, h) = (37, 23);
        let pixels = speckled_bands(w, h, 12345, 7, (9, 7));
        let labels = LabelImage::from_vec(w, h, pixels).unwrap();
        // Segments 1..=5 and 9 (never present); 0 and 6 unlisted; 5 listed but not wanted.
        let listed = [3u16, 1, 5, 2, 4, 9];
        let mut slot = vec![u32::MAX; IDS];
        for (k, &id) in listed.iter().enumerate() {
            slot[id as usize] = k as u32;
        }
        let mut wanted = vec![true; listed.len()];
        wanted[2] = false;
        let extents = segment_extents(&labels, &slot, &wanted);
        assert!(extents[2].is_none(), "segment 5 is not wanted");
        for (k, &id) in listed.iter().enumerate().filter(|&(k, _)| wanted[k]) {
            let at: Vec<(usize, usize)> = (0..w * h)
                .filter(|&i| labels.pixels()[i] == id)
                .map(|i| (i % w, i / w))
                .collect();
            let Some(e) = &extents[k] else {
                assert!(at.is_empty(), "segment {id} has pixels");
                continue;
            };
            let xs = at.iter().map(|p| p.0);
            let ys = at.iter().map(|p| p.1);
            assert_eq!(e.x, xs.clone().min().unwrap()..=xs.max().unwrap(), "{id}");
            assert_eq!(e.y, ys.clone().min().unwrap()..=ys.max().unwrap(), "{id}");
        }
        assert!(extents[5].is_none());
    }
}
