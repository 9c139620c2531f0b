//! What a voxel holds, in 12 bytes: the TSDF's distance as a 16-bit fraction of the truncation
//! distance, its weight as a bfloat16, and the colour (7 bytes), and two instance candidates with
//! 4-bit counts (5 bytes). Both structs are packed (no padding); their fields are read and
//! written by value.

use half::bf16;

use crate::lanes::Lanes;

/// One voxel of the TSDF: signed distance to the nearest surface along the camera rays
/// (positive in front), its fusion weight (0 = never observed) and the fused colour.
///
/// The distance is stored as a fraction of the truncation distance in 16 bits (KinectFusion's
/// encoding): steps of 1/32767 of the band, 1.8 µm at 2 cm voxels and truncation 3, so even
/// a voxel whose weight is hundreds of frames moves when a frame disagrees by half a
/// millimetre. [`Layer::distance`](super::Layer::distance) gives metres. The weight is a
/// bfloat16 (8 significant bits, cheap to convert): it stops growing once a frame adds under
/// 1/512 to 1/256 of it (by where it lies between powers of two), so after a few hundred frames
/// a voxel still follows a moved surface; this, not `tsdf.max_weight`, is what bounds weights
/// in practice (voxblox's `max_weight` plays the same role).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, packed)]
pub struct TsdfVoxel {
    tsdf: i16,
    weight: bf16,
    color: [u8; 3],
}

/// The bits of the bfloat16 nearest to `x` (ties to even), for finite `x`: the upper half of its
/// f32 bits, rounded. Weights are finite, so half's NaN handling is not needed per voxel
/// (wrapping: no input panics).
fn round_to_bfloat(x: f32) -> u16 {
    let bits = x.to_bits();
    (bits.wrapping_add(0x7fff + ((bits >> 16) & 1)) >> 16) as u16
}

/// The smallest and largest positive finite weights a voxel holds (bfloat16's).
pub(crate) const MIN_WEIGHT: f32 = f32::from_bits(0x0001_0000);
pub(crate) const MAX_WEIGHT: f32 = f32::from_bits(0x7f7f_0000);

/// Steps of the stored distance per truncation distance.
pub(crate) const TSDF_STEPS: f32 = i16::MAX as f32;

impl TsdfVoxel {
    /// `tsdf` is the distance over the truncation distance; values beyond ±1 are clamped.
    /// `weight` is finite and not negative.
    pub fn new(tsdf: f32, weight: f32, color: [u8; 3]) -> Self {
        let steps = tsdf * TSDF_STEPS;
        Self {
            // Rounds half away from zero: `as` truncates, saturates (the clamp to ±1) and turns
            // NaN into 0; the `max` keeps `i16::MIN` free to mark unobserved voxels.
            tsdf: ((steps + 0.5f32.copysign(steps)) as i16).max(-i16::MAX),
            weight: bf16::from_bits(round_to_bfloat(weight)),
            color,
        }
    }

    /// Eight voxels' stored parts at once, each as [`Self::new`] would store it: the
    /// distances in steps (`tsdf` over the truncation distance) and the weights' bfloat16
    /// bits. The integrator encodes a row of voxels with it.
    #[inline(always)]
    pub(crate) fn encode_lanes<L: Lanes>(tsdf: L, weight: L) -> ([i16; 8], [u16; 8]) {
        L::encode(tsdf, weight)
    }

    /// Eight stored distances in steps, as [`Self::tsdf`] decodes each.
    #[inline(always)]
    pub(crate) fn decode_lanes<L: Lanes>(steps: [i16; 8]) -> L {
        L::decode_steps(steps)
    }

    /// Eight stored weights' bfloat16 bits, as [`Self::weight`] decodes each.
    #[inline(always)]
    pub(crate) fn weight_lanes<L: Lanes>(bits: [u16; 8]) -> L {
        L::from_bfloat(bits)
    }

    /// The stored weight's bfloat16 bits.
    pub(crate) fn weight_bits(&self) -> u16 {
        self.weight.to_bits()
    }

