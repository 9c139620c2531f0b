//! `voxpan eval --report DIR`: report.md and report.html with the tables and plots a person
//! needs to see whether refinement helped.

use std::path::Path;

use plotters::prelude::*;
use voxpan_core::{ColorImage, DepthImage, Frame, LabelImage, Segment, is_valid_depth};
use voxpan_kde::{Kde, KdeMethod};
use voxpan_pipeline::protocols::{MaskEvaluation, VoxelRow};
use voxpan_refine::{RefineConfig, Refiner};

use crate::document::{Block, Cell, Document, Table};
use crate::{ReportError, Result};

/// A frame to illustrate refinement on: its id, colour, measured depth, labels and segments.
pub struct SampleFrame {
    pub id: String,
    pub color: ColorImage,
    pub depth: DepthImage,
    pub labels: LabelImage,
    pub segments: Vec<Segment>,
}

impl SampleFrame {
    /// The frame as a sample, if its segmentation has a thing to show (refinement is about
    /// objects over-covering what lies behind them).
    pub fn from_frame(frame: Frame) -> Option<Self> {
        let s = frame.segments?;
        s.segments
            .iter()
            .any(|seg| seg.is_thing == Some(true))
            .then_some(Self {
                id: frame.id,
                color: frame.color,
                depth: frame.depth,
                labels: s.labels,
                segments: s.segments,
            })
    }
}

/// Pictures of refinement on `sample`: the depth densities of its largest thing masks with the
/// kept interval, the first one's depth before and after, and that mask on the colour image
/// (kept pixels green, removed red). Written into `dir`; returns (file name, caption) pairs.
pub(crate) fn refinement_pictures(
    dir: &Path,
    sample: &SampleFrame,
) -> Result<Vec<(&'static str, String)>> {
    let mut out = Vec::new();
    let shown = plot_densities(
        &dir.join("densities.png"),
        &sample.depth,
        &sample.labels,
        &sample.segments,
    )?;
    out.push((
        "densities.png",
        format!(
            "Frame {}: depth densities of sample masks (default rule): kept interval shaded, cut-offs in red",
            sample.id
        ),
    ));
    if let Some(&seg) = shown.first() {
        depth_before_after(
            &dir.join("depth_before_after.png"),
            &sample.depth,
            &sample.labels,
            seg,
        )?;
        out.push((
            "depth_before_after.png",
            format!(
                "Frame {}: depth under the first sample mask, predicted (left) and refined (right)",
                sample.id
            ),
        ));
        mask_on_color(&dir.join("mask_on_color.png"), sample, seg)?;
        out.push((
            "mask_on_color.png",
            format!(
                "Frame {}: the first sample mask on the colour image, kept by refinement (green) and removed (red)",
                sample.id
            ),
        ));
    }
    Ok(out)
}

/// Segment `id` of `sample` over its colour image: pixels refinement keeps tinted green, those
/// it removes tinted red.
fn mask_on_color(path: &Path, sample: &SampleFrame, id: u16) -> Result<()> {
    let mut refined = sample.labels.clone();
    Refiner::new(RefineConfig::default())
        .refine_frame(&sample.depth, &mut refined, &[Segment::bare(id)])
        .map_err(|e| ReportError::new(path, e))?;
    let tint =
        |c: [u8; 3], to: [u8; 3]| [0, 1, 2].map(|k| ((c[k] as u16 + 2 * to[k] as u16) / 3) as u8);
    let (w, h) = sample.color.dims();
    let out = ColorImage::from_fn(w, h, |x, y| {
        let c = *sample.color.get(x, y);
        match (*sample.labels.get(x, y) == id, *refined.get(x, y) == id) {
            (true, true) => tint(c, [0, 200, 0]),
            (true, false) => tint(c, [230, 0, 0]),
            _ => c,
        }
    });
    voxpan_io::write_color_png(path, &out)?;
    Ok(())
}

/// What the evaluation report shows.
pub struct EvalReport<'a> {
    pub dataset: &'a Path,
    pub evaluation: &'a MaskEvaluation,
    pub sample: Option<SampleFrame>,
    /// Maps against the tracker-free reference, when computed.
    pub voxel: Option<&'a [VoxelRow]>,
}

