use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use voxpan_core::{ClassInfo, ClassTable, Frame, Intrinsics, Pose, Segments};
use voxpan_dataset::DatasetError;
use voxpan_dataset::flat::{write_frame, write_intrinsics, write_timestamps};
use voxpan_io::{write_class_csv, write_ply};

use crate::masks::{SequenceFrame, TrueView};
use crate::{MaskErrors, Rand, Scene, SensorModel, render, scene_mesh, trajectory};

/// Which world to build.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum World {
    /// One furnished room ([`Scene::generate`]).
    #[default]
    Room,
    /// Three rooms joined by doorways, with rugs, doors and books ([`Scene::flat`]).
    Flat,
}

impl World {
    /// The scene of this world for `seed`.
    pub fn scene(self, seed: u64) -> Scene {
        match self {
            World::Room => Scene::generate(seed),
            World::Flat => Scene::flat(seed),
        }
    }
}

/// What to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SynthConfig {
    pub world: World,
    pub frames: usize,
    pub width: usize,
    pub height: usize,
    pub seed: u64,
    /// Seeds the network's masks alone (`None`: `seed` does): the same room, trajectory and
    /// depth with another draw of the mask errors, to tell what association does from which
    /// errors one draw happened to make.
    pub mask_seed: Option<u64>,
    pub sensor: SensorModel,
    pub masks: MaskErrors,
    /// Camera rate, for timestamps.
    pub fps: f64,
}

impl Default for SynthConfig {
    /// 200 frames of 640×480 at 30 Hz, RealSense-like sensor, CNN-like masks (strength 1).
    fn default() -> Self {
        Self {
            world: World::Room,
            frames: 200,
            width: 640,
            height: 480,
            seed: 1,
            mask_seed: None,
            sensor: SensorModel::default(),
            masks: MaskErrors::new(1.0),
            fps: 30.0,
        }
    }
}

impl SynthConfig {
    /// 20 frames of 160×120: for tests.
    pub fn tiny() -> Self {
        Self {
            frames: 20,
            width: 160,
            height: 120,
            ..Self::default()
        }
    }

    /// A 90° horizontal field of view, principal point at the image centre.
    pub fn intrinsics(&self) -> Intrinsics {
        let f = self.width as f64 / 2.0;
        Intrinsics {
            width: self.width,
            height: self.height,
            fx: f,
            fy: f,
            cx: self.width as f64 / 2.0,
            cy: self.height as f64 / 2.0,
        }
    }
}

/// What [`generate`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthSummary {
    pub frames: usize,
    pub objects: usize,
    pub mesh_triangles: usize,
}

/// Salt of the masks' own stream when [`SynthConfig::mask_seed`] is given.
const MASK_DRAW: u64 = 0x3a5c_d7a1;

/// One frame: ideal render, then the sensor, then the network's masks (each from the frame's
/// own random stream, so frames are independent and reproducible).
pub fn synth_frame(scene: &Scene, config: &SynthConfig, index: usize, pose: &Pose) -> Frame {
    let k = config.intrinsics();
    let view = render(scene, pose, &k);
    let mut rng = Rand::stream(config.seed, index as u64);
    let depth = config
        .sensor
        .measure(&view.depth, &view.color, &view.instances, scene, &mut rng);
    // Without a mask seed the masks continue the sensor's stream, as sequences written before
    // the option had them.
    let (mask_seed, mut mask_rng) = match config.mask_seed {
        None => (config.seed, rng),
        Some(seed) => (seed, Rand::stream(seed ^ MASK_DRAW, index as u64)),
    };
    let truth = TrueView {
        instances: &view.instances,
        parts: Some(&view.parts),
        depth: &view.depth,
    };
    let sequence = SequenceFrame {
        seed: mask_seed,
        index,
        pose,
        intrinsics: &k,
    };
    let (labels, segments, _) =
        config
            .masks
            .predict_in_sequence(truth, scene, &mut mask_rng, Some(sequence));
    Frame {
        id: format!("{index:06}"),
        timestamp: index as f64 / config.fps,
        color: view.color,
        depth,
        segments: Some(Segments { labels, segments }),
        ground_truth: Some(view.instances),
        pose: *pose,
        intrinsics: k,
    }
}

/// Writes a synthetic sequence in the flat format into `out` (with `run1/`), plus
/// `groundtruth_mesh.ply`. `progress` is called once per finished frame.
pub fn generate(
    out: &Path,
    config: &SynthConfig,
    progress: impl Fn(usize) + Sync,
) -> Result<SynthSummary, DatasetError> {
    let run = out.join("run1");
    std::fs::create_dir_all(&run).map_err(|e| DatasetError::Invalid {
        path: run.clone(),
        message: e.to_string(),
    })?;
    let scene = config.world.scene(config.seed);
    let poses = trajectory(&scene, config.frames);
    write_metadata(out, config, &scene)?;
    let done = AtomicUsize::new(0);
    poses.par_iter().enumerate().try_for_each(|(i, pose)| {
        write_frame(&run, &synth_frame(&scene, config, i, pose))?;
        progress(done.fetch_add(1, Ordering::Relaxed) + 1);
        Ok::<_, DatasetError>(())
    })?;
    let stamps: Vec<(String, f64)> = (0..config.frames)
        .map(|i| (format!("{i:06}"), i as f64 / config.fps))
        .collect();
    write_timestamps(&run, &stamps)?;
    let mesh = scene_mesh(&scene);
    let mesh_path = out.join("groundtruth_mesh.ply");
    write_ply(&mesh_path, &mesh, "voxpan synthetic ground truth")?;
    Ok(SynthSummary {
        frames: config.frames,
        objects: scene.objects.len(),
        mesh_triangles: mesh.triangles.len(),
    })
}

fn write_metadata(out: &Path, config: &SynthConfig, scene: &Scene) -> Result<(), DatasetError> {
    write_intrinsics(out, &config.intrinsics())?;
    let name_of = |class: u32| {
        Scene::classes()
            .iter()
            .find(|c| c.0 == class)
            .map_or("unknown", |c| c.1)
    };
    let ground_truth = ClassTable {
        entries: scene
            .objects
            .iter()
            .map(|o| {
                (
                    o.instance_id as u32,
                    ClassInfo {
                        class_id: o.class_id,
                        is_thing: o.is_thing,
                        name: name_of(o.class_id).to_owned(),
                        color: o.color,
                    },
                )
            })
            .collect(),
    };
    write_class_csv(&ground_truth, &out.join("groundtruth_labels.csv"))?;
    let network = ClassTable {
        entries: Scene::classes()
            .iter()
            .map(|&(id, name, thing)| {
                (
                    id,
                    ClassInfo {
                        class_id: id,
                        is_thing: thing,
                        name: name.to_owned(),
                        color: [0, 0, 0],
                    },
                )
            })
            .collect(),
    };
    write_class_csv(&network, &out.join("detectron_labels.csv"))?;
    let classes: String = std::iter::once("ClassID,Name\n".to_owned())
        .chain(
            Scene::classes()
                .iter()
                .map(|(id, name, _)| format!("{id},{name}\n")),
        )
        .collect();
    let path = out.join("groundtruth_labels_classes.csv");
    std::fs::write(&path, classes).map_err(|e| DatasetError::Invalid {
        path,
        message: e.to_string(),
    })
}
