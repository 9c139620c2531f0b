use std::collections::BTreeMap;
use std::sync::Arc;
use voxpan_dataset::{FrameSource, open_dataset};
use voxpan_eval::protocols::{reference_map, tracked_map};
use voxpan_eval::volume::surface_labels;
use voxpan_pipeline::Config;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let source: Arc<dyn FrameSource> = Arc::from(open_dataset(path.as_ref()).unwrap());
    let sel: Vec<usize> = (0..source.len()).collect();
    let config = std::env::var("CFG")
        .map(|p| Config::from_toml_file(p.as_ref()).unwrap())
        .unwrap_or_default();
    let reference = reference_map(&source, &sel, &config).unwrap();
    let map = if std::env::args().nth(2).as_deref() == Some("gt") {
        let seg = voxpan_perception::GroundTruthMasks::new(source.ground_truth_classes().cloned())
            .with_random_ids(7);
        let mut c = config;
        c.refine.rule = voxpan_refine::Rule::None;
        let p = voxpan_perception::Perception::new(c.perception(), Box::new(seg)).unwrap();
        voxpan_pipeline::build(
            voxpan_dataset::stream(source.clone(), sel.clone()),
            p,
            voxpan_map::PanopticMap::new(c.map()).unwrap(),
            &std::sync::atomic::AtomicBool::new(false),
            |_| Ok(()),
        )
        .unwrap()
        .map
    } else if std::env::args().nth(2).as_deref() == Some("oracle") {
        voxpan_eval::protocols::correctly_associated_map(&source, &sel, &config).unwrap()
    } else {
        tracked_map(&source, &sel, &config).unwrap()
    };
    let (p, t) = (surface_labels(&map), surface_labels(&reference));
    let mut overlap: BTreeMap<(u16, u16), usize> = BTreeMap::new();
    let mut psize: BTreeMap<u16, usize> = BTreeMap::new();
    let mut tsize: BTreeMap<u16, usize> = BTreeMap::new();
    for (k, &a) in &p {
        *psize.entry(a).or_default() += 1;
        if let Some(&b) = t.get(k) {
            *overlap.entry((a, b)).or_default() += 1;
        }
    }
    for &b in t.values() {
        *tsize.entry(b).or_default() += 1;
    }
    let pinfo: BTreeMap<u16, _> = map.instances().into_iter().map(|i| (i.id, i)).collect();
    let tinfo: BTreeMap<u16, _> = reference
        .instances()
        .into_iter()
        .map(|i| (i.id, i))
        .collect();
    let names = if std::env::args().nth(2).as_deref() == Some("gt") {
        source.ground_truth_classes().unwrap()
    } else {
        source.network_classes().unwrap()
    };
    let ids: Vec<u16> = map.instances().iter().map(|i| i.id).collect();
    println!("instances() ids: {ids:?}");
    println!(
        "psize has 5: {:?}, class_of(5) {:?}",
        psize.get(&5),
        map.class_of(5)
    );
    println!("reference objects:");
    for (id, n) in &tsize {
        let i = &tinfo[id];
        let best = overlap
            .iter()
            .filter(|((_, b), _)| b == id)
            .map(|((a, _), n)| (*n, *a))
            .max();
        println!(
            "  obj {id:>4} thing {} class {:?} {} voxels; best inst {:?}",
            i.is_thing,
            i.class_name.as_deref().or(i.class_id.map(|_| "?")),
            n,
            best.map(|(n, a)| (a, n, pinfo.get(&a).map(|x| x.class_name.clone())))
        );
    }
    println!("true positives (IoU > 0.5):");
    for (&(a, b), &n) in &overlap {
        let iou = n as f64 / (psize[&a] + tsize[&b] - n) as f64;
        if iou > 0.5 {
            println!("  inst {a} obj {b} iou {iou:.2}");
        }
    }
    println!("map instances (>= 500 voxels):");
    for (id, n) in psize.iter() {
        let Some(i) = pinfo.get(id) else {
            println!("  inst {id} missing from instances()");
            continue;
        };
        let mut ov: Vec<(usize, u16)> = overlap
            .iter()
            .filter(|((a, _), _)| a == id)
            .map(|((_, b), n)| (*n, *b))
            .collect();
        ov.sort_by(|a, b| b.cmp(a));
        println!(
            "  inst {id:>4} thing {} {:?} {} voxels seen {} -> {:?}",
            i.is_thing,
            i.class_id.and_then(|c| names.name(c)),
            n,
            i.frames_seen,
            &ov[..ov.len().min(3)]
        );
    }
}
