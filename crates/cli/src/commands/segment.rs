use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::network::NetworkArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    network: NetworkArgs,
    /// Output folder: NNNNNN_predicted.png (8-bit label image, 0 = no instance, or 16-bit
    /// past 255 instances), NNNNNN_labels.json (per id: isthing, category_id, score) and
    /// labels.csv (the model's classes; category_id is its InstanceID), as the flat dataset
    /// stores a network's masks.
    #[arg(long)]
    out: PathBuf,
    /// Colour images (PNG). The frame id is the file name without extension and without a
    /// trailing `_color` (flat's `000074_color.png` gives `000074`).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Replace masks already in --out when --out is the images' own folder (a dataset's run
    /// folder: its masks are refused otherwise).
    #[arg(long)]
    force: bool,
}

/// A colour image's frame id: its file stem without flat's `_color` suffix.
fn frame_id(image: &Path) -> String {
    let stem = image
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    stem.strip_suffix("_color").unwrap_or(&stem).to_owned()
}

pub fn run(args: Args) -> Result<()> {
    if args.network.model.is_none() {
        bail!("--model is required: the ONNX model to segment with");
    }
    // Two images with one id would overwrite each other's output: refuse before any work.
    let mut ids: BTreeMap<String, &PathBuf> = BTreeMap::new();
    for image in &args.images {
        if let Some(first) = ids.insert(frame_id(image), image) {
            bail!(
                "{} and {} both give frame id {}: their outputs would overwrite each other",
                first.display(),
                image.display(),
                frame_id(image)
            );
        }
    }
    // Pointed at a dataset's own run folder, it would replace the dataset's masks.
    crate::paths::refuse_file_as_folder("--out", &args.out)?;
    let inputs: Vec<&Path> = args.images.iter().map(PathBuf::as_path).collect();
    let beside_inputs = args.images.iter().filter_map(|i| i.parent()).any(|dir| {
        crate::paths::same_file(dir, &args.out)
            || dir.as_os_str().is_empty() && crate::paths::same_file(Path::new("."), &args.out)
    });
    for id in ids.keys() {
        for name in [format!("{id}_predicted.png"), format!("{id}_labels.json")] {
            let output = args.out.join(&name);
            crate::paths::refuse_overwriting("--out", &output, &inputs)?;
            if beside_inputs && output.exists() && !args.force {
                bail!(
                    "--out {}: {name} exists beside the images (the dataset's own masks?); \
                     choose another folder, or --force to replace them",
                    args.out.display()
                );
            }
        }
    }
    // Every image readable before the first output is written (their headers: cheap).
    for image in &args.images {
        voxpan_io::color_image_size(image)?;
    }
    let mut segmenter = args.network.open()?.expect("--model checked above");
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let names = segmenter.yolo().info().names.clone();
    eprintln!(
        "{} ({}, {} classes, {}x{} input) on {}",
        segmenter.yolo().path().display(),
        segmenter.yolo().info().layout.name(),
        names.len(),
        segmenter.yolo().info().input.0,
        segmenter.yolo().info().input.1,
        segmenter.yolo().backend_name()
    );
    for image in &args.images {
        let color = voxpan_io::read_color_png(image)?;
        let (segments, _) = segmenter.segment_image(&color)?;
        let id = frame_id(image);
        let labels = args.out.join(format!("{id}_predicted.png"));
        voxpan_io::write_label_png(&labels, &segments.labels)?;
        voxpan_io::write_segments_json(
            &args.out.join(format!("{id}_labels.json")),
            &segments.segments,
        )?;
        let t = segmenter.yolo().times();
        let found: Vec<String> = segments
            .segments
            .iter()
            .map(|s| {
                let name = s
                    .class_id
                    .and_then(|c| names.get(c as usize))
                    .map_or("?", String::as_str);
                format!("{name} {:.2}", s.score.unwrap_or(0.0))
            })
            .collect();
        println!(
            "{id}: {} instances in {:.0} ms{}{}",
            found.len(),
            t.preprocess + t.inference + t.postprocess,
            if found.is_empty() { "" } else { ": " },
            found.join(", ")
        );
    }
    voxpan_io::write_class_csv(segmenter.class_table(), &args.out.join("labels.csv"))?;
    Ok(())
}
