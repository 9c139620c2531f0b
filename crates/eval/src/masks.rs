use pathfinding::prelude::{Matrix, kuhn_munkres};
use voxpan_core::LabelImage;

/// IoU is matched as an integer (pathfinding's Hungarian needs exact arithmetic); 1e-12
/// resolution keeps every real tie-break.
const IOU_SCALE: f64 = 1e12;

/// One frame's matching.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameMatch {
    /// IoU of each assigned (prediction, ground truth) pair, including zeros.
    pub matched: Vec<f64>,
    /// `(intersection, predicted area, ground-truth area)` of each assigned pair.
    pub pairs: Vec<(u64, u64, u64)>,
    pub n_pred: usize,
    pub n_gt: usize,
    /// Non-void predicted pixels and all ground-truth pixels.
    pub pred_pixels: u64,
    pub gt_pixels: u64,
}

/// Matches `pred` (0 = void) against `gt` (every id a segment). Images must have equal size.
pub fn match_frame(pred: &LabelImage, gt: &LabelImage) -> FrameMatch {
    match_frame_subset(pred, gt, |_| true, |_| true)
}

/// Like [`match_frame`], but only predicted ids with `keep_pred` and ground-truth ids with
/// `keep_gt` take part (for things and stuff separately); IoUs still use the whole images.
pub fn match_frame_subset(
    pred: &LabelImage,
    gt: &LabelImage,
    keep_pred: impl Fn(u16) -> bool,
    keep_gt: impl Fn(u16) -> bool,
) -> FrameMatch {
    assert_eq!(
        pred.dims(),
        gt.dims(),
        "prediction and ground truth differ in size"
    );
    let index = |img: &LabelImage, skip_void: bool| {
        let mut slot = vec![u32::MAX; u16::MAX as usize + 1];
        let mut ids = Vec::new();
        for &l in img.pixels() {
            if (l != 0 || !skip_void) && slot[l as usize] == u32::MAX {
                slot[l as usize] = 0;
                ids.push(l);
            }
        }
        ids.sort_unstable();
        for (i, &id) in ids.iter().enumerate() {
            slot[id as usize] = i as u32;
        }
        (slot, ids.len())
    };
    let (p_slot, n_pred) = index(pred, true);
    let (g_slot, n_gt) = index(gt, false);
    let mut inter = vec![0u64; n_pred * n_gt];
    let mut p_area = vec![0u64; n_pred];
    let mut g_area = vec![0u64; n_gt];
    for (&p, &g) in pred.pixels().iter().zip(gt.pixels()) {
        let gi = g_slot[g as usize] as usize;
        g_area[gi] += 1;
        if p != 0 {
            let pi = p_slot[p as usize] as usize;
            p_area[pi] += 1;
            inter[pi * n_gt + gi] += 1;
        }
    }
    let iou = |pi: usize, gi: usize| {
        let i = inter[pi * n_gt + gi];
        if i == 0 {
            0.0
        } else {
            i as f64 / (p_area[pi] + g_area[gi] - i) as f64
        }
    };
    let ids_of = |slot: &[u32]| {
        let mut ids: Vec<(u16, usize)> = (0..=u16::MAX)
            .filter(|&id| slot[id as usize] != u32::MAX)
            .map(|id| (id, slot[id as usize] as usize))
            .collect();
        ids.sort_by_key(|&(_, i)| i);
        ids
    };
    let preds: Vec<usize> = ids_of(&p_slot)
        .into_iter()
        .filter(|&(id, _)| keep_pred(id))
        .map(|(_, i)| i)
        .collect();
    let gts: Vec<usize> = ids_of(&g_slot)
        .into_iter()
        .filter(|&(id, _)| keep_gt(id))
        .map(|(_, i)| i)
        .collect();
    let mut result = FrameMatch {
        n_pred: preds.len(),
        n_gt: gts.len(),
        pred_pixels: preds.iter().map(|&i| p_area[i]).sum(),
        gt_pixels: gts.iter().map(|&i| g_area[i]).sum(),
        ..FrameMatch::default()
    };
    if preds.is_empty() || gts.is_empty() {
        return result;
    }
    // kuhn_munkres needs rows <= columns: put the smaller side on the rows.
    let transpose = preds.len() > gts.len();
    let (rows, cols) = if transpose {
        (gts.len(), preds.len())
    } else {
        (preds.len(), gts.len())
    };
    let weights = Matrix::from_fn(rows, cols, |(r, c)| {
        let (a, b) = if transpose { (c, r) } else { (r, c) };
        (iou(preds[a], gts[b]) * IOU_SCALE).round() as i64
    });
    let (_, assignment) = kuhn_munkres(&weights);
    for (r, &c) in assignment.iter().enumerate() {
        let (a, b) = if transpose { (c, r) } else { (r, c) };
        let (pi, gi) = (preds[a], gts[b]);
        result.matched.push(iou(pi, gi));
        result
            .pairs
            .push((inter[pi * n_gt + gi], p_area[pi], g_area[gi]));
    }
    result
}

/// Scores pooled over frames.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MaskScores {
    positive_ious: Vec<f64>,
    tp_iou_sum: f64,
    tp: usize,
    n_pred: usize,
    n_gt: usize,
    assigned_inter: u64,
    pred_pixels: u64,
    gt_pixels: u64,
    frames: usize,
}

