//! `voxpan`: the command-line front end. Each subcommand lives in `commands/` and only parses,
//! calls the stage crates, and prints.

mod commands;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "voxpan",
    version,
    about = "RGB-D panoptic mapping with parameter-free mask refinement"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Map a dataset (flat or TUM RGB-D), or the built-in synthetic world when none is given.
    Run(commands::run::Args),
    /// Refine a frame's instance masks by the depth density under each mask.
    Refine(commands::refine::Args),
    /// Generate a synthetic RGB-D sequence (flat format) with exact ground truth.
    Synth(commands::synth::Args),
    /// Score masks against ground truth: no refinement and each rule, side by side.
    Eval(commands::eval::Args),
    /// Extract a mesh from a saved map, coloured by RGB, instance or class.
    Mesh(commands::mesh::Args),
    /// Time the whole pipeline (frames/s and per-stage medians) against a no-refinement run.
    Bench(commands::bench::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => commands::run::run(args),
        Command::Refine(args) => commands::refine::run(args),
        Command::Synth(args) => commands::synth::run(args),
        Command::Eval(args) => commands::eval::run(args),
        Command::Mesh(args) => commands::mesh::run(args),
        Command::Bench(args) => commands::bench::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
