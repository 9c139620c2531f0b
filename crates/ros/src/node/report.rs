//! What a node did: frames in, done, dropped, unpaired, failed, and latency.

use voxpan_bag::assemble::Unpaired;

/// What a node did.
#[derive(Clone, Debug, Default)]
pub struct NodeReport {
    /// Frames that reached the node's worker (assembled or joined).
    pub frames_in: u64,
    /// Frames perceived (perception node) or integrated (mapping node).
    pub frames_done: u64,
    /// Frames with masks of their own among those done: perceived with the segmenter
    /// (perception node) or integrated with the perception node's masks rather than carried
    /// from the map (mapping node).
    pub keyframes: Option<u64>,
    /// Frames dropped because the worker was busy (the mailbox was full).
    pub dropped_busy: u64,
    /// Messages skipped because the node read them too slowly (subscription queues full).
    pub dropped_lagged: u64,
    /// Depth images that found no partner in time, with why.
    pub unpaired: Vec<Unpaired>,
    /// Messages that could not be decoded, with the first few reasons.
    pub bad_messages: u64,
    pub bad_examples: Vec<String>,
    /// Frames the worker failed on.
    pub failed: Vec<String>,
    /// Milliseconds from the perception node receiving a depth image to the frame being
    /// integrated (mapping node; same host clock) or perceived and sent (perception node).
    pub latency_ms: Vec<f64>,
    pub seconds: f64,
}

impl NodeReport {
    /// Frames per second done over the node's life.
    pub fn fps(&self) -> f64 {
        if self.seconds > 0.0 {
            self.frames_done as f64 / self.seconds
        } else {
            0.0
        }
    }

    /// Share of frames lost to back-pressure (busy or lagged) among those offered.
    pub fn drop_rate(&self) -> f64 {
        let lost = self.dropped_busy + self.dropped_lagged;
        let offered = self.frames_in + self.dropped_lagged;
        if offered == 0 {
            0.0
        } else {
            lost as f64 / offered as f64
        }
    }

    pub fn summary(&self) -> String {
        let mut lat = self.latency_ms.clone();
        lat.sort_by(f64::total_cmp);
        let pct = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
        let latency = if lat.is_empty() {
            "no latency (no frame done)".to_owned()
        } else {
            format!("latency median {:.1} ms, p95 {:.1} ms", pct(0.5), pct(0.95))
        };
        let segmented = self
            .keyframes
            .map_or(String::new(), |k| format!(", {k} segmented"));
        format!(
            "{} frames in, {} done{segmented} ({:.1} frames/s), dropped {} busy + {} lagged ({:.1} %), \
             {} unpaired, {} bad messages, {} failed; {latency}",
            self.frames_in,
            self.frames_done,
            self.fps(),
            self.dropped_busy,
            self.dropped_lagged,
            self.drop_rate() * 100.0,
            self.unpaired.len(),
            self.bad_messages,
            self.failed.len(),
        )
    }
}