/// The summary numbers, in percent.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct MaskSummary {
    pub frames: usize,
    pub mean_matched_iou: f64,
    pub pq: f64,
    pub sq: f64,
    pub rq: f64,
    pub precision: f64,
    pub recall: f64,
    pub tp: usize,
    pub n_pred: usize,
    pub n_gt: usize,
}

impl MaskScores {
    pub fn add(&mut self, m: &FrameMatch) {
        self.frames += 1;
        self.n_pred += m.n_pred;
        self.n_gt += m.n_gt;
        self.pred_pixels += m.pred_pixels;
        self.gt_pixels += m.gt_pixels;
        for (&iou, &(inter, _, _)) in m.matched.iter().zip(&m.pairs) {
            if iou > 0.0 {
                self.positive_ious.push(iou);
            }
            if iou > 0.5 {
                self.tp += 1;
                self.tp_iou_sum += iou;
            }
            self.assigned_inter += inter;
        }
    }

    pub fn merge(&mut self, other: &MaskScores) {
        self.positive_ious.extend_from_slice(&other.positive_ious);
        self.tp_iou_sum += other.tp_iou_sum;
        self.tp += other.tp;
        self.n_pred += other.n_pred;
        self.n_gt += other.n_gt;
        self.assigned_inter += other.assigned_inter;
        self.pred_pixels += other.pred_pixels;
        self.gt_pixels += other.gt_pixels;
        self.frames += other.frames;
    }

    pub fn summary(&self) -> MaskSummary {
        let pct = |num: f64, den: f64| if den > 0.0 { 100.0 * num / den } else { 0.0 };
        let tp = self.tp as f64;
        let (fp, fn_) = ((self.n_pred - self.tp) as f64, (self.n_gt - self.tp) as f64);
        let sq = pct(self.tp_iou_sum, tp);
        let rq = pct(tp, tp + fp / 2.0 + fn_ / 2.0);
        MaskSummary {
            frames: self.frames,
            mean_matched_iou: pct(
                self.positive_ious.iter().sum(),
                self.positive_ious.len() as f64,
            ),
            pq: sq * rq / 100.0,
            sq,
            rq,
            precision: pct(self.assigned_inter as f64, self.pred_pixels as f64),
            recall: pct(self.assigned_inter as f64, self.gt_pixels as f64),
            tp: self.tp,
            n_pred: self.n_pred,
            n_gt: self.n_gt,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: usize, v: &[u16]) -> LabelImage {
        LabelImage::from_vec(w, v.len() / w, v.to_vec()).unwrap()
    }

    #[test]
    fn hand_computed_case() {
        // Ground truth: two halves (ids 0 and 5). Prediction: id 1 covers the left half and
        // one pixel of the right; id 2 is a single pixel of the right half; one void pixel.
        let gt = img(4, &[0, 0, 5, 5, 0, 0, 5, 5]);
        let pred = img(4, &[1, 1, 1, 2, 1, 1, 0, 0]);
        let m = match_frame(&pred, &gt);
        assert_eq!((m.n_pred, m.n_gt), (2, 2));
        // IoU(1, 0) = 4/5; IoU(2, 5) = 1/4; the other pairing gives 1/7 + 0.
        let mut ious = m.matched.clone();
        ious.sort_by(f64::total_cmp);
        assert_eq!(ious, vec![0.25, 0.8]);
        let mut scores = MaskScores::default();
        scores.add(&m);
        let s = scores.summary();
        assert!((s.mean_matched_iou - 52.5).abs() < 1e-12);
        assert_eq!(s.tp, 1);
        assert!((s.sq - 80.0).abs() < 1e-12);
        // RQ = 1 / (1 + 1/2 + 1/2)
        assert!((s.rq - 50.0).abs() < 1e-12);
        assert!((s.pq - 40.0).abs() < 1e-12);
        // Assigned intersections 4 + 1 over 6 predicted and 8 true pixels.
        assert!((s.precision - 500.0 / 6.0).abs() < 1e-9);
        assert!((s.recall - 62.5).abs() < 1e-12);
    }

    #[test]
    fn subsets_match_within_themselves() {
        // Things are ids >= 5 in both images.
        let gt = img(4, &[0, 0, 5, 5, 0, 0, 5, 5]);
        let pred = img(4, &[1, 1, 1, 7, 1, 1, 0, 0]);
        let things = match_frame_subset(&pred, &gt, |id| id >= 5, |id| id >= 5);
        assert_eq!((things.n_pred, things.n_gt), (1, 1));
        assert!((things.matched[0] - 0.25).abs() < 1e-12);
        let stuff = match_frame_subset(&pred, &gt, |id| id < 5, |id| id < 5);
        assert!((stuff.matched[0] - 0.8).abs() < 1e-12);
    }

    #[test]
    fn more_predictions_than_truth_and_empty_frames() {
        let gt = img(3, &[7, 7, 7]);
        let pred = img(3, &[1, 2, 3]);
        let m = match_frame(&pred, &gt);
        assert_eq!(m.matched.len(), 1);
        assert!((m.matched[0] - 1.0 / 3.0).abs() < 1e-12);
        let m = match_frame(&img(3, &[0, 0, 0]), &gt);
        assert_eq!((m.n_pred, m.matched.len()), (0, 0));
    }
}
