//! `voxpan node perceive|map|both`: the ROS nodes, through voxpan-ros when voxpan is built
//! with the feature `ros1` (ROS 1) or `ros2` (ROS 1 and, with `--ros2`, ROS 2 over rmw_zenoh's
//! wire format).

use std::path::PathBuf;

use anyhow::Result;

use super::bag::BagArgs;
use super::network::NetworkArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    role: Role,
}

#[derive(clap::Subcommand)]
enum Role {
    /// Camera topics in; fill, segment, refine; depth, refined masks, colour, camera_info and
    /// pose out under --prefix, stamped like the depth image.
    Perceive(PerceiveArgs),
    /// The perception node's topics in; integrate; the mesh's changed blocks out as an RViz
    /// MarkerArray; the map saved when stopped (Ctrl-C / SIGINT) and, on ROS 1, on each call
    /// of the std_srvs/Trigger service PREFIX/save_map.
    Map(MapArgs),
    /// Both in one process (no ROS between them): camera topics in, mesh out, map saved when
    /// stopped and (ROS 1) on each call of PREFIX/save_map.
    Both(BothArgs),
}

#[derive(clap::Args)]
struct Common {
    /// The ROS master [default: $ROS_MASTER_URI, else http://127.0.0.1:11311]. The address
    /// this node gives its peers comes from $ROS_IP or $ROS_HOSTNAME.
    #[arg(long, value_name = "URI", conflicts_with = "ros2")]
    master: Option<String>,
    /// Speak ROS 2 instead of ROS 1: rmw_zenoh's wire format over zenoh, as ROS 2 nodes
    /// running rmw_zenoh_cpp do (needs a voxpan built with --features ros2).
    #[arg(long)]
    ros2: bool,
    /// ROS 2: zenoh endpoint to connect to, the router (rmw_zenohd); repeatable
    /// [default: tcp/localhost:7447, as rmw_zenoh].
    #[arg(long, value_name = "ENDPOINT", requires = "ros2")]
    zenoh_connect: Vec<String>,
    /// ROS 2: endpoint this node listens on for its peers; repeatable
    /// [default: tcp/localhost:0, as rmw_zenoh; another host's peers need e.g. tcp/0.0.0.0:0].
    #[arg(long, value_name = "ENDPOINT", requires = "ros2")]
    zenoh_listen: Vec<String>,
    /// ROS 2: the domain [default: $ROS_DOMAIN_ID, else 0].
    #[arg(long, value_name = "ID", requires = "ros2")]
    domain: Option<u32>,
    /// Node name [default: /voxpan_perceive, /voxpan_map or /voxpan].
    #[arg(long)]
    name: Option<String>,
    /// Configuration file (TOML, as for `voxpan run`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Mask refinement rule: none, paper, release or default [refine.rule].
    #[arg(long)]
    refine: Option<voxpan_refine::Rule>,
    /// Topic prefix of the perception node's outputs (the mapping node's inputs).
    #[arg(long, default_value = "/voxpan")]
    prefix: String,
    /// Frames waiting for the node's worker; when it falls behind, the oldest is dropped
    /// (counted). 1 keeps latency lowest; more absorbs bursts.
    #[arg(long, default_value_t = 2)]
    queue: usize,
    /// Messages each subscription buffers before skipping (counted as lagged).
    #[arg(long, default_value_t = 16)]
    subscriber_queue: usize,
}

#[derive(clap::Args)]
struct PerceiveOnly {
    /// Segment only keyframes: every Nth frame, or "auto" (when the view has moved on from the
    /// last keyframe's). The frames between go to the mapping node with their depth as
    /// measured and no masks; it renders the map's masks at their pose, refines them on that
    /// depth and fills it, with this node's [refine] and [fill] [segment.every, default 1].
    #[arg(long, value_name = "N|auto")]
    segment_every: Option<voxpan_perception::Keyframes>,
    #[command(flatten)]
    topics: BagArgs,
    #[command(flatten)]
    network: NetworkArgs,
}

