//! After `voxpan run`: `metrics.json` (machine-readable) and `report.md` / `report.html`.

use plotters::prelude::*;
use voxpan_map::{InstanceSummary, PanopticMap};
use voxpan_pipeline::protocols::{ReferenceComparison, SurfaceReport};
use voxpan_pipeline::{Config, ONCE_PER_RUN, Outputs, RunFolder, RunReport, STAGES};

use crate::SampleFrame;
use crate::document::{Block, Cell, Document, Table};
use crate::views::{Paint, class_color, overview_poses, perspective, top_down};
use crate::{ReportError, Result};

/// What a run report shows.
pub struct RunSummary<'a> {
    /// What was mapped (a dataset folder, a bag, ...).
    pub input: &'a str,
    pub config: &'a Config,
    pub report: &'a RunReport,
    pub outputs: &'a Outputs,
    /// The map against a ground-truth mesh, when the input has one.
    pub surface: Option<SurfaceReport>,
    /// The map's instances against the tracker-free reference (scores, and the true object
    /// each instance matched), when the input has a ground-truth segmentation.
    pub panoptic: Option<&'a ReferenceComparison>,
    /// The map itself, for its pictures and instance table.
    pub map: Option<&'a PanopticMap>,
    /// A frame to show refinement on (densities, depth and mask before/after).
    pub sample: Option<&'a SampleFrame>,
}

/// A picture written into the run folder (`name`) and embedded into report.html.
struct Picture {
    name: String,
    caption: String,
    png: Vec<u8>,
}