/// Writes `report.md`, `report.html` and their plots into `dir`.
pub fn write_eval_report(dir: &Path, data: &EvalReport) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| ReportError::new(dir, e))?;
    let mut images = Vec::new();
    plot_iou_per_frame(&dir.join("iou_per_frame.png"), data)?;
    images.push(("iou_per_frame.png", "Mean matched IoU per frame, per rule"));
    let sample_pictures = match &data.sample {
        Some(sample) => refinement_pictures(dir, sample)?,
        None => Vec::new(),
    };
    for (name, caption) in &sample_pictures {
        images.push((*name, caption.as_str()));
    }

    let mut doc = Document::new(
        format!("voxpan evaluation of {}", data.dataset.display()),
        "body{max-width:60em;margin:auto}table{border-collapse:collapse}\
         td,th{border:1px solid #999;padding:2px 8px;text-align:right}img{max-width:100%}",
    );
    let rows = &data.evaluation.rows;
    let frames = rows.first().map_or(0, |r| r.all.frames);
    doc.push(Block::Paragraph(format!(
        "{frames} frames; mean matched IoU, PQ, SQ, RQ, pixel precision and recall in percent \
         (protocol in docs/design/refinement.md)."
    )));
    for (k, part) in ["All segments", "Things", "Stuff"].iter().enumerate() {
        doc.push(Block::Heading((*part).into()));
        let mut table = Table::new(&["masks", "mIoU", "PQ", "SQ", "RQ", "precision", "recall"]);
        for row in rows {
            let s = [&row.all, &row.things, &row.stuff][k];
            let cells = [s.mean_matched_iou, s.pq, s.sq, s.rq, s.precision, s.recall];
            table.row(
                std::iter::once(Cell::from(row.name.as_str()))
                    .chain(cells.iter().map(|c| Cell::from(format!("{c:.2}")))),
            );
        }
        doc.push(Block::Table(table));
    }
    if let Some(rows) = data.voxel {
        doc.push(Block::Heading(
            "Maps against the tracker-free reference (panoptic quality over voxels)".into(),
        ));
        let mut table = Table::new(&VOXEL_COLUMNS);
        for cells in voxel_table(rows) {
            table.row(cells.into_iter().map(Cell::from));
        }
        doc.push(Block::Table(table));
        doc.push(Block::Paragraph(VOXEL_LEGEND.into()));
    }
    if let (Some(none), Some(default)) = (
        rows.iter().find(|r| r.name == "none"),
        rows.iter().find(|r| r.name == "default"),
    ) {
        let (di, dp) = (
            default.all.mean_matched_iou - none.all.mean_matched_iou,
            default.all.pq - none.all.pq,
        );
        doc.push(Block::Strong(format!(
            "The default refinement changes mean matched IoU by {di:+.2} and PQ by {dp:+.2} \
             points over no refinement."
        )));
    }
    for (file, caption) in &images {
        doc.push(Block::Heading((*caption).into()));
        doc.push(Block::Figure {
            caption: (*caption).into(),
            file: (*file).into(),
            png: None,
        });
    }
    crate::write_text(&dir.join("report.md"), &doc.markdown())?;
    crate::write_text(&dir.join("report.html"), &doc.html())
}

/// Runs a plotting step, naming the picture in its error.
fn plot<T>(
    path: &Path,
    draw: impl FnOnce() -> std::result::Result<T, Box<dyn std::error::Error + Send + Sync>>,
) -> Result<T> {
    draw().map_err(|e| ReportError::new(path, e))
}

const COLORS: [RGBColor; 5] = [BLACK, RED, BLUE, GREEN, MAGENTA];

/// The valid depths under segment `id`.
fn valid_depths_under(depth: &DepthImage, labels: &LabelImage, id: u16) -> Vec<f32> {
    labels
        .pixels()
        .iter()
        .zip(depth.pixels())
        .filter(|&(&l, &d)| l == id && is_valid_depth(d))
        .map(|(_, &d)| d)
        .collect()
}

