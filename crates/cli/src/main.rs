//! `voxpan`: the command-line front end. Each subcommand lives in `commands/` and only parses,
//! calls the stage crates, and prints.

mod commands;
mod heap;
mod paths;
mod progress;

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
    /// Map a dataset (flat or TUM RGB-D) or a ROS bag, or the built-in synthetic world when none is given.
    // Boxed: the run options are several times the size of the other commands'.
    Run(Box<commands::run::Args>),
    /// Refine a frame's instance masks by the depth density under each mask.
    Refine(commands::refine::Args),
    /// Generate a synthetic RGB-D sequence (flat format) with exact ground truth.
    Synth(commands::synth::Args),
    /// Score masks against ground truth: no refinement and each rule, side by side.
    Eval(commands::eval::Args),
    /// Extract a mesh from a saved map, coloured by RGB, instance or class.
    Mesh(commands::mesh::Args),
    /// Cut a 2-D costmap (ROS map_server's PGM + YAML) from a saved map's distance field.
    Costmap(commands::costmap::Args),
    /// Time the whole pipeline (frames/s and per-stage medians) against a no-refinement run.
    Bench(commands::bench::Args),
    /// List a ROS bag's topics: types, message counts, rates, duration.
    Info(commands::bag::InfoArgs),
    /// Segment colour images with a YOLO instance-segmentation network (ONNX) into label
    /// images and segment lists, as the flat dataset stores a network's masks.
    Segment(commands::segment::Args),
    /// ROS nodes, ROS 1 or ROS 2 (`--ros2`): `perceive` (camera in, refined masks out), `map`
    /// (those in, mesh out, map saved) or `both` in one process. Needs a voxpan built with
    /// `--features ros1` (ROS 1) or `--features ros2` (both).
    Node(Box<commands::node::Args>),
}

/// Keeps freed memory in the process instead of returning it to the kernel. Frames allocate
/// and free megabyte buffers many times a second; glibc would otherwise map and unmap them
/// each time, and the page faults of fresh mappings cost more than the work done in them
/// (measured on the flat sample: depth decoding 2.8 -> 0.7 ms per frame, the pipeline 19 -> 28
/// frames/s on a loaded 2-core machine). Programs embedding the library can do the same.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; it is called before any thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 256 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

/// A closed standard output (`voxpan info map.voxpan | head`) ends the process quietly, as it
/// does other Unix tools, instead of panicking in `println!`. Not for the commands that serve
/// sockets (the nodes, `run --live`): a peer hanging up must not kill them.
fn die_quietly_on_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: restores the default disposition of one signal before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() -> std::process::ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    if !matches!(cli.command, Command::Run(_) | Command::Node(_)) {
        die_quietly_on_closed_pipe();
    }
    let result = match cli.command {
        Command::Run(args) => match commands::run::run(*args) {
            Ok(code) => return code,
            Err(e) => Err(e),
        },
        Command::Refine(args) => commands::refine::run(args),
        Command::Synth(args) => commands::synth::run(args),
        Command::Eval(args) => commands::eval::run(args),
        Command::Mesh(args) => commands::mesh::run(args),
        Command::Costmap(args) => commands::costmap::run(args),
        Command::Bench(args) => commands::bench::run(args),
        Command::Info(args) => commands::bag::info(args),
        Command::Segment(args) => commands::segment::run(args),
        Command::Node(args) => commands::node::run(*args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes, `: `-joined, each cause said once: many errors print their
/// source in their own message and also return it as `source()`.
fn error_chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let cause = cause.to_string();
        if text.contains(&cause) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::error_chain;

    #[test]
    fn a_cause_already_in_the_message_is_not_said_again() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file");
        let e = anyhow::Error::new(voxpan_io::IoError::io(std::path::Path::new("/m.toml"), io))
            .context("reading the configuration");
        assert_eq!(
            error_chain(&e),
            "reading the configuration: /m.toml: No such file"
        );
    }
}