/// Writes `metrics.json`, `report.md` and `report.html` into the run folder.
pub fn write_run_report(folder: &mut RunFolder, run: &RunSummary) -> Result<()> {
    let mut write = |name: &str, text: &str| -> Result<()> {
        let path = folder
            .path(name)
            .map_err(|e| crate::ReportError::new(folder.dir(), e))?;
        crate::write_text(&path, text)?;
        folder.record(name);
        Ok(())
    };
    let metrics = serde_json::json!({
        "input": run.input,
        "config": run.config,
        "report": run.report,
        "outputs": run.outputs,
        "surface": run.surface,
        "panoptic": run.panoptic.map(|p| p.scores),
        "instance_matches": run.panoptic.map(|p| &p.matches),
        "missed_objects": run.panoptic.map(|p| &p.missed),
    });
    write(
        "metrics.json",
        &serde_json::to_string_pretty(&metrics).expect("plain data"),
    )?;
    let report = run.report;
    let mut rows = vec![
        ("frames".to_owned(), report.frames.to_string()),
        ("frames/s".to_owned(), format!("{:.1}", report.fps)),
        (
            "median frame interval (ms)".to_owned(),
            format!("{:.2}", report.frame_interval_ms),
        ),
        ("map instances".to_owned(), report.instances.to_string()),
        ("allocated blocks".to_owned(), report.blocks.to_string()),
        ("mesh triangles".to_owned(), report.triangles.to_string()),
        (
            "skipped frames".to_owned(),
            report.skipped.len().to_string(),
        ),
    ];
    rows.extend(report.stage_ms.iter().map(|(k, v)| {
        match ONCE_PER_RUN.iter().find(|(key, _)| key == k) {
            Some((_, name)) => (format!("{name}, once (ms)"), format!("{v:.0}")),
            None => (format!("{k} (median ms per frame)"), format!("{v:.2}")),
        }
    }));
    if let Some(s) = run.surface {
        rows.push((
            "accuracy vs ground-truth mesh (every vertex)".to_owned(),
            format!(
                "mean {:.1} mm, median {:.1} mm, 95th percentile {:.1} mm ({:.1} % within a voxel)",
                1000.0 * s.accuracy_mean_m,
                1000.0 * s.accuracy_median_m,
                1000.0 * s.accuracy_p95_m,
                s.accuracy_within
            ),
        ));
        rows.push((
            "completeness (observed truth within a voxel)".to_owned(),
            format!("{:.1} %", s.completeness_within),
        ));
        rows.push((
            "label agreement (surface voxels)".to_owned(),
            format!("{:.1} %", s.label_agreement),
        ));
    }
    if let Some(p) = run.panoptic.map(|p| p.scores) {
        rows.push((
            "voxel PQ vs ground truth (all / things / stuff)".to_owned(),
            format!("{:.1} / {:.1} / {:.1}", p.all.pq, p.things.pq, p.stuff.pq),
        ));
        rows.push((
            "instances / true objects (split, merged)".to_owned(),
            format!(
                "{} / {} ({} split, {} merged)",
                p.instances, p.objects, p.over_segmented, p.under_segmenting
            ),
        ));
    }
    let mut doc = Document::new(
        format!("voxpan run on {}", run.input),
        "table{border-collapse:collapse}td,th{border:1px solid #999;padding:2px 8px}\
         figure{display:inline-block;vertical-align:top;margin:0 1em 1em 0}\
         img{max-width:100%;height:auto}",
    );
    if report.stopped_early {
        doc.push(Block::Strong(format!(
            "Stopped early (interrupted): the outputs hold what {} frames built.",
            report.frames
        )));
    }
    let mut summary = Table::new(&["", ""]);
    for (k, v) in rows {
        summary.row([Cell::from(k), Cell::from(v)]);
    }
    doc.push(Block::Table(summary));
    if !report.skipped.is_empty() {
        doc.push(Block::Heading("Skipped frames".into()));
        doc.push(Block::List(
            report
                .skipped
                .iter()
                .map(|s| format!("{}: {}", s.frame, s.reason))
                .collect(),
        ));
    }
    if !report.warnings.is_empty() {
        doc.push(Block::Heading("Warnings".into()));
        doc.push(Block::List(report.warnings.clone()));
    }
    let mut pictures = Vec::new();
    if let Some(map) = run.map {
        pictures.extend(map_pictures(map, &report.poses)?);
        doc.blocks.extend(instance_table(map, run.panoptic));
        if let Some(truth) = run.panoptic {
            doc.blocks.extend(missed_table(map, truth));
        }
    }
    if report.timeline.len() >= 2 {
        pictures.push(timeline_plot(report)?);
    }
    if let Some(sample) = run.sample {
        // Plotted straight into the staging folder, then embedded like the others.
        let probe = folder
            .path("report/densities.png")
            .map_err(|e| ReportError::new(folder.dir(), e))?;
        let dir = probe.parent().expect("inside the folder");
        for (file, caption) in crate::eval_report::refinement_pictures(dir, sample)? {
            let path = dir.join(file);
            let png = std::fs::read(&path).map_err(|e| ReportError::new(&path, e))?;
            pictures.push(Picture {
                name: format!("report/{file}"),
                caption,
                png,
            });
        }
    }
    if !pictures.is_empty() {
        doc.push(Block::Heading("Pictures".into()));
    }
    for p in pictures {
        let path = folder
            .path(&p.name)
            .map_err(|e| ReportError::new(folder.dir(), e))?;
        voxpan_io::write_atomically(&path, |w| w.write_all(&p.png))?;
        folder.record(&p.name);
        doc.push(Block::Figure {
            caption: p.caption,
            file: p.name,
            png: Some(p.png),
        });
    }
    doc.push(Block::Heading("Configuration".into()));
    doc.push(Block::Code {
        language: "toml",
        text: run.config.to_toml(),
    });
    doc.push(Block::Paragraph(
        "Meshes: mesh_rgb.ply, mesh_instance.ply, mesh_class.ply, instances/. Mask scores: \
         voxpan eval DATASET --report DIR."
            .into(),
    ));
    let mut write = |name: &str, text: &str| -> Result<()> {
        let path = folder
            .path(name)
            .map_err(|e| crate::ReportError::new(folder.dir(), e))?;
        crate::write_text(&path, text)?;
        folder.record(name);
        Ok(())
    };
    write("report.md", &doc.markdown())?;
    write("report.html", &doc.html())
}

/// Top-down and two overview ray casts, each by RGB, instance and class.
fn map_pictures(map: &PanopticMap, poses: &[voxpan_core::Pose]) -> Result<Vec<Picture>> {
    let mut out = Vec::new();
    let views = overview_poses(map, poses);
    for paint in Paint::ALL {
        let by = paint.name();
        out.push(picture(
            format!("report/top_{by}.png"),
            format!("The map from above by {by}, camera path in black"),
            &top_down(map, poses, paint, 800),
        )?);
        for (k, pose) in views.iter().enumerate() {
            out.push(picture(
                format!("report/view{}_{by}.png", k + 1),
                format!("Overview {} by {by} (ray cast of the TSDF)", k + 1),
                &perspective(map, pose, paint),
            )?);
        }
    }
    if let Some(costmap) = map.costmap() {
        out.push(picture(
            "report/costmap.png".into(),
            format!(
                "The costmap ({} to {} m up): black obstacles, red to white the clearance in \
                 the plane up to {} m, grey unknown",
                map.config().esdf.slice_min_z,
                map.config().esdf.slice_max_z,
                map.config().esdf.max_distance
            ),
            &clearance_picture(&costmap, map.config().esdf.max_distance as f32, 800),
        )?);
    }
    Ok(out)
}

