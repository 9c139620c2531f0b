pub mod bag;
pub mod bench;
pub mod costmap;
pub mod eval;
pub mod frames;
pub mod live;
pub mod map_info;
pub mod mesh;
pub mod network;
pub mod node;
pub mod refine;
pub mod run;
pub mod segment;
pub mod synth;

/// Warns of frames left out, one line per kind of reason (see
/// [`voxpan_dataset::group_skipped`]).
pub(crate) fn warn_skipped<'a>(skipped: impl IntoIterator<Item = (&'a str, &'a str)>) {
    for group in voxpan_dataset::group_skipped(skipped) {
        eprintln!("warning: {group}");
    }
}
