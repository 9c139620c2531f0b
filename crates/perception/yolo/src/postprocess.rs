//! From raw outputs to instances: candidates above the confidence threshold, class-aware
//! non-maximum suppression, instance masks (`sigmoid(coefficients · prototypes)`, bilinearly
//! upsampled, thresholded at 0.5, cut to the box) and one label image where the higher score
//! wins.
//!
//! Arithmetic follows `tools/yolo/yolo_common.py` (float32, same order of operations), so that
//! the goldens' detections are reproduced, not merely approximated.

use voxpan_core::LabelImage;

use crate::letterbox::{Letterbox, sample_at};
use crate::model::{Layout, ModelInfo};

/// One detected instance, in network input pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// Class id (index into [`ModelInfo::names`]).
    pub class: usize,
    /// Confidence: class probability, times objectness for YOLOv5.
    pub score: f32,
    /// `[x1, y1, x2, y2]`, input pixels.
    pub bbox: [f32; 4],
    /// The mask coefficients.
    pub coefs: Vec<f32>,
}

/// The candidates of `output0` (shaped as `info` says) whose score exceeds `confidence`, in
/// candidate order.
pub fn candidates(info: &ModelInfo, output0: &[f32], confidence: f32) -> Vec<Detection> {
    let (n, nc, nm) = (info.candidates, info.classes(), info.mask_dim);
    let first = info.layout.box_fields();
    let fields = first + nc + nm;
    assert_eq!(
        output0.len(),
        n * fields,
        "output0 does not match the model info"
    );
    let mut out = Vec::new();
    match info.layout {
        Layout::V5 => {
            for row in output0.chunks_exact(fields) {
                let obj = row[4];
                // A class probability is at most 1, so the score cannot pass without this.
                if obj <= confidence {
                    continue;
                }
                let (class, p) = argmax(&row[first..first + nc]);
                let score = obj * p;
                if score > confidence {
                    out.push(detection(
                        [row[0], row[1], row[2], row[3]],
                        class,
                        score,
                        row[first + nc..].to_vec(),
                    ));
                }
            }
        }
        Layout::V8 => {
            // Fields are rows here: find each candidate's best class a row at a time.
            let at = |f: usize, i: usize| output0[f * n + i];
            let mut best: Vec<(usize, f32)> = (0..n).map(|i| (0, at(first, i))).collect();
            for c in 1..nc {
                let row = &output0[(first + c) * n..(first + c + 1) * n];
                for (b, &p) in best.iter_mut().zip(row) {
                    if p > b.1 {
                        *b = (c, p);
                    }
                }
            }
            for (i, &(class, score)) in best.iter().enumerate() {
                if score > confidence {
                    let coefs = (0..nm).map(|m| at(first + nc + m, i)).collect();
                    let cxcywh = [at(0, i), at(1, i), at(2, i), at(3, i)];
                    out.push(detection(cxcywh, class, score, coefs));
                }
            }
        }
    }
    out
}

/// The first largest value and its index.
fn argmax(values: &[f32]) -> (usize, f32) {
    let mut best = (0, values[0]);
    for (i, &v) in values.iter().enumerate().skip(1) {
        if v > best.1 {
            best = (i, v);
        }
    }
    best
}

fn detection([cx, cy, w, h]: [f32; 4], class: usize, score: f32, coefs: Vec<f32>) -> Detection {
    Detection {
        class,
        score,
        bbox: [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0],
        coefs,
    }
}

/// Intersection over union of two boxes (0 for two empty boxes).
pub fn iou(a: &[f32; 4], b: &[f32; 4]) -> f32 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = w * h;
    let area = |r: &[f32; 4]| (r[2] - r[0]) * (r[3] - r[1]);
    // The epsilon keeps two empty boxes at 0 instead of NaN.
    inter / (area(a) + area(b) - inter + 1e-9)
}