#[derive(clap::Args)]
struct MapOnly {
    /// Save the map here when the node stops, and (ROS 1) when the service PREFIX/save_map
    /// (std_srvs/Trigger) is called.
    #[arg(long, value_name = "FILE.voxpan")]
    save: Option<PathBuf>,
    /// visualization_msgs/MarkerArray topic of the mesh [default: PREFIX/mesh].
    #[arg(long)]
    mesh_topic: Option<String>,
    /// Publish the changed mesh blocks every N integrated frames (and at the end); 0: never.
    #[arg(long, value_name = "N", default_value_t = 10)]
    mesh_every: usize,
    /// Mesh colours: rgb, instance or class.
    #[arg(long, default_value = "rgb")]
    coloring: String,
    /// nav_msgs/OccupancyGrid topic of the costmap [default: PREFIX/costmap].
    #[arg(long)]
    costmap_topic: Option<String>,
    /// sensor_msgs/PointCloud2 topic of the costmap's clearance (a `distance` per known cell),
    /// published with the costmap [default: PREFIX/esdf_slice].
    #[arg(long)]
    esdf_slice_topic: Option<String>,
    /// Update the distance field and publish the costmap every N integrated frames (and at
    /// the end); 0: never [default: 10 with `[esdf] enabled` in the configuration, else 0].
    /// Turns `[esdf] enabled` on: the costmap's free space needs it.
    #[arg(long, value_name = "N")]
    costmap_every: Option<usize>,
    /// Consolidate the live map (pieces of one object joined, label holes filled) every N
    /// integrated frames, so that its meshes and costmaps read about as a finished map would;
    /// 0: only when the map is saved [default: `[tracking] consolidate_every` where the
    /// configuration sets it, else 30].
    #[arg(long, value_name = "N")]
    consolidate_every: Option<u32>,
}

/// A mapping node's consolidation period when neither `--consolidate-every` nor the
/// configuration says: a node's map is read live, and on the synthetic three rooms one
/// consolidated every 30 frames reads 51.4 voxel PQ at worst between passes against 42.3
/// without passes, and the map saved at the end loses nothing by them (docs/ros.md).
#[cfg(any(feature = "ros1", test))]
const NODE_CONSOLIDATE_EVERY: u32 = 30;

/// How often a mapping node consolidates its live map: `flag` (`--consolidate-every`), else
/// `[tracking] consolidate_every` where the configuration file's text `file` sets it, else
/// [`NODE_CONSOLIDATE_EVERY`].
#[cfg(any(feature = "ros1", test))]
fn node_consolidate_every(flag: Option<u32>, file: Option<&str>) -> u32 {
    let from_file = file
        .and_then(|text| text.parse::<toml::Table>().ok())
        .and_then(|table| {
            table
                .get("tracking")?
                .get("consolidate_every")?
                .as_integer()
        })
        .and_then(|n| u32::try_from(n).ok());
    flag.or(from_file).unwrap_or(NODE_CONSOLIDATE_EVERY)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flag_wins_then_the_file_then_the_nodes_default() {
        let sets = "[tracking]\nconsolidate_every = 0\n";
        let silent = "[tracking]\nmin_voxels = 8\n[esdf]\nenabled = true\n";
        assert_eq!(node_consolidate_every(Some(5), Some(sets)), 5);
        assert_eq!(node_consolidate_every(None, Some(sets)), 0);
        assert_eq!(
            node_consolidate_every(None, Some(silent)),
            NODE_CONSOLIDATE_EVERY
        );
        assert_eq!(node_consolidate_every(None, None), NODE_CONSOLIDATE_EVERY);
    }
}

#[derive(clap::Args)]
struct PerceiveArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    perceive: PerceiveOnly,
}

#[derive(clap::Args)]
struct MapArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    map: MapOnly,
}

#[derive(clap::Args)]
struct BothArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    perceive: PerceiveOnly,
    #[command(flatten)]
    map: MapOnly,
}

pub fn run(args: Args) -> Result<()> {
    imp::run(args)
}

#[cfg(not(feature = "ros1"))]
mod imp {
    pub fn run(_: super::Args) -> anyhow::Result<()> {
        anyhow::bail!(
            "voxpan node needs a voxpan built with ROS 1 support: cargo build --release \
             --features ros1"
        )
    }
}

#[cfg(feature = "ros1")]
mod imp {
    use std::collections::BTreeMap;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    use anyhow::{Context, Result, bail};
    use voxpan_map::{Coloring, PanopticMap};
    use voxpan_perception::{DatasetMasks, Perception, Segmenter};
    use voxpan_pipeline::Config;
    use voxpan_ros::{
        Connection, MapOptions, Middleware, NodeReport, Outputs, PerceiveOptions, Ros2Options,
    };

    use super::*;

