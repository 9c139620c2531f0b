use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use voxpan_sim::{MaskErrors, SensorModel, SynthConfig, generate};

use crate::progress::Counter;

#[derive(clap::Args)]
pub struct Args {
    /// Output folder (flat format: Intrinsics.txt, label CSVs, run1/, groundtruth_mesh.ply).
    #[arg(long)]
    out: PathBuf,
    /// Size preset; the options below override it.
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    /// Number of frames.
    #[arg(long)]
    frames: Option<usize>,
    /// Image width in pixels.
    #[arg(long)]
    width: Option<usize>,
    /// Image height in pixels.
    #[arg(long)]
    height: Option<usize>,
    /// Random seed: the same seed gives the same room, trajectory, noise and masks.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Strength of the predicted-mask errors (0 = perfect masks, 1 = typical lightweight CNN).
    #[arg(long, default_value_t = 1.0)]
    mask_error: f64,
    /// Masks err only by over-covering (no jitter, fragments, merges or misses): the error
    /// depth refinement targets.
    #[arg(long)]
    over_cover_only: bool,
    /// Exact depth: no noise, quantisation, holes or range limit.
    #[arg(long)]
    ideal_depth: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum Preset {
    /// 200 frames, 640x480.
    Default,
    /// 20 frames, 160x120 (tests).
    Tiny,
}

pub fn run(args: Args) -> Result<()> {
    let mut config = match args.preset {
        Preset::Default => SynthConfig::default(),
        Preset::Tiny => SynthConfig::tiny(),
    };
    config.frames = args.frames.unwrap_or(config.frames);
    config.width = args.width.unwrap_or(config.width);
    config.height = args.height.unwrap_or(config.height);
    config.seed = args.seed;
    config.masks = if args.over_cover_only {
        MaskErrors::over_cover_only(args.mask_error)
    } else {
        MaskErrors::new(args.mask_error)
    };
    if args.ideal_depth {
        config.sensor = SensorModel::ideal();
    }
    if config.frames == 0 || config.width < 8 || config.height < 8 {
        bail!("need at least one frame of at least 8x8 pixels");
    }
    // Strength 1 bleeds masks by up to 15 px; 10 (150 px) already covers most of a VGA frame,
    // and beyond it the error models' work grows without making masks any worse.
    if !(args.mask_error.is_finite() && (0.0..=10.0).contains(&args.mask_error)) {
        bail!(
            "--mask-error must be between 0 and 10 (found {})",
            args.mask_error
        );
    }
    let counter = Counter::new("rendering", "rendering frame", config.frames);
    let start = Instant::now();
    let summary = generate(&args.out, &config, |_| counter.inc())
        .with_context(|| format!("generating into {}", args.out.display()))?;
    counter.finish();
    println!(
        "wrote {} frames ({}x{}, {} objects, ground-truth mesh of {} triangles) to {} in {:.1} s",
        summary.frames,
        config.width,
        config.height,
        summary.objects,
        summary.mesh_triangles,
        args.out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