/// Greedy class-aware non-maximum suppression: by descending score (ties in candidate order),
/// a detection is kept unless a kept one of its class overlaps it by IoU > `iou_threshold`.
/// At most `max_detections` are kept, best first.
pub fn nms(
    mut detections: Vec<Detection>,
    iou_threshold: f32,
    max_detections: usize,
) -> Vec<Detection> {
    // Stable: equal scores stay in candidate order, as numpy's stable argsort keeps them.
    detections.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<Detection> = Vec::new();
    for d in detections {
        if kept.len() == max_detections {
            break;
        }
        let suppressed = kept
            .iter()
            .any(|k| k.class == d.class && iou(&k.bbox, &d.bbox) > iou_threshold);
        if !suppressed {
            kept.push(d);
        }
    }
    kept
}

/// The prototype masks, `[M, height, width]` row-major.
#[derive(Clone, Copy, Debug)]
pub struct Protos<'a> {
    pub data: &'a [f32],
    pub dim: usize,
    pub width: usize,
    pub height: usize,
}

/// A pixel grid masks are drawn on, placed in the network input: the centre of pixel `(u, v)`
/// lies at input point `(origin.0 + (u + 0.5) step.0, origin.1 + (v + 0.5) step.1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub width: usize,
    pub height: usize,
    pub step: (f64, f64),
    pub origin: (f64, f64),
}

impl Grid {
    /// The network input's own pixels.
    pub fn input(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            step: (1.0, 1.0),
            origin: (0.0, 0.0),
        }
    }

    /// The original image's pixels, through the letterbox.
    pub fn image(letterbox: &Letterbox) -> Self {
        let (sx, sy) = letterbox.scale();
        Self {
            width: letterbox.image.0,
            height: letterbox.image.1,
            step: (sx, sy),
            origin: (letterbox.left as f64, letterbox.top as f64),
        }
    }
}

/// One axis of a mask's sampling: for each grid index inside the box, the index and the two
/// prototype cells (with the second's weight) it samples.
fn axis_samples(
    n: usize,
    step: f64,
    origin: f64,
    lo: f32,
    hi: f32,
    input: usize,
    protos: usize,
) -> Vec<(usize, usize, usize, f32)> {
    let to_proto = protos as f64 / input as f64;
    (0..n)
        .filter_map(|u| {
            let c = origin + (u as f64 + 0.5) * step;
            // Pixel centres inside [lo, hi): the box's own pixels, as the reference crops.
            (c >= lo as f64 && c < hi as f64).then(|| {
                let (i0, i1, f) = sample_at(c * to_proto - 0.5, protos);
                (u, i0, i1, f)
            })
        })
        .collect()
}

/// Calls `hit(u, v)` for every pixel of `grid` in the mask of `detection`: pixel centres inside
/// its box where the bilinearly upsampled `sigmoid(coefficients · prototypes)` exceeds 0.5.
/// `input` is the network input's `(width, height)`.
pub fn for_each_mask_pixel(
    detection: &Detection,
    protos: &Protos,
    input: (usize, usize),
    grid: &Grid,
    mut hit: impl FnMut(usize, usize),
) {
    let b = detection.bbox;
    let cols = axis_samples(
        grid.width,
        grid.step.0,
        grid.origin.0,
        b[0],
        b[2],
        input.0,
        protos.width,
    );
    let rows = axis_samples(
        grid.height,
        grid.step.1,
        grid.origin.1,
        b[1],
        b[3],
        input.1,
        protos.height,
    );
    let (Some(first_col), Some(first_row)) = (cols.first(), rows.first()) else {
        return;
    };
    // The window of prototype cells the box samples; probabilities only there.
    let (x0, y0) = (first_col.1, first_row.1);
    let x1 = cols.iter().map(|c| c.2).max().unwrap_or(x0);
    let y1 = rows.iter().map(|r| r.2).max().unwrap_or(y0);
    let (ww, wh) = (x1 - x0 + 1, y1 - y0 + 1);
    let plane = protos.width * protos.height;
    let mut p = vec![0f32; ww * wh];
    for (m, &c) in detection.coefs.iter().enumerate().take(protos.dim) {
        let proto = &protos.data[m * plane..(m + 1) * plane];
        for y in 0..wh {
            let src = &proto[(y0 + y) * protos.width + x0..][..ww];
            for (acc, &v) in p[y * ww..(y + 1) * ww].iter_mut().zip(src) {
                *acc += c * v;
            }
        }
    }
    for v in &mut p {
        *v = 1.0 / (1.0 + (-*v).exp());
    }
    let at = |x: usize, y: usize| p[(y - y0) * ww + (x - x0)];
    for &(v, py0, py1, fy) in &rows {
        for &(u, px0, px1, fx) in &cols {
            let top = at(px0, py0) * (1.0 - fx) + at(px1, py0) * fx;
            let bottom = at(px0, py1) * (1.0 - fx) + at(px1, py1) * fx;
            if top * (1.0 - fy) + bottom * fy > 0.5 {
                hit(u, v);
            }
        }
    }
}