    /// The node's configuration, and the text of the `--config` file when one is named (read
    /// once: the mapping node also reads which keys it sets, see [`map_config`]).
    fn config(common: &Common) -> Result<(Config, Option<String>)> {
        let text = common
            .config
            .as_ref()
            .map(|path| {
                std::fs::read_to_string(path)
                    .with_context(|| format!("--config {}", path.display()))
            })
            .transpose()?;
        let mut config = match common.config.as_deref().zip(text.as_deref()) {
            Some((path, text)) => Config::from_toml_text(text, path)?,
            None => Config::default(),
        };
        if let Some(r) = common.refine {
            config.refine.rule = r;
        }
        config
            .validate()
            .map_err(|e| anyhow::anyhow!("invalid option: {e}"))?;
        Ok((config, text))
    }

    fn middleware(common: &Common) -> Result<Middleware> {
        if !common.ros2 {
            let master_uri = common.master.clone().unwrap_or_else(|| {
                std::env::var("ROS_MASTER_URI").unwrap_or_else(|_| "http://127.0.0.1:11311".into())
            });
            return Ok(Middleware::Ros1 { master_uri });
        }
        if !cfg!(feature = "ros2") {
            bail!(
                "--ros2 needs a voxpan built with ROS 2 support: cargo build --release \
                 --features ros2"
            );
        }
        let mut options = Ros2Options::default();
        if !common.zenoh_connect.is_empty() {
            options.connect = common.zenoh_connect.clone();
        }
        if !common.zenoh_listen.is_empty() {
            options.listen = common.zenoh_listen.clone();
        }
        options.domain = match (common.domain, std::env::var("ROS_DOMAIN_ID")) {
            (Some(d), _) => d,
            (None, Ok(text)) if !text.trim().is_empty() => text
                .trim()
                .parse()
                .with_context(|| format!("ROS_DOMAIN_ID={text:?} is not a domain number"))?,
            _ => 0,
        };
        options.check().map_err(|e| anyhow::anyhow!(e))?;
        Ok(Middleware::Ros2(options))
    }

    fn connection(common: &Common, default_name: &str) -> Result<Connection> {
        Ok(Connection {
            middleware: middleware(common)?,
            node_name: common.name.clone().unwrap_or_else(|| default_name.into()),
            subscriber_queue: common.subscriber_queue.max(1),
        })
    }