/// The costmap's clearance per cell, seen from above (the grid's highest row at the top),
/// scaled up to about `size` pixels on its longer side: black where occupied, red to yellow to
/// white with the distance to the nearest obstacle, grey where unknown.
fn clearance_picture(
    costmap: &voxpan_map::Costmap,
    max_distance: f32,
    size: usize,
) -> voxpan_core::ColorImage {
    let scale = (size / costmap.width.max(costmap.height)).max(1);
    let (w, h) = (costmap.width * scale, costmap.height * scale);
    voxpan_core::Image::from_fn(w, h, |x, y| {
        let (column, row) = (x / scale, costmap.height - 1 - y / scale);
        match (
            costmap.cell(column, row),
            costmap.clearance[row * costmap.width + column],
        ) {
            (voxpan_map::CostmapCell::Unknown, _) | (_, None) => [160, 160, 160],
            (voxpan_map::CostmapCell::Occupied, _) => [0, 0, 0],
            (voxpan_map::CostmapCell::Free, Some(d)) => {
                // Red next to an obstacle, through yellow, to white at the field's reach.
                let t = (d / max_distance).clamp(0.0, 1.0);
                let lerp = |a: [f32; 3], b: [f32; 3], t: f32| {
                    std::array::from_fn(|k| (a[k] + (b[k] - a[k]) * t) as u8)
                };
                let (red, yellow, white) = ([200.0, 40.0, 30.0], [245.0, 200.0, 50.0], [255.0; 3]);
                if t < 0.5 {
                    lerp(red, yellow, 2.0 * t)
                } else {
                    lerp(yellow, white, 2.0 * t - 1.0)
                }
            }
        }
    })
}

fn picture(name: String, caption: String, image: &voxpan_core::ColorImage) -> Result<Picture> {
    let mut png = Vec::new();
    let mut encoder = png::Encoder::new(&mut png, image.width() as u32, image.height() as u32);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let pixels: Vec<u8> = image.pixels().iter().flatten().copied().collect();
    encoder
        .write_header()
        .and_then(|mut w| w.write_image_data(&pixels))
        .map_err(|e| ReportError::new(std::path::Path::new(&name), e))?;
    Ok(Picture { name, caption, png })
}

/// The instances, largest first, with their class colour as a legend and, with ground truth,
/// the true object each matched in the voxel PQ (IoU > 0.5), or "—".
fn instance_table(map: &PanopticMap, truth: Option<&ReferenceComparison>) -> Vec<Block> {
    let mut instances = map.instances();
    instances.sort_by_key(|i| std::cmp::Reverse(i.voxels));
    let mut columns = vec!["id", "class", "kind", "voxels", "size (m)", "frames seen"];
    if truth.is_some() {
        columns.push("true object (voxel IoU)");
    }
    let mut blocks = vec![Block::Heading("Instances".into())];
    if truth.is_some() {
        blocks.push(Block::Paragraph(
            "True object: the ground-truth instance (its id in the segmentation images, its \
             class) this instance matches in the voxel PQ, i.e. with a surface voxel IoU above \
             0.5 against the tracker-free reference; — where it matches none."
                .into(),
        ));
    }
    let mut table = Table::new(&columns);
    for i in &instances {
        let kind = if i.is_thing { "thing" } else { "stuff" };
        let size = i.bounds.map_or("-".into(), |b| {
            let s = b.size();
            format!("{:.2} × {:.2} × {:.2}", s[0], s[1], s[2])
        });
        let mut row = vec![
            Cell::from(i.id.to_string()),
            Cell {
                text: class_label(i),
                swatch: Some(class_color(map, i.id)),
            },
            Cell::from(kind),
            Cell::from(i.voxels.to_string()),
            Cell::from(size),
            Cell::from(i.frames_seen.to_string()),
        ];
        if let Some(t) = truth {
            row.push(Cell::from(match t.match_of(i.id) {
                Some(m) => {
                    let id = m.truth_id.map_or("?".into(), |id| id.to_string());
                    match &m.class {
                        Some(c) => format!("{id} {c} ({:.2})", m.iou),
                        None => format!("{id} ({:.2})", m.iou),
                    }
                }
                None => "—".into(),
            }));
        }
        table.row(row);
    }
    blocks.push(Block::Table(table));
    blocks
}

/// An instance's class as the tables show it: its name, else its id, else "-".
fn class_label(i: &InstanceSummary) -> String {
    i.class_name
        .clone()
        .or(i.class_id.map(|c| format!("class {c}")))
        .unwrap_or_else(|| "-".into())
}