    /// A voxel from [`Self::encode_lanes`]'s parts.
    pub(crate) fn from_parts(tsdf_steps: i16, weight_bits: u16, color: [u8; 3]) -> Self {
        Self {
            tsdf: tsdf_steps,
            weight: bf16::from_bits(weight_bits),
            color,
        }
    }

    /// The stored distance in steps of 1/32767 of the truncation distance.
    pub fn tsdf_steps(&self) -> i16 {
        self.tsdf
    }

    /// The distance over the truncation distance, in [-1, 1].
    pub fn tsdf(&self) -> f32 {
        self.tsdf as f32 * (1.0 / TSDF_STEPS)
    }

    pub fn weight(&self) -> f32 {
        self.weight.to_f32()
    }

    pub fn color(&self) -> [u8; 3] {
        self.color
    }

    #[cfg(test)]
    pub fn set_tsdf(&mut self, tsdf: f32) {
        *self = Self::new(tsdf, self.weight(), self.color);
    }

    pub fn observed(&self) -> bool {
        // Weights are never negative: any set bit is a positive weight.
        self.weight.to_bits() != 0
    }
}

/// The largest count a candidate holds (4 bits).
pub(crate) const MAX_LABEL_COUNT: u16 = 15;

/// Instance evidence of one voxel: the two strongest candidates and their counts, updated like
/// a two-slot Misra-Gries summary (a label that keeps being seen displaces a stale one).
///
/// Counts are 4 bits each. When the leader would pass 15 both counts halve (rounding up), so
/// the ratio between the candidates is kept and old evidence fades: a voxel follows what its
/// last dozen or so observations say, as a decaying vote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, packed)]
pub struct LabelVoxel {
    ids: [u16; 2],
    /// The leader's count in the low nibble, the challenger's in the high one.
    counts: u8,
}

impl LabelVoxel {
    /// Candidates and counts as a map file stores them; counts above 15 (maps saved before
    /// counts had 4 bits) are halved until they fit, keeping their ratio.
    pub fn from_parts(ids: [u16; 2], counts: [u16; 2]) -> Self {
        let mut v = Self::default();
        v.store(ids, counts);
        v
    }

    pub fn ids(&self) -> [u16; 2] {
        self.ids
    }

    pub fn counts(&self) -> [u16; 2] {
        [self.leader_count(), u16::from(self.counts >> 4)]
    }

    fn leader_count(&self) -> u16 {
        u16::from(self.counts & 0xf)
    }

    /// Keeps the leader first and the counts within 4 bits.
    fn store(&mut self, mut ids: [u16; 2], mut counts: [u16; 2]) {
        if counts[1] > counts[0] {
            ids.swap(0, 1);
            counts.swap(0, 1);
        }
        while counts[0] > MAX_LABEL_COUNT {
            counts = counts.map(|c| c.div_ceil(2));
        }
        self.ids = ids;
        self.counts = (counts[0] | counts[1] << 4) as u8;
    }

    /// The most supported instance (0 = none).
    pub fn instance(&self) -> u16 {
        if self.leader_count() > 0 {
            self.ids[0]
        } else {
            0
        }
    }

    /// The runner-up instance (0 = none): what a voxel is also seen as, such as an object
    /// on a surface first mapped as the surface.
    pub fn challenger(&self) -> u16 {
        if self.counts >> 4 > 0 { self.ids[1] } else { 0 }
    }

    /// Calls instance `from` `into` from now on; returns whether anything changed.
    pub fn relabel(&mut self, from: u16, into: u16) -> bool {
        // Most voxels of a map hold neither: a merge visits every voxel.
        let ids = self.ids;
        if ids[0] != from && ids[1] != from {
            return false;
        }
        let (mut ids, mut counts) = (ids, self.counts());
        let mut changed = false;
        for k in 0..2 {
            if counts[k] > 0 && ids[k] == from {
                ids[k] = into;
                changed = true;
            }
        }
        if changed && counts[1] > 0 && ids[0] == ids[1] {
            counts[0] += counts[1];
            counts[1] = 0;
            ids[1] = 0;
        }
        self.store(ids, counts);
        changed
    }

