//! What a run leaves in its output folder: the map file, its meshes (by RGB, instance and
//! class; one per instance), the effective configuration and, on request, the refined masks.

use std::path::PathBuf;
use std::time::Instant;

use voxpan_map::{Coloring, MapError, PanopticMap};
use voxpan_perception::Perceived;

use crate::{Config, Mapped, RunFolder};

/// A file of the output folder that could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("cannot create {path}: {source}")]
    Folder {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    File(#[from] voxpan_io::IoError),
    #[error(transparent)]
    Map(#[from] MapError),
    #[error(
        "{path} is in use by another voxpan run ({holder}); wait for it, or choose another --out"
    )]
    Locked { path: PathBuf, holder: String },
    #[error("{path}: {needed} bytes are needed for the outputs but only {free} are free")]
    Space {
        path: PathBuf,
        needed: u64,
        free: u64,
    },
}

/// The steps of [`write_outputs`], for progress displays (`Display`: what a person reads).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputStep {
    Meshing,
    WritingMeshes,
    SavingMap,
}

impl std::fmt::Display for OutputStep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Meshing => "extracting the mesh",
            Self::WritingMeshes => "writing the meshes",
            Self::SavingMap => "saving the map",
        })
    }
}

/// Dropped blocks per file of `dropped/` while a run goes on (about 10 MB at 2 cm).
pub const DROPPED_BLOCKS_PER_FILE: usize = 1024;

/// Writes the dropped blocks the map keeps into the next `dropped/blocks-NNNNNN.voxpan` once
/// it keeps at least `at_least` (and one); returns the file's name.
pub fn write_dropped_blocks(
    folder: &mut RunFolder,
    map: &mut PanopticMap,
    at_least: usize,
) -> Result<Option<String>, OutputError> {
    if map.dropped_block_count() < at_least.max(1) {
        return Ok(None);
    }
    let written = folder
        .recorded()
        .filter(|f| f.starts_with("dropped/"))
        .count();
    let name = format!("dropped/blocks-{:06}.voxpan", written + 1);
    map.save_dropped_blocks(&folder.path(&name)?)?;
    folder.record(&name);
    Ok(Some(name))
}

/// What [`write_outputs`] wrote.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Outputs {
    /// Paths relative to the output folder.
    pub files: Vec<String>,
    pub triangles: usize,
    pub vertices: usize,
    /// Milliseconds of the final mesh extraction.
    pub mesh_ms: f64,
}

/// A name safe in a file name: letters, digits, `-` and `_` kept, anything else `_`.
fn file_safe(name: &str) -> String {
    let cleaned: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    cleaned.to_lowercase()
}

/// The file name of instance `id`'s mesh: `NNNN_<class name>.ply`, the class named by the
/// map's label table when it knows it, else by number (`class7`), else `unknown`.
pub fn instance_file_name(map: &PanopticMap, id: u16) -> String {
    let class = match map.class_of(id) {
        Some(c) => map
            .class_name(c)
            .map(file_safe)
            .unwrap_or_else(|| format!("class{c}")),
        None => "unknown".to_owned(),
    };
    format!("{id:04}_{class}.ply")
}

/// Writes `config.toml` (the effective configuration) into the run folder.
pub fn write_config(folder: &mut RunFolder, config: &Config) -> Result<(), OutputError> {
    let text = config.to_toml();
    voxpan_io::write_atomically(&folder.path("config.toml")?, |w| {
        w.write_all(text.as_bytes())
    })?;
    folder.record("config.toml");
    Ok(())
}

/// Writes a frame's refined label image as `refined/<frame id>.png`, and its segment list
/// beside it as `refined/<frame id>_labels.json` (the flat format: `voxpan eval --pred`
/// reads each id's kind from it).
pub fn write_refined(folder: &mut RunFolder, perceived: &Perceived) -> Result<(), OutputError> {
    if let Some(s) = &perceived.segments {
        let id = &perceived.frame.id;
        let image = format!("refined/{id}.png");
        voxpan_io::write_label_png(&folder.path(&image)?, &s.labels)?;
        folder.record(&image);
        let list = format!("refined/{id}_labels.json");
        let text = voxpan_io::segments_json(&s.segments);
        voxpan_io::write_atomically(&folder.path(&list)?, |w| w.write_all(text.as_bytes()))?;
        folder.record(&list);
    }
    Ok(())
}

