//! The README's command line section holds: every command of its table answers `--help`, and
//! every option of its `voxpan run` synopsis is one `voxpan run --help` lists.

use super::common::voxpan_ok;
use voxpan_test_support::{code_block, readme, readme_section};

#[test]
fn every_command_and_run_option_the_readme_names_exists() {
    let readme = readme();
    let section = readme_section(&readme, "## Command line");
    let commands: Vec<&str> = section
        .lines()
        .filter_map(|l| l.strip_prefix("| `voxpan "))
        .map(|l| l.split([' ', '`']).next().unwrap())
        .collect();
    assert!(commands.len() >= 10, "the command table: {commands:?}");
    for command in &commands {
        voxpan_ok([command, "--help"]);
    }
    let synopsis = code_block(section, "")
        .strip_prefix("voxpan run ")
        .expect("the block is the run synopsis");
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
