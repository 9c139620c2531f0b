//! Refining every segment of a frame's label image.

use voxpan_core::{DepthImage, LabelImage, Segment, is_valid_depth, label_runs, widest};
use voxpan_kde::{BandwidthFallback, Kde, KdeMethod};

use crate::Rule;
use crate::interior::interior_depth;
use crate::interval::{DepthInterval, FAR_LIMIT_M, Judgement, KeptReason, depth_interval};

/// What to refine and how (the `[refine]` section of voxpan's configuration file; every key
/// optional, unknown keys rejected).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineConfig {
    pub rule: Rule,
    /// Overrides the rule's KDE (`--kde`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kde: Option<KdeMethod>,
    /// Refine only segments known to be things (`--things-only`).
    pub things_only: bool,
    /// Masks with fewer valid-depth pixels are kept as they are: a density from a handful of
    /// samples says nothing. 16 keeps the published rules' results on real data (their code
    /// has no guard; Detectron's masks are far larger).
    pub min_pixels: usize,
    /// Default rule: depths beyond this are no surface (sky, a failed reading) and leave the
    /// mask. In the depth image's unit; metres by voxpan's convention.
    pub far_limit: f64,
    /// Before the rule, thing masks give up their pixels on the frame's stuff planes (floor,
    /// walls) unless they lie flat on them: see [`crate::PlaneTrimmer`]. voxpan's step, not
    /// the paper's; applied by the pipeline's perception stage, not by [`Refiner`].
    pub trim_stuff_planes: bool,
}

impl RefineConfig {
    pub fn new(rule: Rule) -> Self {
        Self {
            rule,
            kde: None,
            things_only: false,
            min_pixels: 16,
            far_limit: FAR_LIMIT_M,
            trim_stuff_planes: true,
        }
    }

    /// The KDE in effect: the override, else the rule's own.
    pub fn kde_method(&self) -> KdeMethod {
        self.kde.unwrap_or(self.rule.default_kde())
    }
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self::new(Rule::Default)
    }
}

/// The outcome for one mask.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "status")]
pub enum MaskStatus {
    Refined,
    Kept(KeptReason),
}

/// One mask's line in the per-frame report.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct MaskReport {
    pub id: u16,
    /// Pixels of the mask before refinement.
    pub pixels: usize,
    /// Of those, pixels with valid depth.
    pub valid_depth: usize,
    /// Pixels still carrying the id afterwards.
    pub kept: usize,
    /// Pixels set to void.
    pub removed: usize,
    pub low: Option<f64>,
    pub high: Option<f64>,
    pub bandwidth: Option<f64>,
    #[serde(skip)]
    pub bandwidth_fallback: Option<BandwidthFallback>,
    pub status: MaskStatus,
}

/// The depth and label images differ in size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShapeMismatch {
    pub depth: (usize, usize),
    pub labels: (usize, usize),
}

impl std::fmt::Display for ShapeMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "depth is {}x{} but the label image is {}x{}",
            self.depth.0, self.depth.1, self.labels.0, self.labels.1
        )
    }
}

impl std::error::Error for ShapeMismatch {}

impl ShapeMismatch {
    /// `Ok` when `depth` and `labels` have the same size.
    pub(crate) fn check(depth: &DepthImage, labels: &LabelImage) -> Result<(), Self> {
        if depth.dims() == labels.dims() {
            Ok(())
        } else {
            Err(Self {
                depth: depth.dims(),
                labels: labels.dims(),
            })
        }
    }
}

const NO_SLOT: u32 = u32::MAX;

/// Appends the valid depths of `depths` to `out` without a branch per pixel: each depth is
/// written at the next free place, which advances only past valid ones (a filtered `extend`
/// checks the capacity at every push; compacting in place waits on its own stores).
#[inline(always)]
fn extend_valid(out: &mut Vec<f32>, depths: &[f32]) {
    let base = out.len();
    out.resize(base + depths.len(), 0.0);
    let tail = &mut out[base..];
    let mut kept = 0;
    for &d in depths {
        tail[kept] = d;
        kept += is_valid_depth(d) as usize;
    }
    out.truncate(base + kept);
}

/// Refines frames; owns the KDE workspace and buffers, so keep one per thread.
pub struct Refiner {
    config: RefineConfig,
    kde: Kde,
    /// Segment id → index into the frame's segment list (or `NO_SLOT`).
    slot_of: Vec<u32>,
    /// Valid depths under each mask, by slot.
    depths: Vec<Vec<f32>>,
    /// How deep inside its mask each pixel lies (default rule, frames with a mask of several
    /// depth clusters only).
    interior_map: Vec<u16>,
    /// The frame's runs of listed segments' pixels, with their slots: found once, read by
    /// every pass.
    runs: Vec<(usize, std::ops::Range<usize>)>,
    scratch: Vec<f64>,
}

