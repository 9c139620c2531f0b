/// One voxel of the TSDF: signed distance to the nearest surface along the camera rays (metres,
/// positive in front), its fusion weight (0 = never observed) and the fused colour.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct TsdfVoxel {
    pub distance: f32,
    pub weight: f32,
    pub color: [u8; 3],
    _pad: u8,
}

impl TsdfVoxel {
    pub fn new(distance: f32, weight: f32, color: [u8; 3]) -> Self {
        Self {
            distance,
            weight,
            color,
            _pad: 0,
        }
    }

    pub fn observed(&self) -> bool {
        self.weight > 0.0
    }
}

/// Instance evidence of one voxel: the two strongest candidates and their counts, updated like
/// a two-slot Misra-Gries summary (a label that keeps being seen displaces a stale one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
pub struct LabelVoxel {
    pub ids: [u16; 2],
    pub counts: [u16; 2],
}

impl LabelVoxel {
    /// The most supported instance (0 = none).
    pub fn instance(&self) -> u16 {
        if self.counts[0] > 0 { self.ids[0] } else { 0 }
    }

    /// Calls instance `from` `into` from now on; returns whether anything changed.
    pub fn relabel(&mut self, from: u16, into: u16) -> bool {
        let mut changed = false;
        for k in 0..2 {
            if self.counts[k] > 0 && self.ids[k] == from {
                self.ids[k] = into;
                changed = true;
            }
        }
        if changed && self.counts[1] > 0 && self.ids[0] == self.ids[1] {
            self.counts[0] = self.counts[0].saturating_add(self.counts[1]);
            self.counts[1] = 0;
            self.ids[1] = 0;
        }
        if self.counts[1] > self.counts[0] {
            self.ids.swap(0, 1);
            self.counts.swap(0, 1);
        }
        changed
    }

    /// One observation of instance `id` (non-zero).
    pub fn observe(&mut self, id: u16) {
        if self.counts[0] > 0 && self.ids[0] == id {
            self.counts[0] = self.counts[0].saturating_add(1);
        } else if self.counts[1] > 0 && self.ids[1] == id {
            self.counts[1] = self.counts[1].saturating_add(1);
        } else if self.counts[0] == 0 {
            self.ids[0] = id;
            self.counts[0] = 1;
        } else if self.counts[1] == 0 {
            self.ids[1] = id;
            self.counts[1] = 1;
        } else {
            // Both slots taken by others: weaken the weaker; replace it once it is gone.
            self.counts[1] -= 1;
            if self.counts[1] == 0 {
                self.ids[1] = id;
                self.counts[1] = 1;
            }
        }
        if self.counts[1] > self.counts[0] {
            self.ids.swap(0, 1);
            self.counts.swap(0, 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twenty_bytes_per_voxel() {
        assert_eq!(std::mem::size_of::<TsdfVoxel>(), 12);
        assert_eq!(std::mem::size_of::<LabelVoxel>(), 8);
    }

    #[test]
    fn relabelling_pools_the_counts_of_merged_instances() {
        let mut v = LabelVoxel::default();
        for _ in 0..3 {
            v.observe(7);
        }
        for _ in 0..2 {
            v.observe(9);
        }
        assert!(v.relabel(9, 7));
        assert_eq!((v.ids[0], v.counts[0], v.counts[1]), (7, 5, 0));
        assert!(!v.relabel(4, 7));
        // A relabelled second slot that now outweighs the first moves up.
        let mut v = LabelVoxel {
            ids: [3, 5],
            counts: [2, 1],
        };
        v.observe(5);
        v.observe(5);
        assert_eq!(v.instance(), 5);
    }

    #[test]
    fn majority_label_wins_and_stale_labels_are_displaced() {
        let mut v = LabelVoxel::default();
        assert_eq!(v.instance(), 0);
        for _ in 0..3 {
            v.observe(7);
        }
        v.observe(9);
        assert_eq!(v.instance(), 7);
        // A third label erodes the second slot, then takes it.
        v.observe(11);
        assert_eq!(v.ids[1], 11);
        for _ in 0..5 {
            v.observe(11);
        }
        assert_eq!(v.instance(), 11);
    }
}
