//! After `voxpan run`: `metrics.json` (machine-readable) and `report.md` / `report.html`.

use voxpan_eval::protocols::SurfaceReport;
use voxpan_eval::volume::PanopticScores;
use voxpan_pipeline::{Config, Outputs, RunFolder, RunReport};

use crate::Result;

/// What a run report shows.
pub struct RunSummary<'a> {
    /// What was mapped (a dataset folder, a bag, ...).
    pub input: &'a str,
    pub config: &'a Config,
    pub report: &'a RunReport,
    pub outputs: &'a Outputs,
    /// The map against a ground-truth mesh, when the input has one.
    pub surface: Option<SurfaceReport>,
    /// The map's instances against the tracker-free reference, when the input has a
    /// ground-truth segmentation.
    pub panoptic: Option<PanopticScores>,
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
        "panoptic": run.panoptic,
    });
    write(
        "metrics.json",
        &serde_json::to_string_pretty(&metrics).expect("plain data"),
    )?;
    let report = run.report;
    let mut rows = vec![
        ("frames".to_owned(), report.frames.to_string()),
        ("frames/s".to_owned(), format!("{:.1}", report.fps)),
        ("map instances".to_owned(), report.instances.to_string()),
        ("allocated blocks".to_owned(), report.blocks.to_string()),
        ("mesh triangles".to_owned(), report.triangles.to_string()),
        (
            "skipped frames".to_owned(),
            report.skipped.len().to_string(),
        ),
    ];
    rows.extend(
        report
            .stage_ms
            .iter()
            .map(|(k, v)| (format!("{k} (median ms)"), format!("{v:.2}"))),
    );
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
    if let Some(p) = run.panoptic {
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
    let mut md = format!("# voxpan run on {}\n\n", run.input);
    let mut html = format!(
        "<!doctype html><meta charset=utf-8><title>voxpan run</title><style>body{{font-family:sans-serif}}\
         td{{border:1px solid #999;padding:2px 8px}}</style><h1>voxpan run on {}</h1>",
        crate::escape(run.input)
    );
    if report.stopped_early {
        let note = format!(
            "Stopped early (interrupted): the outputs hold what {} frames built.",
            report.frames
        );
        md += &format!("**{note}**\n\n");
        html += &format!("<p><b>{note}</b></p>");
    }
    md += "| | |\n|---|---|\n";
    html += "<table>";
    for (k, v) in &rows {
        md += &format!("| {k} | {v} |\n");
        html += &format!("<tr><td>{k}<td>{v}</tr>");
    }
    html += "</table>";
    if !report.skipped.is_empty() {
        md += "\n## Skipped frames\n\n";
        html += "<h2>Skipped frames</h2><ul>";
        for s in &report.skipped {
            md += &format!("- {}: {}\n", s.frame, s.reason);
            html += &format!(
                "<li>{}: {}</li>",
                crate::escape(&s.frame),
                crate::escape(&s.reason)
            );
        }
        html += "</ul>";
    }
    if !report.warnings.is_empty() {
        md += "\n## Warnings\n\n";
        html += "<h2>Warnings</h2><ul>";
        for w in &report.warnings {
            md += &format!("- {w}\n");
            html += &format!("<li>{}</li>", crate::escape(w));
        }
        html += "</ul>";
    }
    md += "\nMeshes: `mesh_rgb.ply`, `mesh_instance.ply`, `mesh_class.ply`, `instances/`. Mask scores: `voxpan eval DATASET --report DIR`.\n";
    write("report.md", &md)?;
    write("report.html", &html)
}