    /// One observation of instance `id` (non-zero) that takes the lead: the leader stays as
    /// the runner-up with its count, and `id` leads with one more. For a thing seen where stuff
    /// leads (see `associate::claims`): later stuff observations win the voxel back only
    /// where they are allowed to count, two of them against one of the thing's.
    pub fn observe_over(&mut self, id: u16) {
        let [leader, _] = self.ids;
        let lead = self.leader_count();
        if lead == 0 || leader == id {
            self.observe(id);
            return;
        }
        self.store([id, leader], [lead + 1, lead]);
    }

    /// One observation of instance `id` (non-zero).
    pub fn observe(&mut self, id: u16) {
        // The common case, the leader seen again below the cap: one add.
        let leader = self.leader_count();
        if leader > 0 && leader < MAX_LABEL_COUNT && self.ids[0] == id {
            self.counts += 1;
            return;
        }
        let (mut ids, mut counts) = (self.ids, self.counts());
        if counts[0] > 0 && ids[0] == id {
            counts[0] += 1;
        } else if counts[1] > 0 && ids[1] == id {
            counts[1] += 1;
        } else if counts[0] == 0 {
            ids[0] = id;
            counts[0] = 1;
        } else if counts[1] == 0 {
            ids[1] = id;
            counts[1] = 1;
        } else {
            // Both slots taken by others: weaken the weaker; replace it once it is gone.
            counts[1] -= 1;
            if counts[1] == 0 {
                ids[1] = id;
                counts[1] = 1;
            }
        }
        self.store(ids, counts);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn observe_times(v: &mut LabelVoxel, id: u16, times: usize) {
        for _ in 0..times {
            v.observe(id);
        }
    }

    #[test]
    fn twelve_bytes_per_voxel() {
        assert_eq!(std::mem::size_of::<TsdfVoxel>(), 7);
        assert_eq!(std::mem::size_of::<LabelVoxel>(), 5);
    }

    #[test]
    fn sixteen_bit_distances_and_bfloat_weights() {
        for t in [-1.0f32, -0.2051, -1e-4, 0.0, 3e-4, 0.3317, 1.0] {
            let v = TsdfVoxel::new(t, 1.0, [0; 3]);
            assert!(
                (v.tsdf() - t).abs() <= 0.5 / TSDF_STEPS,
                "{t} -> {}",
                v.tsdf()
            );
        }
        assert_eq!(TsdfVoxel::new(-7.0, 1.0, [0; 3]).tsdf(), -1.0);
        assert_eq!(TsdfVoxel::new(f32::NAN, 1.0, [0; 3]).tsdf(), 0.0);
        // The default max_weight is kept to its 8 significant bits; a frame's weight at 5 m
        // (1/25) still counts on a weight of 10.
        assert!((TsdfVoxel::new(0.0, 1e4, [0; 3]).weight() - 1e4).abs() <= 1e4 / 256.0);
        let v = TsdfVoxel::new(0.0, 10.0 + 1.0 / 25.0, [0; 3]);
        assert!(v.weight() > 10.0);
        assert!(!TsdfVoxel::default().observed());
        assert!(TsdfVoxel::new(0.0, 1e-3, [0; 3]).observed());
        // Weights at the ends of the range stay positive and finite.
        for w in [MIN_WEIGHT, MAX_WEIGHT] {
            let v = TsdfVoxel::new(0.0, w, [0; 3]);
            assert!(v.observed() && v.weight() == w, "{w}");
        }
        // The rounding agrees with half's, ties (to even, down and up) included.
        let ties = [f32::from_bits(0x3f80_8000), f32::from_bits(0x3f81_8000)];
        for w in [0.0f32, 1e-6, 0.04, 1.0, 3.3, 777.7, 1e4, 3e38]
            .into_iter()
            .chain(ties)
        {
            assert_eq!(round_to_bfloat(w), bf16::from_f32(w).to_bits(), "{w}");
        }
    }

    #[test]
    fn an_observation_over_takes_the_lead_and_keeps_the_leader_second() {
        let mut v = LabelVoxel::default();
        observe_times(&mut v, 1, 9);
        observe_times(&mut v, 2, 3);
        assert_eq!((v.instance(), v.counts()), (1, [9, 3]));
        v.observe_over(2);
        assert_eq!((v.ids(), v.counts()), ([2, 1], [10, 9]));
        // The old leader needs two observations to lead again.
        v.observe(1);
        assert_eq!(v.instance(), 2);
        v.observe(1);
        assert_eq!((v.instance(), v.counts()), (1, [11, 10]));
        // Over its own lead, or an empty voxel, it is one observation.
        v.observe_over(1);
        assert_eq!((v.instance(), v.counts()), (1, [12, 10]));
        let mut empty = LabelVoxel::default();
        empty.observe_over(4);
        assert_eq!((empty.instance(), empty.counts()), (4, [1, 0]));
        // At the cap the counts halve as for any observation, the new leader first.
        let mut full = LabelVoxel::default();
        observe_times(&mut full, 1, 15);
        full.observe_over(2);
        assert_eq!((full.ids(), full.counts()), ([2, 1], [8, 8]));
    }

    #[test]
    fn relabelling_pools_the_counts_of_merged_instances() {
        let mut v = LabelVoxel::default();
        observe_times(&mut v, 7, 3);
        observe_times(&mut v, 9, 2);
        assert!(v.relabel(9, 7));
        assert_eq!((v.ids()[0], v.counts()), (7, [5, 0]));
        assert!(!v.relabel(4, 7));
        // A relabelled second slot that now outweighs the first moves up.
        let mut v = LabelVoxel::from_parts([3, 5], [2, 1]);
        v.observe(5);
        v.observe(5);
        assert_eq!(v.instance(), 5);
        // Pooled counts past 4 bits halve.
        let mut v = LabelVoxel::from_parts([3, 5], [12, 10]);
        assert!(v.relabel(5, 3));
        assert_eq!((v.instance(), v.counts()), (3, [11, 0]));
    }

    #[test]
    fn the_runner_up_is_the_second_candidate_while_it_has_a_count() {
        let mut v = LabelVoxel::default();
        assert_eq!((v.instance(), v.challenger()), (0, 0));
        observe_times(&mut v, 4, 3);
        assert_eq!(v.challenger(), 0);
        v.observe(6);
        assert_eq!((v.instance(), v.challenger()), (4, 6));
        // A third label wears the runner-up's count down to nothing, then takes its place.
        v.observe(8);
        assert_eq!(v.challenger(), 8);
        observe_times(&mut v, 8, 3);
        assert_eq!((v.instance(), v.challenger()), (8, 4));
    }

    #[test]
    fn majority_label_wins_and_stale_labels_are_displaced() {
        let mut v = LabelVoxel::default();
        assert_eq!(v.instance(), 0);
        observe_times(&mut v, 7, 3);
        v.observe(9);
        assert_eq!(v.instance(), 7);
        // A third label erodes the second slot, then takes it.
        v.observe(11);
        assert_eq!(v.ids()[1], 11);
        observe_times(&mut v, 11, 5);
        assert_eq!(v.instance(), 11);
    }

    #[test]
    fn counts_halve_past_four_bits_and_keep_their_ratio() {
        let mut v = LabelVoxel::default();
        observe_times(&mut v, 7, 15);
        observe_times(&mut v, 9, 6);
        assert_eq!(v.counts(), [15, 6]);
        v.observe(7);
        assert_eq!((v.instance(), v.counts()), (7, [8, 3]));
        // A long-held label still needs more than a stray observation or two to be displaced,
        // but a label that keeps being seen takes over.
        let mut v = LabelVoxel::default();
        observe_times(&mut v, 7, 1000);
        observe_times(&mut v, 9, 2);
        assert_eq!(v.instance(), 7);
        observe_times(&mut v, 9, 20);
        assert_eq!(v.instance(), 9);
    }

    #[test]
    fn counts_from_older_map_files_are_scaled_into_four_bits() {
        let v = LabelVoxel::from_parts([4, 8], [300, 100]);
        let c = v.counts();
        assert_eq!(v.instance(), 4);
        assert!(c[0] <= MAX_LABEL_COUNT && c[0] >= 2 * c[1], "{c:?}");
        // Round trip of what fits.
        let v = LabelVoxel::from_parts([4, 8], [9, 2]);
        assert_eq!(LabelVoxel::from_parts(v.ids(), v.counts()), v);
    }
}
