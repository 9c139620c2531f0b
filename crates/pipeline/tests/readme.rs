//! The README's configuration block is the defaults, key for key and value for value: a
//! changed default, a new key or a renamed one fails here until the README says so.

use voxpan_pipeline::Config;
use voxpan_test_support::{code_block, readme, readme_section};

#[test]
fn the_readme_configuration_block_is_the_defaults() {
    let readme = readme();
    let block = code_block(readme_section(&readme, "## Configuration"), "toml");
    let mut written: toml::Table = toml::from_str(block).expect("the README's block is TOML");
    let mut defaults: toml::Table = toml::from_str(&Config::default().to_toml()).unwrap();
    // The memory limit's default is half the machine's memory (unset in the file); the README
    // shows a value and says so.
    let resources = written.remove("resources").expect("a [resources] section");
    assert_eq!(
        resources.as_table().map(|t| t.keys().collect::<Vec<_>>()),
        Some(vec![&"max_memory_gb".to_owned()])
    );
    defaults.remove("resources");
    assert_eq!(written, defaults, "README.md's configuration block");
    // And it is a configuration a run accepts, as it stands.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("readme.toml");
    std::fs::write(&path, block).unwrap();
    Config::from_toml_file(&path).expect("voxpan run --config accepts the README's block");
}
