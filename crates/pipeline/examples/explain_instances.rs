//! Lists a map's instances against the tracker-free reference, one line each: what association
//! made of every object (a dev-time tool for studying association, not part of the product).
//!
//! ```text
//! cargo run --release -p voxpan-pipeline --example explain_instances -- DATASET [default|gt|correct] [START:END]
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;

use voxpan_dataset::{FrameSource, open_dataset};
use voxpan_eval::volume::surface_labels;
use voxpan_pipeline::Config;
use voxpan_pipeline::protocols::{
    correctly_associated_map, random_id_map, reference_map, tracked_map,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dataset = args
        .first()
        .ok_or("usage: explain_instances DATASET [default|gt|correct] [START:END]")?;
    let which = args.get(1).map_or("default", String::as_str);
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(std::path::Path::new(dataset))?);
    let range = args.get(2).map(|r| {
        let (a, b) = r.split_once(':').expect("START:END");
        (
            a.parse::<u64>().expect("start"),
            b.parse::<u64>().expect("end"),
        )
    });
    let selected: Vec<usize> = (0..source.len())
        .filter(|&i| {
            range.is_none_or(|(a, b)| {
                let id: u64 = source.frame_id(i).parse().unwrap_or(0);
                (a..=b).contains(&id)
            })
        })
        .collect();
    // A `[segment]` schedule or other settings to study, from a config file.
    let config = match std::env::var_os("VOXPAN_EXPLAIN_CONFIG") {
        Some(path) => Config::from_toml_file(std::path::Path::new(&path))?,
        None => Config::default(),
    };
    let reference = reference_map(&source, &selected, &config)?;
    let map = match which {
        "gt" => random_id_map(&source, &selected, &config, 7)?,
        "correct" => correctly_associated_map(&source, &selected, &config)?,
        _ => tracked_map(&source, &selected, &config)?,
    };
    let (predicted, truth) = (surface_labels(&map), surface_labels(&reference));
    let mut both: BTreeMap<(u16, u16), usize> = BTreeMap::new();
    let mut p_size: BTreeMap<u16, usize> = BTreeMap::new();
    let mut t_size: BTreeMap<u16, usize> = BTreeMap::new();
    for (k, &a) in &predicted {
        *p_size.entry(a).or_default() += 1;
        if let Some(&b) = truth.get(k) {
            *both.entry((a, b)).or_default() += 1;
        }
    }
    for &b in truth.values() {
        *t_size.entry(b).or_default() += 1;
    }
    let name_of = |object: u16| {
        reference
            .class_of(object)
            .and_then(|c| reference.class_name(c))
            .unwrap_or("?")
            .to_owned()
    };
    let mut matched_objects = std::collections::BTreeSet::new();
    println!(
        "{:>5} {:<18} {:>5} {:>6} {:>7} {:>15}  {:<22} {:>6} {:>6}",
        "id", "class", "kind", "frames", "voxels", "size m", "main object", "share", "IoU"
    );
    // Instances that match no object (IoU at most 0.5), with the objects they hold most of.
    let mut false_instances = Vec::new();
    for summary in map.instances() {
        let id = summary.id;
        let Some(&size) = p_size.get(&id) else {
            continue;
        };
        // The objects this instance holds, most voxels first.
        let mut held: Vec<(u16, usize)> = both
            .iter()
            .filter(|((a, _), _)| *a == id)
            .map(|(&(_, b), &n)| (b, n))
            .collect();
        held.sort_by_key(|h| std::cmp::Reverse(h.1));
        let (object, share, iou) =
            held.iter()
                .max_by_key(|h| h.1)
                .map_or((String::from("-"), 0.0, 0.0), |&(b, n)| {
                    let iou = n as f64 / (size + t_size[&b] - n) as f64;
                    if iou > 0.5 {
                        matched_objects.insert(b);
                    }
                    (format!("{} #{b}", name_of(b)), n as f64 / size as f64, iou)
                });
        let extent = summary.bounds.map_or(String::from("-"), |b| {
            let s = b.size();
            format!("{:.1}x{:.1}x{:.1}", s[0], s[1], s[2])
        });
        println!(
            "{:>5} {:<18} {:>5} {:>6} {:>7} {:>15}  {:<22} {:>6.2} {:>6.2}{}",
            id,
            summary.class_name.as_deref().unwrap_or("?"),
            if summary.is_thing { "thing" } else { "stuff" },
            summary.frames_seen,
            size,
            extent,
            object,
            share,
            iou,
            if iou > 0.5 { "" } else { "  FP" }
        );
        if iou <= 0.5 {
            held.truncate(4);
            false_instances.push((id, size, held));
        }
    }
    println!("what each false instance holds (reference objects, voxels):");
    for (id, size, held) in false_instances {
        let held: Vec<String> = held
            .iter()
            .map(|&(b, n)| format!("{} #{b} {n}", name_of(b)))
            .collect();
        println!("  {id}: {size} voxels: {}", held.join(", "));
    }
    // Where each object's reference voxels went: its main instance, other instances, surface
    // the map holds unlabelled, or no surface voxel of the map at all.
    let unlabelled: std::collections::BTreeSet<_> = map
        .surface_voxels()
        .filter(|v| v.instance == 0)
        .map(|v| v.index)
        .collect();
    println!("where each object's voxels went (main instance / other / unlabelled / absent):");
    let mut totals = [0usize; 4];
    for (&b, &n) in &t_size {
        let mut by: BTreeMap<u16, usize> = BTreeMap::new();
        let (mut none, mut absent) = (0, 0);
        for (k, &o) in &truth {
            if o != b {
                continue;
            }
            match predicted.get(k) {
                Some(&a) => *by.entry(a).or_default() += 1,
                None if unlabelled.contains(k) => none += 1,
                None => absent += 1,
            }
        }
        let main = by.values().copied().max().unwrap_or(0);
        let other = by.values().sum::<usize>() - main;
        for (t, x) in totals.iter_mut().zip([main, other, none, absent]) {
            *t += x;
        }
        println!(
            "  {} #{b}: {n}: {main} / {other} / {none} / {absent}",
            name_of(b)
        );
    }
    println!("  all: {totals:?}");
    println!("missed objects:");
    for (&b, &n) in &t_size {
        if matched_objects.contains(&b) {
            continue;
        }
        let mut holders: Vec<(u16, usize)> = both
            .iter()
            .filter(|((_, o), _)| *o == b)
            .map(|(&(a, _), &m)| (a, m))
            .collect();
        holders.sort_by_key(|h| std::cmp::Reverse(h.1));
        holders.truncate(4);
        println!("  {} #{b}: {n} voxels, held by {holders:?}", name_of(b));
    }
    Ok(())
}