/// Writes `costmap` as ROS map_server reads it: the PGM at `pgm` and, at `yaml`, its YAML
/// naming the PGM by file name (both written atomically).
pub fn write_costmap(
    costmap: &voxpan_map::Costmap,
    pgm: &std::path::Path,
    yaml: &std::path::Path,
) -> Result<(), voxpan_io::IoError> {
    let image = pgm
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let bytes = costmap.pgm();
    voxpan_io::write_atomically(pgm, |w| w.write_all(&bytes))?;
    let text = costmap.yaml(&image);
    voxpan_io::write_atomically(yaml, |w| w.write_all(text.as_bytes()))
}

/// Bytes of a binary PLY of `mesh` as [`voxpan_io::write_ply`] writes it (the header aside).
fn ply_bytes(mesh: &voxpan_core::Mesh) -> u64 {
    let vertex = 12
        + 12 * !mesh.normals.is_empty() as u64
        + 3 * !mesh.colors.is_empty() as u64
        + 2 * !mesh.instances.is_empty() as u64;
    mesh.vertices.len() as u64 * vertex + mesh.triangles.len() as u64 * 13 + 512
}

/// Writes the map and its meshes into the run folder: `map.voxpan`, `mesh_rgb.ply`,
/// `mesh_instance.ply`, `mesh_class.ply` and, when configured, `instances/NNNN_<class>.ply`.
/// Checks first that the disk can hold them all. Records the mesh time in the report.
/// `step` hears of each step as it begins.
pub fn write_outputs(
    folder: &mut RunFolder,
    mapped: &mut Mapped,
    config: &Config,
    mut step: impl FnMut(OutputStep),
) -> Result<Outputs, OutputError> {
    let map: &mut PanopticMap = &mut mapped.map;
    step(OutputStep::Meshing);
    let t = Instant::now();
    let mut mesh = map.mesh(Coloring::Rgb);
    let mesh_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut outputs = Outputs {
        triangles: mesh.triangles.len(),
        vertices: mesh.vertices.len(),
        mesh_ms,
        ..Outputs::default()
    };
    // Three coloured meshes, the instance meshes (together about one more) and the map.
    let needed = 4 * ply_bytes(&mesh) + map.file_size_estimate();
    folder.check_space(needed + needed / 10)?;
    step(OutputStep::WritingMeshes);
    let mut write = |folder: &mut RunFolder, name: String, m: &voxpan_core::Mesh| {
        voxpan_io::write_ply(&folder.path(&name)?, m, "voxpan TSDF mesh")?;
        folder.record(&name);
        outputs.files.push(name);
        Ok::<_, OutputError>(())
    };
    write(folder, "mesh_rgb.ply".into(), &mesh)?;
    if config.output.instance_meshes {
        for (id, part) in mesh.split_by_instance() {
            write(
                folder,
                format!("instances/{}", instance_file_name(map, id)),
                &part,
            )?;
        }
    }
    // Recoloured in place: one mesh in memory, not one per colouring.
    for (name, coloring) in [
        ("mesh_instance.ply", Coloring::Instance),
        ("mesh_class.ply", Coloring::Class),
    ] {
        map.recolor(&mut mesh, coloring);
        write(folder, name.into(), &mesh)?;
    }
    drop(mesh);
    if config.output.dropped_blocks {
        outputs.files.extend(write_dropped_blocks(folder, map, 1)?);
    }
    if config.esdf.enabled {
        map.update_esdf();
        if let Some(costmap) = map.costmap() {
            let (pgm, yaml) = (folder.path("costmap.pgm")?, folder.path("costmap.yaml")?);
            write_costmap(&costmap, &pgm, &yaml)?;
            for name in ["costmap.pgm", "costmap.yaml"] {
                folder.record(name);
                outputs.files.push(name.into());
            }
        }
    }
    step(OutputStep::SavingMap);
    map.save(&folder.path("map.voxpan")?)?;
    folder.record("map.voxpan");
    outputs.files.push("map.voxpan".into());
    mapped.report.triangles = outputs.triangles;
    mapped.report.stage_ms.insert("mesh".into(), mesh_ms);
    Ok(outputs)
}