impl Refiner {
    pub fn new(config: RefineConfig) -> Self {
        Self {
            kde: match config.rule {
                Rule::Default => Kde::new(config.kde_method()).with_resolution_floor(),
                Rule::Paper | Rule::Release | Rule::None => Kde::new(config.kde_method()),
            },
            config,
            slot_of: vec![NO_SLOT; u16::MAX as usize + 1],
            depths: Vec::new(),
            interior_map: Vec::new(),
            runs: Vec::new(),
            scratch: Vec::new(),
        }
    }

    pub fn config(&self) -> &RefineConfig {
        &self.config
    }

    /// The interval one mask keeps, from the depths under it (invalid ones are skipped).
    pub fn interval(&mut self, depths: &[f32]) -> Result<DepthInterval, KeptReason> {
        let valid: Vec<f32> = depths
            .iter()
            .copied()
            .filter(|&d| is_valid_depth(d))
            .collect();
        if valid.len() < self.config.min_pixels.max(1) {
            return Err(KeptReason::TooFewPixels {
                valid: valid.len(),
                min: self.config.min_pixels.max(1),
            });
        }
        let judgement = depth_interval(
            &mut self.kde,
            self.config.rule,
            &valid,
            self.config.far_limit,
            &mut self.scratch,
            None,
        )?;
        match judgement {
            Judgement::Decided(interval) => Ok(interval),
            // Without the image every pixel weighs the same.
            Judgement::Undecided(choice) => choice.choose(&choice.density_weights()),
        }
    }

    /// Refines, in place, every segment of `labels` listed in `segments` (ids absent from the
    /// list are left alone). Returns one report per listed segment, in list order.
    pub fn refine_frame(
        &mut self,
        depth: &DepthImage,
        labels: &mut LabelImage,
        segments: &[Segment],
    ) -> Result<Vec<MaskReport>, ShapeMismatch> {
        ShapeMismatch::check(depth, labels)?;
        for (slot, s) in segments.iter().enumerate() {
            self.slot_of[s.id as usize] = slot as u32;
        }
        // The passes over the frame's pixels vectorise twice as wide with AVX2.
        let reports = widest!(self.refine_slots(depth, labels, segments));
        for s in segments {
            self.slot_of[s.id as usize] = NO_SLOT;
        }
        Ok(reports)
    }

    /// Settles the masks whose depths fall into several clusters: each cluster weighs its
    /// pixels by how deep inside the mask they lie (one distance map for the frame, one pass
    /// over the pixels of those masks). Frames where every mask is one cluster skip both.
    #[inline(always)]
    fn decide(
        &mut self,
        labels: &LabelImage,
        depth: &DepthImage,
        judgements: Vec<Result<Judgement, KeptReason>>,
    ) -> Vec<Result<DepthInterval, KeptReason>> {
        // Each undecided mask gathers one weight per cluster: sums of small integers, exact.
        let mut weights: Vec<Vec<u64>> = judgements
            .iter()
            .map(|j| match j {
                Ok(Judgement::Undecided(choice)) => vec![0; choice.len()],
                _ => Vec::new(),
            })
            .collect();
        if weights.iter().any(|w| !w.is_empty()) {
            interior_depth(labels, &mut self.interior_map);
            for (slot, run) in &self.runs {
                let slot = *slot;
                let Ok(Judgement::Undecided(choice)) = &judgements[slot] else {
                    continue;
                };
                let weights = &mut weights[slot];
                // Neighbouring pixels mostly share a cluster: their weights are summed locally
                // and added to the cluster's when it changes.
                let (mut cluster, mut sum) = (None, 0);
                // Neighbours mostly share their depth too: the last depth's cluster is reused.
                // The start value is a NaN pattern, whose cluster is indeed none.
                let (mut last_depth, mut last_cluster) = (u32::MAX, None);
                let pixels = depth.pixels()[run.clone()].iter();
                for (&d, &inside) in pixels.zip(&self.interior_map[run.clone()]) {
                    if d.to_bits() != last_depth {
                        last_depth = d.to_bits();
                        last_cluster = if is_valid_depth(d) {
                            choice.cluster_of(d)
                        } else {
                            None
                        };
                    }
                    let k = last_cluster;
                    if k != cluster {
                        if let Some(c) = cluster {
                            weights[c] += sum;
                        }
                        (cluster, sum) = (k, 0);
                    }
                    // +1: outline pixels still count, as in an unweighted mask.
                    sum += inside as u64 + 1;
                }
                if let Some(c) = cluster {
                    weights[c] += sum;
                }
            }
        }
        judgements
            .into_iter()
            .zip(weights)
            .map(|(judgement, weights)| match judgement? {
                Judgement::Decided(interval) => Ok(interval),
                Judgement::Undecided(choice) => {
                    choice.choose(&weights.iter().map(|&w| w as f64).collect::<Vec<_>>())
                }
            })
            .collect()
    }