/// The instances as one label image on `grid`: `detections` (best first, as [`nms`] returns
/// them) get ids 1, 2, ... in that order, and a pixel in several masks goes to the
/// highest-scoring one. Returns the image and, per id (from 1), the index of its detection;
/// a detection left without pixels gets no id.
pub fn label_image(
    detections: &[Detection],
    protos: &Protos,
    input: (usize, usize),
    grid: &Grid,
) -> (LabelImage, Vec<usize>) {
    let mut labels = LabelImage::filled(grid.width, grid.height, 0);
    let mut owners = Vec::new();
    for (k, d) in detections.iter().enumerate() {
        let Ok(id) = u16::try_from(owners.len() + 1) else {
            break;
        };
        let pixels = labels.pixels_mut();
        let mut painted = false;
        for_each_mask_pixel(d, protos, input, grid, |u, v| {
            let l = &mut pixels[v * grid.width + u];
            if *l == 0 {
                *l = id;
                painted = true;
            }
        });
        if painted {
            owners.push(k);
        }
    }
    (labels, owners)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v8_info(candidates: usize, classes: usize, mask_dim: usize) -> ModelInfo {
        ModelInfo {
            layout: Layout::V8,
            input: (64, 32),
            names: (0..classes).map(|c| format!("c{c}")).collect(),
            candidates,
            mask_dim,
            protos: (16, 8),
        }
    }

    /// Candidates as v8 columns: (cx, cy, w, h, class probabilities, coefficients).
    fn v8_output(cands: &[(Vec<f32>, Vec<f32>, Vec<f32>)]) -> Vec<f32> {
        let rows: Vec<Vec<f32>> = cands
            .iter()
            .map(|(b, p, c)| b.iter().chain(p).chain(c).copied().collect())
            .collect();
        let fields = rows[0].len();
        (0..fields)
            .flat_map(|f| rows.iter().map(move |r| r[f]))
            .collect()
    }

    #[test]
    fn decoding_reads_both_layouts_alike() {
        // Two candidates, 2 classes, 1 coefficient, as v8 columns and as v5 rows.
        let cands = [
            (vec![10.0, 20.0, 4.0, 6.0], vec![0.1, 0.9], vec![0.5]),
            (vec![30.0, 5.0, 2.0, 2.0], vec![0.2, 0.1], vec![-1.0]),
        ];
        let v8 = candidates(&v8_info(2, 2, 1), &v8_output(&cands), 0.25);
        assert_eq!(v8.len(), 1);
        assert_eq!(v8[0].class, 1);
        assert_eq!(v8[0].score, 0.9);
        assert_eq!(v8[0].bbox, [8.0, 17.0, 12.0, 23.0]);
        assert_eq!(v8[0].coefs, vec![0.5]);
        // v5: objectness 0.5 halves the scores: 0.45 passes, the second (0.1) does not.
        let v5_info = ModelInfo {
            layout: Layout::V5,
            ..v8_info(2, 2, 1)
        };
        let v5: Vec<f32> = cands
            .iter()
            .flat_map(|(b, p, c)| {
                b.iter()
                    .copied()
                    .chain([0.5])
                    .chain(p.iter().copied())
                    .chain(c.iter().copied())
            })
            .collect();
        let d = candidates(&v5_info, &v5, 0.25);
        assert_eq!(d.len(), 1);
        assert_eq!((d[0].class, d[0].score, d[0].bbox), (1, 0.45, v8[0].bbox));
        // Low objectness rejects even a certain class.
        let mut low = v5.clone();
        low[4] = 0.2;
        assert!(candidates(&v5_info, &low, 0.25).is_empty());
    }

    fn det(class: usize, score: f32, bbox: [f32; 4]) -> Detection {
        Detection {
            class,
            score,
            bbox,
            coefs: vec![],
        }
    }

    #[test]
    fn iou_by_hand() {
        let a = [0.0, 0.0, 10.0, 10.0];
        assert!((iou(&a, &a) - 1.0).abs() < 1e-6);
        // Half overlap: 50 / (100 + 100 - 50).
        assert!((iou(&a, &[5.0, 0.0, 15.0, 10.0]) - 1.0 / 3.0).abs() < 1e-6);
        assert_eq!(iou(&a, &[20.0, 20.0, 30.0, 30.0]), 0.0);
        assert_eq!(iou(&[1.0, 1.0, 1.0, 1.0], &[1.0, 1.0, 1.0, 1.0]), 0.0);
    }

    #[test]
    fn nms_is_per_class_and_greedy() {
        let boxes = vec![
            det(0, 0.6, [0.0, 0.0, 20.0, 10.0]), // IoU 0.5 with the best chair: dropped
            det(0, 0.9, [0.0, 0.0, 10.0, 10.0]), // best chair
            det(1, 0.8, [0.0, 0.0, 10.0, 10.0]), // same box, other class: kept
            det(0, 0.7, [6.0, 0.0, 16.0, 10.0]), // IoU 0.25 with the best chair: kept
            det(0, 0.5, [10.0, 0.0, 20.0, 10.0]), // IoU 0.5 with the dropped 0.6, 3/7 with 0.7
        ];
        let kept = nms(boxes.clone(), 0.45, 100);
        let scores: Vec<f32> = kept.iter().map(|d| d.score).collect();
        assert_eq!(scores, vec![0.9, 0.8, 0.7, 0.5]);
        // A suppressed box suppresses nothing: 0.5 survives although 0.6 overlaps it more.
        // A stricter threshold drops 0.5 (IoU 0.43 with 0.7) too.
        let kept = nms(boxes.clone(), 0.4, 100);
        assert_eq!(kept.len(), 3);
        // The cap keeps the best.
        let kept = nms(boxes, 0.45, 2);
        assert_eq!(
            kept.iter().map(|d| d.score).collect::<Vec<_>>(),
            vec![0.9, 0.8]
        );
    }

    /// Prototypes of an 8×4 grid for a 32×16 input (4 px per cell): one mask that is +8 on
    /// the left half and −8 on the right, one that is +8 in the top row only, one +8 everywhere.
    fn protos() -> Vec<f32> {
        let mut p = vec![8f32; 3 * 32];
        for y in 0..4 {
            for x in 0..8 {
                p[y * 8 + x] = if x < 4 { 8.0 } else { -8.0 };
                p[32 + y * 8 + x] = if y == 0 { 8.0 } else { -8.0 };
            }
        }
        p
    }

    fn proto_view(data: &[f32]) -> Protos<'_> {
        Protos {
            data,
            dim: 3,
            width: 8,
            height: 4,
        }
    }

    #[test]
    fn masks_by_hand_in_input_pixels() {
        let data = protos();
        let protos = proto_view(&data);
        let grid = Grid::input(32, 16);
        let mask = |coefs: Vec<f32>, bbox: [f32; 4]| {
            let d = Detection {
                class: 0,
                score: 1.0,
                bbox,
                coefs,
            };
            let mut px = Vec::new();
            for_each_mask_pixel(&d, &protos, (32, 16), &grid, |u, v| px.push((u, v)));
            px
        };
        // Left half, whole-image box: the 0.5 crossing lies midway between cells 3 and 4, at
        // input x = 16, so columns 0..16 (centres up to 15.5), all 16 rows.
        let left = mask(vec![1.0, 0.0, 0.0], [0.0, 0.0, 32.0, 16.0]);
        assert_eq!(left.len(), 16 * 16);
        assert!(left.iter().all(|&(u, _)| u < 16));
        // Cut to a box: pixel centres in [2.5, 9.5) × [1, 3) are columns 2..=8 (centre 2.5 is
        // in, 9.5 is out) and rows 1, 2.
        let cut = mask(vec![1.0, 0.0, 0.0], [2.5, 1.0, 9.5, 3.0]);
        let want: Vec<(usize, usize)> = (1..3).flat_map(|v| (2..9).map(move |u| (u, v))).collect();
        assert_eq!(cut, want);
        // Negated coefficients give the right half.
        let right = mask(vec![-1.0, 0.0, 0.0], [0.0, 0.0, 32.0, 16.0]);
        assert_eq!(right.len(), 16 * 16);
        assert!(right.iter().all(|&(u, _)| u >= 16));
        // The top row of cells: centres above the midpoint between cells 0 and 1 (y = 4), the
        // upsampling clamped at the edge.
        let top = mask(vec![0.0, 1.0, 0.0], [0.0, 0.0, 32.0, 16.0]);
        assert_eq!(top.len(), 32 * 4);
        assert!(top.iter().all(|&(_, v)| v < 4));
        // A box outside the input has no pixels.
        assert!(mask(vec![1.0, 0.0, 0.0], [-20.0, -20.0, -1.0, -1.0]).is_empty());
    }

    #[test]
    fn masks_through_the_letterbox_and_overlaps_to_the_higher_score() {
        let data = protos();
        let protos = proto_view(&data);
        // A 16×4 image letterboxed into 32×16: doubled to 32×8, 4 rows of padding on top.
        let lb = Letterbox::new(16, 4, 32, 16).unwrap();
        assert_eq!((lb.resized, lb.top), ((32, 8), 4));
        let grid = Grid::image(&lb);
        assert_eq!((grid.step, grid.origin), ((2.0, 2.0), (0.0, 4.0)));
        let whole = [0.0, 0.0, 32.0, 16.0];
        let d = |score: f32, coefs: [f32; 3]| Detection {
            class: 0,
            score,
            bbox: whole,
            coefs: coefs.to_vec(),
        };
        // Best first: the left half (0.9), everything (0.8), the left half again (0.7: no
        // pixel left, no id), the top cell row (0.6: image rows lie at input y = 5, 7, 9, 11,
        // below the mask's edge at 4: no pixel, no id).
        let dets = [
            d(0.9, [1.0, 0.0, 0.0]),
            d(0.8, [0.0, 0.0, 1.0]),
            d(0.7, [1.0, 0.0, 0.0]),
            d(0.6, [0.0, 1.0, 0.0]),
        ];
        let (labels, owners) = label_image(&dets, &protos, (32, 16), &grid);
        assert_eq!(owners, vec![0, 1]);
        // Image column u lies at input x = 2u + 1: columns 0..8 are left of x = 16.
        let want = LabelImage::from_fn(16, 4, |u, _| if u < 8 { 1 } else { 2 });
        assert_eq!(labels, want);
    }
}