/// The true objects no instance matched, largest first, and where their voxels are: the map
/// instances holding most of them, and how many no shown instance leads. Where association
/// loses an object (split into hidden pieces, absorbed by a neighbour) shows here.
fn missed_table(map: &PanopticMap, truth: &ReferenceComparison) -> Vec<Block> {
    let note = format!(
        "{} of {} true objects matched no instance (voxel IoU ≤ 0.5). Where their surface voxels \
         are in the map: the instances holding most of them, and those no shown instance leads \
         (never labelled, or led by an instance still hidden: unconfirmed or under \
         tracking.min_voxels).",
        truth.missed.len(),
        truth.scores.objects
    );
    let mut blocks = vec![
        Block::Heading("Missed objects".into()),
        Block::Paragraph(note),
    ];
    if truth.missed.is_empty() {
        return blocks;
    }
    let mut table = Table::new(&[
        "true object",
        "class",
        "voxels",
        "held by",
        "no shown instance",
    ]);
    let mut missed: Vec<_> = truth.missed.iter().collect();
    missed.sort_by_key(|m| std::cmp::Reverse(m.voxels));
    let instances = map.instances();
    for m in missed {
        let id = m.truth_id.map_or("?".into(), |id| id.to_string());
        let class = m.class.clone().unwrap_or_else(|| "-".into());
        let held: Vec<String> = m
            .holders
            .iter()
            .map(|&(instance, voxels)| {
                let name = instances
                    .iter()
                    .find(|i| i.id == instance)
                    .map_or_else(|| "-".into(), class_label);
                format!("{instance} {name} ({voxels})")
            })
            .collect();
        let held = if held.is_empty() {
            "—".to_owned()
        } else {
            held.join(", ")
        };
        table.row([
            Cell::from(id),
            Cell::from(class),
            Cell::from(m.voxels.to_string()),
            Cell::from(held),
            Cell::from(m.unlabelled.to_string()),
        ]);
    }
    blocks.push(Block::Table(table));
    blocks
}

/// Per-frame milliseconds of each stage (stacked), and the map's instances, over the run.
fn timeline_plot(report: &RunReport) -> Result<Picture> {
    let name = "report/timeline.png".to_owned();
    let (w, h) = (1000usize, 600usize);
    let mut rgb = vec![0u8; w * h * 3];
    let mut draw = || -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>> {
        let root = BitMapBackend::with_buffer(&mut rgb, (w as u32, h as u32)).into_drawing_area();
        root.fill(&WHITE)?;
        let (upper, lower) = root.split_vertically(360);
        let frames = report.timeline.len();
        let total = |r: &voxpan_pipeline::FrameRecord| r.stage_ms.iter().sum::<f64>();
        let top = report.timeline.iter().map(total).fold(1.0, f64::max) * 1.05;
        let mut chart = ChartBuilder::on(&upper)
            .caption(
                "milliseconds per frame by stage, stacked (perception overlaps mapping: work, not wall time)",
                ("sans-serif", 18),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(0..frames, 0f64..top)?;
        chart.configure_mesh().x_desc("frame").y_desc("ms").draw()?;
        // One per stage: a stage added to STAGES needs a colour here (the array's length).
        const COLORS: [RGBColor; STAGES.len()] = [
            RGBColor(120, 120, 120),
            RGBColor(230, 159, 0),
            RGBColor(0, 0, 0),
            RGBColor(0, 114, 178),
            RGBColor(213, 94, 0),
            RGBColor(86, 180, 233),
            RGBColor(204, 121, 167),
            RGBColor(0, 158, 115),
            RGBColor(240, 228, 66),
        ];
        for k in (0..STAGES.len()).rev() {
            let color = COLORS[k];
            chart
                .draw_series(AreaSeries::new(
                    report
                        .timeline
                        .iter()
                        .enumerate()
                        .map(|(i, r)| (i, r.stage_ms[..=k].iter().sum::<f64>())),
                    0.0,
                    color.mix(0.8),
                ))?
                .label(STAGES[k])
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled())
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        let most = report
            .timeline
            .iter()
            .map(|r| r.instances)
            .max()
            .unwrap_or(0)
            + 1;
        let mut chart = ChartBuilder::on(&lower)
            .caption(
                "map instances (confirmed) after each frame",
                ("sans-serif", 18),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(0..frames, 0..most)?;
        chart
            .configure_mesh()
            .x_desc("frame")
            .y_desc("instances")
            .draw()?;
        chart.draw_series(LineSeries::new(
            report
                .timeline
                .iter()
                .enumerate()
                .map(|(i, r)| (i, r.instances)),
            BLUE.stroke_width(2),
        ))?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| ReportError::new(std::path::Path::new(&name), e))?;
    let image = voxpan_core::ColorImage::from_fn(w, h, |x, y| {
        let i = 3 * (y * w + x);
        [rgb[i], rgb[i + 1], rgb[i + 2]]
    });
    picture(
        name,
        "Time per frame by stage, and instances over the run".into(),
        &image,
    )
}
