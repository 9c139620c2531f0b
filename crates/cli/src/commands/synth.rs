use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use voxpan_sim::{MaskErrors, SensorModel, SynthConfig, World, generate};

use crate::progress::Counter;

#[derive(clap::Args)]
pub struct Args {
    /// Output folder (flat format: Intrinsics.txt, label CSVs, run1/, groundtruth_mesh.ply).
    #[arg(long)]
    out: PathBuf,
    /// Size preset; the options below override it.
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    /// The world: one furnished room, or a flat of three rooms joined by doorways (rugs and
    /// doors in each, shelves of books).
    #[arg(long, value_enum, default_value_t = WorldArg::Room)]
    world: WorldArg,
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
    /// Seed of the predicted masks alone (default: --seed): the same room, trajectory and
    /// depth with another draw of the network's errors.
    #[arg(long)]
    mask_seed: Option<u64>,
    /// Strength of the predicted-mask errors (0 = perfect masks, 1 = the strength voxpan's
    /// synthetic figures use; its over-coverage is several times a real network's, which
    /// `--error over-cover=0.1` matches).
    #[arg(long, default_value_t = 1.0)]
    mask_error: f64,
    /// Masks err only by over-covering (no jitter, fragments, merges or misses): the error
    /// depth refinement targets.
    #[arg(long, conflicts_with = "harder")]
    over_cover_only: bool,
    /// The strength of one kind of mask error, overriding --mask-error for it (repeatable):
    /// over-cover, jitter, fragments, merges, misses (the classic mix, at --mask-error), and
    /// the harder modes, off unless given: flicker (a confusable class), splits (a thing cut
    /// in parts), one-by-one (a group of books segmented item by item), repeated-fragments
    /// (false small things at fixed places), stuff-per-class (the stuff regions of one class
    /// in view as one segment, as a panoptic network gives them, in a share min(1, STRENGTH)
    /// of frames). E.g. --error flicker=1 --error splits=0.5.
    #[arg(long = "error", value_name = "MODE=STRENGTH", value_parser = parse_error_mode)]
    errors: Vec<(String, f64)>,
    /// Every harder mode but stuff-per-class at --mask-error too (as --error for each).
    #[arg(long)]
    harder: bool,
    /// Exact depth: no noise, quantisation, holes or range limit.
    #[arg(long)]
    ideal_depth: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum WorldArg {
    Room,
    Flat,
}

/// `MODE=STRENGTH`, with a mode [`MaskErrors::MODES`] names.
fn parse_error_mode(text: &str) -> Result<(String, f64), String> {
    let (mode, strength) = text
        .split_once('=')
        .ok_or_else(|| format!("expected MODE=STRENGTH, found {text:?}"))?;
    if !MaskErrors::MODES.contains(&mode) {
        return Err(format!(
            "unknown mask error {mode:?}; the modes are {}",
            MaskErrors::MODES.join(", ")
        ));
    }
    let strength: f64 = strength
        .parse()
        .map_err(|_| format!("{mode}: the strength {strength:?} is not a number"))?;
    if !(strength.is_finite() && (0.0..=10.0).contains(&strength)) {
        return Err(format!(
            "{mode}: the strength must be between 0 and 10 (found {strength})"
        ));
    }
    Ok((mode.to_owned(), strength))
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
    config.mask_seed = args.mask_seed;
    config.world = match args.world {
        WorldArg::Room => World::Room,
        WorldArg::Flat => World::Flat,
    };
    config.masks = match (args.over_cover_only, args.harder) {
        (true, _) => MaskErrors::over_cover_only(args.mask_error),
        (false, true) => MaskErrors::harder(args.mask_error),
        (false, false) => MaskErrors::new(args.mask_error),
    };
    for (mode, strength) in &args.errors {
        *config.masks.mode_mut(mode).expect("checked by the parser") = *strength;
    }
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
