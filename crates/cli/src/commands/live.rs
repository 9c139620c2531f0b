//! The live view's options (`run --live`, `--record`): Foxglove, through voxpan-view when
//! voxpan is built with the feature `live`.

use std::path::PathBuf;

use anyhow::Result;
use voxpan_map::PanopticMap;
use voxpan_perception::Perceived;

#[derive(clap::Args, Clone, Debug, Default)]
pub struct LiveArgs {
    /// Serve a live view for Foxglove (WebSocket) on HOST:PORT [default 127.0.0.1:8765]:
    /// colour with the refined masks, depth, camera pose and the growing mesh. Needs a voxpan
    /// built with `--features live`.
    #[arg(long, value_name = "HOST:PORT", num_args = 0..=1,
          default_missing_value = "127.0.0.1:8765")]
    pub live: Option<String>,
    /// Record the live view's topics into this MCAP file (Foxglove opens it); with or
    /// without --live. Needs a voxpan built with `--features live`.
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Send the changed mesh blocks every N frames (and at the end).
    #[arg(long, value_name = "N", default_value_t = 10)]
    pub live_mesh_every: usize,
}

/// A running live view, or none.
pub enum Live {
    Off,
    #[cfg(feature = "live")]
    On(Box<voxpan_view::LiveView>),
}

impl LiveArgs {
    fn wanted(&self) -> bool {
        self.live.is_some() || self.record.is_some()
    }

    /// Refuses a `--record` path that cannot be written, before any work: a folder, or a file
    /// in a folder that does not exist.
    pub fn check_record_path(&self) -> Result<()> {
        let Some(path) = &self.record else {
            return Ok(());
        };
        if path.is_dir() {
            anyhow::bail!(
                "--record {} is a folder: give the recording's file name (FILE.mcap)",
                path.display()
            );
        }
        let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(parent) = parent.filter(|p| !p.is_dir()) {
            anyhow::bail!(
                "--record {}: folder {} does not exist",
                path.display(),
                parent.display()
            );
        }
        Ok(())
    }

    /// Starts the view the options ask for (a server, a recording or both).
    pub fn start(&self) -> Result<Live> {
        if !self.wanted() {
            return Ok(Live::Off);
        }
        self.start_view()
    }

    #[cfg(feature = "live")]
    fn start_view(&self) -> Result<Live> {
        use anyhow::Context;
        let listen = match &self.live {
            Some(address) => Some(parse_address(address).context("--live")?),
            None => None,
        };
        let view = voxpan_view::LiveView::start(&voxpan_view::LiveOptions {
            listen,
            record: self.record.clone(),
            mesh_every: self.live_mesh_every,
            ..voxpan_view::LiveOptions::default()
        })?;
        if let Some(port) = view.port() {
            let host = self.live.as_deref().and_then(|a| a.rsplit_once(':'));
            eprintln!(
                "live view: open Foxglove and connect to ws://{}:{port}",
                host.map_or("127.0.0.1", |(h, _)| h)
            );
        }
        Ok(Live::On(Box::new(view)))
    }

    #[cfg(not(feature = "live"))]
    fn start_view(&self) -> Result<Live> {
        anyhow::bail!(
            "--live and --record need a voxpan built with the live view: \
             cargo build --release --features live"
        )
    }
}

impl Live {
    /// Shows a mapped frame.
    #[cfg_attr(not(feature = "live"), allow(unused_variables))]
    pub fn show(
        &mut self,
        perceived: &Perceived,
        map: &mut PanopticMap,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        match self {
            Live::Off => Ok(()),
            #[cfg(feature = "live")]
            Live::On(view) => {
                view.show(&perceived.frame, perceived.segments.as_ref(), map)?;
                Ok(())
            }
        }
    }

    /// Sends the final mesh and completes the recording.
    #[cfg_attr(not(feature = "live"), allow(unused_variables))]
    pub fn finish(self, map: &mut PanopticMap) -> Result<()> {
        match self {
            Live::Off => Ok(()),
            #[cfg(feature = "live")]
            Live::On(view) => {
                view.finish(map)?;
                Ok(())
            }
        }
    }
}

/// `HOST:PORT` (the host may be an IPv6 address in brackets).
#[cfg(feature = "live")]
fn parse_address(address: &str) -> Result<(String, u16)> {
    let (host, port) = address
        .rsplit_once(':')
        .ok_or_else(|| anyhow::anyhow!("{address:?} is not HOST:PORT"))?;
    let port: u16 = port
        .parse()
        .map_err(|_| anyhow::anyhow!("{address:?}: the port {port:?} is not a number 0-65535"))?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        anyhow::bail!("{address:?}: the host is empty");
    }
    Ok((host.to_string(), port))
}