    fn stop_on_ctrl_c() -> Arc<AtomicBool> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        // Failing to install the handler only loses the clean stop (and the map's save).
        let _ = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed));
        stop
    }

    fn log(role: &'static str) -> voxpan_ros::node::Log {
        Arc::new(move |line: &str| eprintln!("[{role}] {line}"))
    }

    /// The segmenter (the network, masks from the label topics, or none), whether its masks
    /// come from topics, and the names of its class ids (the network's label table, else
    /// `--classes`).
    fn perception(
        p: &PerceiveOnly,
        config: &Config,
    ) -> Result<(Perception, bool, BTreeMap<u32, String>)> {
        let bag = p.topics.options();
        let (segmenter, from_topics): (Box<dyn Segmenter>, bool) = match p.network.open()? {
            Some(network) => (Box::new(network), false),
            // Masks from topics ride on the frame, as a bag's or a dataset's do.
            None => (Box::new(DatasetMasks), bag.require_labels),
        };
        let names = match (segmenter.classes(), &bag.classes) {
            (Some(table), _) => table.names(),
            (None, Some(csv)) => voxpan_io::read_class_csv(csv)
                .with_context(|| format!("--classes {}", csv.display()))?
                .names(),
            (None, None) => BTreeMap::new(),
        };
        let mut settings = config.perception();
        if let Some(every) = p.segment_every {
            settings.keyframes = every;
        }
        if settings.own_thread {
            eprintln!(
                "warning: [segment] own_thread is ignored by the ROS nodes: their perception \
                 thread runs the segmenter on keyframes and waits for it"
            );
        }
        Ok((Perception::new(settings, segmenter)?, from_topics, names))
    }

    fn perceive_options(
        common: &Common,
        p: &PerceiveOnly,
        masks: bool,
        class_names: BTreeMap<u32, String>,
        name: &str,
    ) -> Result<PerceiveOptions> {
        Ok(PerceiveOptions {
            connection: connection(common, name)?,
            inputs: p.topics.options(),
            masks_from_topics: masks,
            outputs: Outputs {
                prefix: common.prefix.clone(),
            },
            queue: common.queue,
            class_names,
        })
    }

    /// How often the costmap is published: `--costmap-every`, else every 10 frames where the
    /// configuration keeps the distance field.
    fn costmap_every(config: &Config, m: &MapOnly) -> usize {
        m.costmap_every
            .unwrap_or(if config.esdf.enabled { 10 } else { 0 })
    }

    fn map_options(
        common: &Common,
        m: &MapOnly,
        config: &Config,
        name: &str,
    ) -> Result<MapOptions> {
        let coloring = match m.coloring.as_str() {
            "rgb" => Coloring::Rgb,
            "instance" => Coloring::Instance,
            "class" => Coloring::Class,
            other => bail!("--coloring {other}: expected rgb, instance or class"),
        };
        let outputs = Outputs {
            prefix: common.prefix.clone(),
        };
        let costmap_topic = m
            .costmap_topic
            .clone()
            .unwrap_or_else(|| outputs.topic("costmap"));
        let esdf_slice_topic = m
            .esdf_slice_topic
            .clone()
            .unwrap_or_else(|| outputs.topic("esdf_slice"));
        Ok(MapOptions {
            connection: connection(common, name)?,
            mesh_topic: m
                .mesh_topic
                .clone()
                .unwrap_or_else(|| outputs.topic("mesh")),
            inputs: outputs,
            mesh_every: m.mesh_every,
            coloring,
            costmap_topic,
            esdf_slice_topic,
            costmap_every: costmap_every(config, m),
            queue: common.queue,
            save: m.save.clone(),
        })
    }

    /// The node's configuration (see [`config`]) with the mapping node's consolidation period
    /// (see [`node_consolidate_every`]).
    fn map_config(common: &Common, m: &MapOnly) -> Result<Config> {
        let (mut config, text) = config(common)?;
        config.tracking.consolidate_every =
            node_consolidate_every(m.consolidate_every, text.as_deref());
        Ok(config)
    }

    fn new_map(config: &Config, m: &MapOnly) -> Result<PanopticMap> {
        if let Some(path) = &m.save {
            // Refused now rather than after an hour of mapping.
            let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
            if let Some(dir) = dir
                && !dir.is_dir()
            {
                bail!(
                    "--save {}: folder {} does not exist",
                    path.display(),
                    dir.display()
                );
            }
            if path.is_dir() {
                bail!(
                    "--save {} is a folder: give the map's file name (FILE.voxpan)",
                    path.display()
                );
            }
            // Written once now: a folder the node may not write into is found at start.
            let probe = path.with_file_name(format!(
                ".{}.probe-{}",
                path.file_name().unwrap_or_default().to_string_lossy(),
                std::process::id()
            ));
            std::fs::write(&probe, b"")
                .and_then(|()| std::fs::remove_file(&probe))
                .with_context(|| format!("--save {}: cannot write there", path.display()))?;
        }
        let mut map_config = config.map();
        map_config.esdf.enabled |= costmap_every(config, m) > 0;
        let mut map = PanopticMap::new(map_config)?;
        map.set_memory_limit(config.resources.max_memory_bytes());
        Ok(map)
    }

    fn print(report: &NodeReport) {
        eprintln!("{}", report.summary());
        for e in &report.bad_examples {
            eprintln!("  bad message: {e}");
        }
    }

    pub fn run(args: Args) -> Result<()> {
        // The middleware's options are checked before a network or map is loaded.
        let common = match &args.role {
            Role::Perceive(a) => &a.common,
            Role::Map(a) => &a.common,
            Role::Both(a) => &a.common,
        };
        middleware(common)?;
        match args.role {
            Role::Perceive(a) => {
                let (config, _) = config(&a.common)?;
                let (perception, masks, names) = perception(&a.perceive, &config)?;
                let options =
                    perceive_options(&a.common, &a.perceive, masks, names, "/voxpan_perceive")?;
                let report = voxpan_ros::run_perceive(
                    &options,
                    perception,
                    stop_on_ctrl_c(),
                    log("perceive"),
                )
                .context("perception node")?;
                print(&report);
            }
            Role::Map(a) => {
                let config = map_config(&a.common, &a.map)?;
                let map = new_map(&config, &a.map)?;
                let options = map_options(&a.common, &a.map, &config, "/voxpan_map")?;
                let (_, report) = voxpan_ros::run_map(&options, map, stop_on_ctrl_c(), log("map"))
                    .context("mapping node")?;
                print(&report);
            }
            Role::Both(a) => {
                let config = map_config(&a.common, &a.map)?;
                let (perception, masks, names) = perception(&a.perceive, &config)?;
                let mut map = new_map(&config, &a.map)?;
                map.set_class_names(names.clone());
                let p = perceive_options(&a.common, &a.perceive, masks, names, "/voxpan")?;
                let m = map_options(&a.common, &a.map, &config, "/voxpan")?;
                let (_, report) =
                    voxpan_ros::run_both(&p, &m, perception, map, stop_on_ctrl_c(), log("voxpan"))
                        .context("voxpan node")?;
                print(&report);
            }
        }
        Ok(())
    }
}