    #[inline(always)]
    fn refine_slots(
        &mut self,
        depth: &DepthImage,
        labels: &mut LabelImage,
        segments: &[Segment],
    ) -> Vec<MaskReport> {
        let n = segments.len();
        let mut pixels = vec![0usize; n];
        if self.depths.len() < n {
            self.depths.resize_with(n, Vec::new);
        }
        for d in &mut self.depths[..n] {
            d.clear();
        }
        // One pass gathers each mask's valid depths (buffers keep their capacity across frames),
        // a run of equal labels at a time.
        self.runs.clear();
        for (l, run) in label_runs(labels.pixels()) {
            let slot = self.slot_of[l as usize];
            if slot != NO_SLOT {
                let slot = slot as usize;
                pixels[slot] += run.len();
                extend_valid(&mut self.depths[slot], &depth.pixels()[run.clone()]);
                self.runs.push((slot, run));
            }
        }
        let valid: Vec<usize> = self.depths[..n].iter().map(Vec::len).collect();

        let min = self.config.min_pixels.max(1);
        let mut judgements: Vec<Result<Judgement, KeptReason>> = Vec::with_capacity(n);
        for (s, seg) in segments.iter().enumerate() {
            judgements.push(if self.config.things_only && seg.is_thing != Some(true) {
                Err(match seg.is_thing {
                    Some(false) => KeptReason::NotAThing,
                    _ => KeptReason::UnknownKind,
                })
            } else if valid[s] < min {
                Err(KeptReason::TooFewPixels {
                    valid: valid[s],
                    min,
                })
            } else {
                depth_interval(
                    &mut self.kde,
                    self.config.rule,
                    &self.depths[s],
                    self.config.far_limit,
                    &mut self.scratch,
                    seg.is_thing,
                )
            });
        }
        let decisions = self.decide(labels, depth, judgements);

        let mut intervals: Vec<Option<DepthInterval>> = Vec::with_capacity(n);
        let mut reports = Vec::with_capacity(n);
        for (s, (seg, decision)) in segments.iter().zip(decisions).enumerate() {
            intervals.push(decision.ok());
            reports.push(MaskReport {
                id: seg.id,
                pixels: pixels[s],
                valid_depth: valid[s],
                kept: pixels[s],
                removed: 0,
                low: decision.ok().map(|i| i.low),
                high: decision.ok().map(|i| i.high),
                bandwidth: decision.ok().map(|i| i.bandwidth),
                bandwidth_fallback: decision.ok().and_then(|i| i.bandwidth_fallback),
                status: match decision {
                    Ok(_) => MaskStatus::Refined,
                    Err(reason) => MaskStatus::Kept(reason),
                },
            });
        }

        let drop_invalid = self.config.rule.drops_pixels_without_depth();
        let bounds: Vec<Option<(f32, f32)>> = intervals
            .iter()
            .map(|i| i.map(|i| i.float32_bounds()))
            .collect();
        let labels = labels.pixels_mut();
        for (slot, run) in &self.runs {
            let Some((low, high)) = bounds[*slot] else {
                continue;
            };
            let mut removed = 0;
            for (l, &d) in labels[run.clone()]
                .iter_mut()
                .zip(&depth.pixels()[run.clone()])
            {
                let outside = if is_valid_depth(d) {
                    !(low <= d && d <= high)
                } else {
                    drop_invalid
                };
                // Without a branch: most pixels stay, the rest in no pattern.
                *l *= !outside as u16;
                removed += outside as usize;
            }
            reports[*slot].removed += removed;
        }
        for r in &mut reports {
            r.kept = r.pixels - r.removed;
        }
        reports
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valid_depths_are_appended_in_order() {
        let mut out = vec![9.0];
        let depths = [1.0, f32::NAN, 0.0, 2.0, -1.0, f32::INFINITY, 3.0];
        extend_valid(&mut out, &depths);
        assert_eq!(out, [9.0, 1.0, 2.0, 3.0]);
    }
}