fn plot_iou_per_frame(path: &Path, data: &EvalReport) -> Result<()> {
    plot(path, || {
        let root = BitMapBackend::new(path, (1000, 420)).into_drawing_area();
        root.fill(&WHITE)?;
        let per_frame = &data.evaluation.per_frame;
        let n = per_frame.len().max(1);
        let mut chart = ChartBuilder::on(&root)
            .caption("mean matched IoU per frame", ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0..n, 0f64..100f64)?;
        chart
            .configure_mesh()
            .x_desc("frame (in order)")
            .y_desc("IoU %")
            .draw()?;
        for (k, row) in data.evaluation.rows.iter().enumerate() {
            let color = COLORS[k % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    per_frame
                        .iter()
                        .enumerate()
                        .map(|(i, (_, v))| (i, v.get(k).copied().unwrap_or(0.0))),
                    color.stroke_width(2),
                ))?
                .label(row.name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
        Ok(())
    })
}

/// Densities of up to three of the largest thing (or unknown-kind) masks; returns their ids.
fn plot_densities(
    path: &Path,
    depth: &DepthImage,
    labels: &LabelImage,
    segments: &[Segment],
) -> Result<Vec<u16>> {
    plot(path, || {
        let mut sizes: Vec<(usize, u16)> = segments
            .iter()
            .filter(|s| s.is_thing != Some(false))
            .map(|s| (labels.pixels().iter().filter(|&&l| l == s.id).count(), s.id))
            .collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        let chosen: Vec<u16> = sizes.iter().take(3).map(|s| s.1).collect();
        let root = BitMapBackend::new(path, (1200, 380)).into_drawing_area();
        root.fill(&WHITE)?;
        let panels = root.split_evenly((1, chosen.len().max(1)));
        let mut kde = Kde::new(KdeMethod::Isj).with_resolution_floor();
        // The intervals the frame's refinement keeps (it weighs pixels by their place in the mask,
        // which the depths alone do not show).
        let config = RefineConfig::default();
        let chosen_segments: Vec<Segment> = segments
            .iter()
            .filter(|s| chosen.contains(&s.id))
            .cloned()
            .collect();
        let reports =
            Refiner::new(config).refine_frame(depth, &mut labels.clone(), &chosen_segments)?;
        for (panel, &id) in panels.iter().zip(&chosen) {
            let depths = valid_depths_under(depth, labels, id);
            let as_f64: Vec<f64> = depths
                .iter()
                .map(|&d| d as f64)
                .filter(|&d| d <= config.far_limit)
                .collect();
            let kept = reports
                .iter()
                .find(|r| r.id == id)
                .and_then(|r| r.low.zip(r.high));
            let (Ok(density), Some((low, high))) = (kde.estimate(&as_f64), kept) else {
                continue;
            };
            let xs: Vec<(f64, f64)> = (0..density.values.len())
                .map(|i| (density.x(i), density.values[i]))
                .collect();
            let (lo, hi) = (
                xs.first().map_or(0.0, |p| p.0),
                xs.last().map_or(1.0, |p| p.0),
            );
            let top = xs.iter().map(|p| p.1).fold(0.0, f64::max) * 1.05;
            let mut chart = ChartBuilder::on(panel)
                .caption(
                    format!("segment {id}: {} px", depths.len()),
                    ("sans-serif", 16),
                )
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(40)
                .build_cartesian_2d(lo..hi, 0f64..top.max(1e-9))?;
            chart
                .configure_mesh()
                .x_desc("depth [m]")
                .y_desc("density")
                .draw()?;
            chart.draw_series(AreaSeries::new(
                xs.iter().filter(|p| p.0 >= low && p.0 <= high).copied(),
                0.0,
                BLUE.mix(0.25),
            ))?;
            chart.draw_series(LineSeries::new(xs.iter().copied(), BLACK.stroke_width(2)))?;
            for x in [low, high] {
                chart.draw_series(LineSeries::new([(x, 0.0), (x, top)], RED.stroke_width(2)))?;
            }
        }
        root.present()?;
        Ok(chosen)
    })
}

/// The depth under segment `id`, predicted and refined, side by side (near = bright).
fn depth_before_after(path: &Path, depth: &DepthImage, labels: &LabelImage, id: u16) -> Result<()> {
    plot(path, || {
        let mut refined = labels.clone();
        Refiner::new(RefineConfig::default()).refine_frame(
            depth,
            &mut refined,
            &[Segment::bare(id)],
        )?;
        let (w, h) = depth.dims();
        let valid = valid_depths_under(depth, labels, id);
        let (lo, hi) = valid
            .iter()
            .fold((f32::INFINITY, 0f32), |(a, b), &d| (a.min(d), b.max(d)));
        let shade = |l: u16, d: f32| -> [u8; 3] {
            if l != id || !is_valid_depth(d) {
                return [30, 30, 30];
            }
            let t = ((hi - d) / (hi - lo).max(1e-6)).clamp(0.0, 1.0);
            [
                (80.0 + 175.0 * t) as u8,
                (40.0 + 120.0 * t) as u8,
                (200.0 * (1.0 - t)) as u8,
            ]
        };
        let out = voxpan_core::ColorImage::from_fn(2 * w + 10, h, |x, y| {
            if x < w {
                shade(*labels.get(x, y), *depth.get(x, y))
            } else if x >= w + 10 {
                shade(*refined.get(x - w - 10, y), *depth.get(x - w - 10, y))
            } else {
                [255, 255, 255]
            }
        });
        voxpan_io::write_color_png(path, &out)?;
        Ok(())
    })
}

/// Columns of the voxel table: PQ / SQ / RQ over all instances, PQ of things and of stuff,
/// and how instances split and merge objects.
pub const VOXEL_COLUMNS: [&str; 10] = [
    "map",
    "PQ",
    "SQ",
    "RQ",
    "PQ th",
    "PQ st",
    "instances",
    "objects",
    "split",
    "merged",
];

/// What the voxel table's last columns mean.
pub const VOXEL_LEGEND: &str = "instances: map instances (in brackets, those under 100 voxels); \
objects: reference objects; split: objects that are the main object of several instances; \
merged: instances that are the main instance of several objects.";

/// The voxel table's cells, one row per map.
pub fn voxel_table(rows: &[VoxelRow]) -> Vec<Vec<String>> {
    rows.iter()
        .map(|r| {
            let s = &r.scores;
            vec![
                r.name.clone(),
                format!("{:.2}", s.all.pq),
                format!("{:.2}", s.all.sq),
                format!("{:.2}", s.all.rq),
                format!("{:.2}", s.things.pq),
                format!("{:.2}", s.stuff.pq),
                format!("{} ({})", s.instances, s.small_instances),
                s.objects.to_string(),
                s.over_segmented.to_string(),
                s.under_segmenting.to_string(),
            ]
        })
        .collect()
}
