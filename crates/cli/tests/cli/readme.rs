//! The README's command line section holds: every command of its table answers `--help`, and
//! every option of its `voxpan run` synopsis is one `voxpan run --help` lists.

use super::common::voxpan_ok;

fn readme() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md")).unwrap()
}

/// The README's "Command line" section.
fn command_line_section(readme: &str) -> &str {
    let after = readme
        .split_once("\n## Command line\n")
        .expect("the section")
        .1;
    after
        .split_once("\n## ")
        .map_or(after, |(section, _)| section)
}

#[test]
fn every_command_and_run_option_the_readme_names_exists() {
    let readme = readme();
    let section = command_line_section(&readme);
    let commands: Vec<&str> = section
        .lines()
        .filter_map(|l| l.strip_prefix("| `voxpan "))
        .map(|l| l.split([' ', '`']).next().unwrap())
        .collect();
    assert!(commands.len() >= 10, "the command table: {commands:?}");
    for command in &commands {
        voxpan_ok([command, "--help"]);
    }
    let synopsis = section
        .split_once("```\nvoxpan run ")
        .expect("the run synopsis")
        .1
        .split_once("\n```")
        .unwrap()
        .0;
    let options: Vec<&str> = synopsis
        .split(|c: char| c.is_whitespace() || "[]|".contains(c))
        .filter(|w| w.starts_with("--"))
        .collect();
    assert!(options.len() >= 20, "the synopsis: {options:?}");
    let help = voxpan_ok(["run", "--help"]);
    let listed = |option: &str| {
        help.lines()
            .any(|l| l.trim_start().split([',', ' ', '=']).any(|w| w == option))
    };
    let missing: Vec<&&str> = options.iter().filter(|o| !listed(o)).collect();
    assert!(
        missing.is_empty(),
        "README options `voxpan run --help` does not list: {missing:?}"
    );
}
