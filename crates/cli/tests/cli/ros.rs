//! `voxpan node`: the ROS 1 nodes against Debian's own ROS 1 (a real rosmaster, `rosbag play`
//! of a bag written by PyPI rosbags, `rostopic echo` as a peer), and (feature `ros2`) the ROS 2
//! nodes against an independent rmw_zenoh peer (tools/ros/ros2_peer.py: PyPI eclipse-zenoh as
//! router, bag player and echo; rosbags for type hashes and CDR). The mapping node's map must
//! equal `voxpan run` on the same bag. Without the feature `ros1`, the command says how to
//! build it.

#[cfg(not(feature = "ros1"))]
#[test]
fn without_the_feature_the_node_command_says_how_to_build_it() {
    let o = crate::common::voxpan(["node", "map"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("--features ros1"), "{err}");
}

#[cfg(feature = "ros1")]
mod live {
    use std::io::{BufRead, BufReader};
    use std::path::{Path, PathBuf};
    use std::process::{Child, Command, Stdio};
    use std::sync::{Arc, Mutex};
    use std::time::{Duration, Instant};

    use crate::common::voxpan_ok;
    use voxpan_map::PanopticMap;

    mod rviz;

    /// A child process killed (SIGKILL) if the test leaves early; its stderr lines collected.
    struct Proc {
        name: String,
        child: Child,
        lines: Arc<Mutex<Vec<String>>>,
    }

    impl Proc {
        fn spawn(name: &str, mut command: Command) -> Proc {
            command.stdout(Stdio::piped()).stderr(Stdio::piped());
            let mut child = command
                .spawn()
                .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
            let lines = Arc::new(Mutex::new(Vec::new()));
            for stream in [
                Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
                Box::new(child.stderr.take().unwrap()),
            ] {
                let lines = lines.clone();
                std::thread::spawn(move || {
                    for line in BufReader::new(stream).lines().map_while(Result::ok) {
                        lines.lock().unwrap().push(line);
                    }
                });
            }
            Proc {
                name: name.into(),
                child,
                lines,
            }
        }

        fn text(&self) -> String {
            self.lines.lock().unwrap().join("\n")
        }

        fn count(&self, needle: &str) -> usize {
            self.lines
                .lock()
                .unwrap()
                .iter()
                .filter(|l| l.contains(needle))
                .count()
        }

        /// SIGINT, then waits (at most `limit`) for a clean exit.
        fn interrupt(&mut self, limit: Duration) -> std::process::ExitStatus {
            // SAFETY: kill only sends a signal to our own child.
            unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
            self.wait(limit)
        }

        fn running(&mut self) -> bool {
            self.child.try_wait().unwrap().is_none()
        }

        fn wait(&mut self, limit: Duration) -> std::process::ExitStatus {
            let start = Instant::now();
            loop {
                if let Some(status) = self.child.try_wait().unwrap() {
                    // Let the reader threads take the last lines.
                    std::thread::sleep(Duration::from_millis(100));
                    return status;
                }
                if start.elapsed() > limit {
                    panic!(
                        "{} did not exit within {limit:?}:\n{}",
                        self.name,
                        self.text()
                    );
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
    }

    impl Drop for Proc {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    fn until(limit: Duration, what: &str, mut done: impl FnMut() -> bool) {
        let start = Instant::now();
        while !done() {
            assert!(start.elapsed() < limit, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Waits (at most a minute) until the map node has integrated `frames` frames; on timeout
    /// the message carries every process's output.
    fn until_integrated(frames: usize, map_node: &Proc, others: &[&Proc]) {
        let start = Instant::now();
        while map_node.count("integrated frame") < frames {
            if start.elapsed() > Duration::from_secs(60) {
                let mut text = format!("map:\n{}", map_node.text());
                for p in others {
                    text += &format!("\n{}:\n{}", p.name, p.text());
                }
                panic!("timed out waiting for {frames} integrated frames\n{text}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// The map a node saved at `saved` equals `voxpan run BAG`'s (and has instances); returns it.
    /// `[esdf] enabled`, written into `dir`: the map node's configuration and `voxpan run`'s.
    fn esdf_config(dir: &Path) -> PathBuf {
        let path = dir.join("esdf.toml");
        std::fs::write(&path, "[esdf]\nenabled = true\n").unwrap();
        path
    }

    fn assert_live_map_is_voxpan_runs(saved: &Path, bag: &Path, dir: &Path) -> PanopticMap {
        assert_live_map_equals(saved, &voxpan_run_map(bag, dir))
    }

    /// `voxpan run BAG`'s map, with the nodes' configuration (`[esdf] enabled`) and classes,
    /// made in `dir/offline`.
    fn voxpan_run_map(bag: &Path, dir: &Path) -> PanopticMap {
        voxpan_run_map_with(bag, dir, "offline", &[])
    }

    /// [`voxpan_run_map`] with `extra` options, made in `dir/out`.
    fn voxpan_run_map_with(bag: &Path, dir: &Path, out: &str, extra: &[&str]) -> PanopticMap {
        // The nodes' configuration file leaves `consolidate_every` to the mapping node, which
        // consolidates every 30 frames by default; `voxpan run` consolidates only at the end
        // unless told. Told here, so that a node that did not default to 30 maps differently.
        voxpan_run_map_configured(bag, dir, out, 30, extra)
    }

    /// [`voxpan_run_map_with`] consolidating every `consolidate_every` frames.
    fn voxpan_run_map_configured(
        bag: &Path,
        dir: &Path,
        out: &str,
        consolidate_every: u32,
        extra: &[&str],
    ) -> PanopticMap {
        let config = dir.join(format!("{out}.toml"));
        std::fs::write(
            &config,
            format!(
                "[esdf]\nenabled = true\n[tracking]\nconsolidate_every = {consolidate_every}\n"
            ),
        )
        .unwrap();
        let classes = classes_csv(dir);
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "run".as_ref(),
            bag.as_os_str(),
            "--config".as_ref(),
            config.as_os_str(),
            "--classes".as_ref(),
            classes.as_os_str(),
        ];
        let out = dir.join(out);
        args.extend(["--out".as_ref(), out.as_os_str()]);
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        voxpan_ok(args);
        PanopticMap::load(&out.join("map.voxpan")).unwrap()
    }

    /// The map a node saved at `saved` equals `offline` (and has named instances); returns it.
    fn assert_live_map_equals(saved: &Path, offline: &PanopticMap) -> PanopticMap {
        let live = PanopticMap::load(saved).unwrap();
        assert!(live.instances().len() > 1);
        // The class names travelled from the perception node with the segment lists.
        assert!(
            live.instances().iter().all(|i| i.class_name.is_some()),
            "{:?}",
            live.instances()
        );
        assert!(live == *offline, "the live map differs from voxpan run's");
        live
    }

    /// The synthetic world's label table (its network's classes), written with the bags.
    fn classes_csv(dir: &Path) -> PathBuf {
        dir.join("synth/detectron_labels.csv")
    }

    /// target/ros-venv's Python (tools/ros/setup.sh).
    fn ros_venv_python() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/ros-venv/bin/python")
    }

    /// Those of `programs` not on `PATH`.
    fn missing_programs<'a>(programs: &[&'a str]) -> Vec<&'a str> {
        programs
            .iter()
            .copied()
            .filter(|t| {
                !Command::new("sh")
                    .args(["-c", &format!("command -v {t}")])
                    .output()
                    .is_ok_and(|o| o.status.success())
            })
            .collect()
    }

    /// Debian's ROS 1 tools and the rosbags venv; `None` (skipped) only with
    /// VOXPAN_ALLOW_MISSING_DATA=1.
    fn tools(test: &str) -> Option<PathBuf> {
        let venv = ros_venv_python();
        let missing = missing_programs(&["rosmaster", "rosbag", "rostopic", "rosservice"]);
        if missing.is_empty() && venv.is_file() {
            return Some(venv);
        }
        if voxpan_test_support::missing_data_allowed() {
            eprintln!(
                "SKIPPED {test}: missing {missing:?} or target/ros-venv (tools/ros/setup.sh)"
            );
            return None;
        }
        panic!(
            "{test}: missing {missing:?} or target/ros-venv: run tools/ros/setup.sh (as root) \
             or set VOXPAN_ALLOW_MISSING_DATA=1"
        );
    }

    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    }

    /// Where the test's ROS processes run: all on this machine's loopback, or on two hosts
    /// made of network namespaces joined by a veth pair (tools/ros/netns.sh): the master, the
    /// mapping node and the peers on host a; the camera (rosbag play) and the perception node
    /// on host b, so perception -> mapping traffic crosses the link.
    #[derive(Clone, Copy, PartialEq)]
    enum Layout {
        Loopback,
        TwoHosts,
    }

    #[derive(Clone, Copy)]
    enum Host {
        A,
        B,
    }

    struct Net {
        layout: Layout,
        port: u16,
        /// VOXPAN_NETNS_A/B/NET for netns.sh.
        env: Vec<(String, String)>,
        master: String,
    }

    impl Net {
        fn new(layout: Layout) -> Net {
            let port = free_port();
            match layout {
                Layout::Loopback => Net {
                    layout,
                    port,
                    env: Vec::new(),
                    master: format!("http://127.0.0.1:{port}"),
                },
                Layout::TwoHosts => {
                    // Names and subnet unique to this test run (tests run in parallel).
                    let id = port % 200 + 20;
                    let net = format!("10.213.{id}");
                    let env = vec![
                        ("VOXPAN_NETNS_A".to_owned(), format!("vxa{port}")),
                        ("VOXPAN_NETNS_B".to_owned(), format!("vxb{port}")),
                        ("VOXPAN_NETNS_NET".to_owned(), net.clone()),
                        ("ROS_PORT".to_owned(), port.to_string()),
                    ];
                    let n = Net {
                        layout,
                        port,
                        env,
                        master: format!("http://{net}.1:{port}"),
                    };
                    let up = n.netns(&["up"]).output().unwrap();
                    assert!(
                        up.status.success(),
                        "netns.sh up: {}",
                        String::from_utf8_lossy(&up.stderr)
                    );
                    n
                }
            }
        }

        fn netns(&self, args: &[&str]) -> Command {
            let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ros/netns.sh");
            let mut c = Command::new(script);
            c.args(args).envs(self.env.iter().map(|(k, v)| (k, v)));
            c
        }

        /// `program` with this test's ROS environment (its own master, logs in `dir`).
        fn command(&self, host: Host, program: &str, dir: &Path) -> Command {
            let mut c = match self.layout {
                Layout::Loopback => {
                    let mut c = Command::new(program);
                    c.env("ROS_MASTER_URI", &self.master)
                        .env("ROS_IP", "127.0.0.1");
                    c
                }
                Layout::TwoHosts => {
                    let h = match host {
                        Host::A => "a",
                        Host::B => "b",
                    };
                    // netns.sh execs the program: the child's pid is the program's.
                    let mut c = self.netns(&["exec", h]);
                    c.arg(program);
                    c
                }
            };
            c.env_remove("ROS_HOSTNAME")
                .env("ROS_HOME", dir.join("ros_home"))
                .env("ROS_LOG_DIR", dir.join("ros_log"));
            c
        }

        /// The address a host's processes listen on.
        #[cfg(feature = "ros2")]
        fn address(&self, host: Host) -> String {
            match (self.layout, host) {
                (Layout::Loopback, _) => "127.0.0.1".into(),
                (Layout::TwoHosts, Host::A) => format!("{}.1", self.env[2].1),
                (Layout::TwoHosts, Host::B) => format!("{}.2", self.env[2].1),
            }
        }

        /// Whether the master answers (from host a).
        fn master_up(&self, dir: &Path) -> bool {
            let mut c = self.command(Host::A, "rostopic", dir);
            c.arg("list").stdout(Stdio::null()).stderr(Stdio::null());
            c.status().is_ok_and(|s| s.success())
        }

        /// A Debian ROS tool (`args[0]`) run to its end on host a; its output. It must succeed
        /// within 30 s.
        fn ros_tool(&self, dir: &Path, args: &[&str]) -> String {
            let mut c = self.command(Host::A, args[0], dir);
            c.args(&args[1..]);
            let mut tool = Proc::spawn(&args.join(" "), c);
            assert!(
                tool.wait(Duration::from_secs(30)).success(),
                "{}",
                tool.text()
            );
            tool.text()
        }

        /// The map node's distance service (voxpan_msgs/DistanceQuery) asked by a rospy
        /// client (tools/ros/distance_client.py) at `points`: the distances and gradients
        /// it answered (`None` where NaN).
        #[allow(clippy::type_complexity)] // two parallel answers, as the service gives them
        fn query_distances(
            &self,
            dir: &Path,
            points: &[[f64; 3]],
        ) -> (Vec<Option<f64>>, Vec<Option<[f64; 3]>>) {
            let client =
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ros/distance_client.py");
            let request = dir.join("points.json");
            std::fs::write(&request, serde_json::to_string(points).unwrap()).unwrap();
            let mut c = self.command(Host::A, "/usr/bin/python3", dir);
            c.arg(client).arg("/voxpan/distance");
            c.stdin(std::fs::File::open(&request).unwrap());
            let out = c.output().unwrap();
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let answer: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            let distances = answer["distances"]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| d.as_f64())
                .collect();
            let gradients = answer["gradients"]
                .as_array()
                .unwrap()
                .iter()
                .map(|g| {
                    let c: Vec<Option<f64>> =
                        g.as_array().unwrap().iter().map(|c| c.as_f64()).collect();
                    Some([c[0]?, c[1]?, c[2]?])
                })
                .collect();
            (distances, gradients)
        }

        /// The map node's save service (std_srvs/Trigger), called by Debian's rosservice; it
        /// must answer success.
        fn call_save_service(&self, dir: &Path) {
            let answer = self.ros_tool(dir, &["rosservice", "call", "/voxpan/save_map"]);
            assert!(answer.contains("success: True"), "{answer}");
        }

        /// A ROS master on host a (a new one on the same port after the last one died).
        fn master(&self, dir: &Path) -> Proc {
            let mut rosmaster = self.command(Host::A, "rosmaster", dir);
            rosmaster.args(["--core", "-p", &self.port.to_string()]);
            let master = Proc::spawn("rosmaster", rosmaster);
            until(Duration::from_secs(30), "rosmaster", || self.master_up(dir));
            master
        }

        /// `voxpan node ROLE` on ROS 1, with deep queues: these tests want every frame, to
        /// compare maps; drops are counted.
        fn ros1_node(&self, dir: &Path, host: Host, role: &str, extra: &[&str]) -> Proc {
            let mut c = self.command(host, env!("CARGO_BIN_EXE_voxpan"), dir);
            c.args(["node", role, "--queue", "64", "--subscriber-queue", "64"])
                .args(extra);
            Proc::spawn(role, c)
        }

        /// The mapping node on host a, saving to `saved`, its mesh every 5 frames, with the
        /// distance field on (its costmap every 10 frames).
        fn map_node(&self, dir: &Path, saved: &Path) -> Proc {
            self.map_node_with(dir, saved, &[])
        }

        /// [`Net::map_node`] with `extra` options.
        fn map_node_with(&self, dir: &Path, saved: &Path, extra: &[&str]) -> Proc {
            let save = saved.to_str().unwrap();
            let config = esdf_config(dir);
            let config = config.to_str().unwrap();
            let mut args = vec!["--save", save, "--mesh-every", "5", "--config", config];
            args.extend(extra);
            self.ros1_node(dir, Host::A, "map", &args)
        }

        /// The mapping node (saving to `saved`) and the perception node, once both listen.
        fn listening_nodes(&self, dir: &Path, saved: &Path) -> (Proc, Proc) {
            self.listening_nodes_with(dir, saved, &[], &[])
        }

        /// [`Net::listening_nodes`] with `map_extra` options for the mapping node and
        /// `perceive_extra` for the perception node.
        fn listening_nodes_with(
            &self,
            dir: &Path,
            saved: &Path,
            map_extra: &[&str],
            perceive_extra: &[&str],
        ) -> (Proc, Proc) {
            let map_node = self.map_node_with(dir, saved, map_extra);
            let perceive_node = self.perceive_node_with(dir, perceive_extra);
            until(Duration::from_secs(20), "both nodes to listen", || {
                map_node.count("listening") == 1 && perceive_node.count("listening") == 1
            });
            (map_node, perceive_node)
        }

        /// Plays `bag` to its end (after 3 s), waits until the mapping node integrated its 20
        /// frames, then stops the perception node and the mapping node (which saves its map),
        /// each cleanly.
        fn map_the_bag(
            &self,
            dir: &Path,
            bag: &Path,
            map_node: &mut Proc,
            perceive_node: &mut Proc,
        ) {
            self.play_to_end(dir, bag, "3");
            until_integrated(20, map_node, &[&*perceive_node]);
            assert!(perceive_node.interrupt(Duration::from_secs(20)).success());
            assert!(
                map_node.interrupt(Duration::from_secs(60)).success(),
                "{}",
                map_node.text()
            );
        }

        /// Debian's `rosbag play` of `bag` on host b, starting after `delay_s` seconds, at a
        /// quarter of real time (20 frames in about 2.5 s, so no frame needs dropping), to its
        /// end (at most a minute).
        fn play_to_end(&self, dir: &Path, bag: &Path, delay_s: &str) {
            let mut play = self.command(Host::B, "rosbag", dir);
            play.args(["play", "-q", "-d", delay_s, "-r", "0.25"])
                .arg(bag);
            let mut play = Proc::spawn("rosbag play", play);
            assert!(
                play.wait(Duration::from_secs(60)).success(),
                "{}",
                play.text()
            );
        }

        /// The perception node on host b, taking the bag's label images, their classes named
        /// by the synthetic world's label table (sent on to the mapping node).
        fn perceive_node(&self, dir: &Path) -> Proc {
            self.perceive_node_with(dir, &[])
        }

        /// [`Net::perceive_node`] with `extra` options.
        fn perceive_node_with(&self, dir: &Path, extra: &[&str]) -> Proc {
            let classes = classes_csv(dir);
            let classes = classes.to_str().unwrap();
            let mut args = vec![
                "--labels-topic",
                "/camera/segments/image",
                "--classes",
                classes,
            ];
            args.extend(extra);
            self.ros1_node(dir, Host::B, "perceive", &args)
        }
    }

    impl Drop for Net {
        fn drop(&mut self) {
            if self.layout == Layout::TwoHosts {
                let _ = self.netns(&["down"]).status();
            }
        }
    }

    #[test]
    fn perceive_and_map_nodes_over_ros1_make_the_map_voxpan_run_makes() {
        nodes_make_the_map_voxpan_run_makes(
            "perceive_and_map_nodes_over_ros1_make_the_map_voxpan_run_makes",
            Layout::Loopback,
        );
    }

    #[test]
    fn perception_and_mapping_on_two_hosts_make_the_map_voxpan_run_makes() {
        let test = "perception_and_mapping_on_two_hosts_make_the_map_voxpan_run_makes";
        if root(test) {
            nodes_make_the_map_voxpan_run_makes(test, Layout::TwoHosts);
        }
    }

    fn nodes_make_the_map_voxpan_run_makes(test: &str, layout: Layout) {
        let Some((dir, bag)) = folder_with_bag(test) else {
            return;
        };
        let d = dir.path();

        let net = Net::new(layout);
        let _master = net.master(d);
        let saved = d.join("live.voxpan");
        let (mut map_node, mut perceive_node) = net.listening_nodes(d, &saved);
        // Stock tools as peers: each must decode what voxpan publishes (type and MD5 checked
        // by the ROS handshake).
        let echo = |topic: &str| {
            let mut c = net.command(Host::A, "rostopic", d);
            c.args(["echo", "-n", "1", "--noarr", topic]);
            Proc::spawn(topic, c)
        };
        let mut echo_depth = echo("/voxpan/depth");
        let mut echo_labels = echo("/voxpan/segments/labels");
        let mut echo_mesh = echo("/voxpan/mesh");
        let mut echo_costmap = echo("/voxpan/costmap");
        let mut echo_slice = echo("/voxpan/esdf_slice");
        std::thread::sleep(Duration::from_secs(2));

        // 3 s after advertising, so every subscriber (across the link too) is connected.
        net.play_to_end(d, &bag, "3");
        until_integrated(20, &map_node, &[&perceive_node]);
        // The save service (std_srvs/Trigger), called by Debian's rosservice: the map now,
        // which must be the map saved at exit (every frame is in).
        net.call_save_service(d);
        let on_request = PanopticMap::load(&saved).unwrap();
        std::fs::remove_file(&saved).unwrap();
        assert_distance_service_answers_from(&net, d, on_request.clone());
        assert!(perceive_node.interrupt(Duration::from_secs(20)).success());
        assert!(
            map_node.interrupt(Duration::from_secs(60)).success(),
            "{}",
            map_node.text()
        );
        let summary = map_node.text();
        assert!(summary.contains("20 frames in, 20 done"), "{summary}");
        assert!(summary.contains("dropped 0 busy + 0 lagged"), "{summary}");
        let perceived = perceive_node.text();
        assert!(perceived.contains("20 frames in, 20 done"), "{perceived}");

        for (echo, needle) in [
            (&mut echo_depth, "encoding: \"32FC1\""),
            (&mut echo_labels, "\\\"segments\\\""),
            (
                &mut echo_mesh,
                "markers: \"<array type: visualization_msgs/Marker",
            ),
            (&mut echo_costmap, "resolution: "),
            (&mut echo_slice, "point_step: 16"),
        ] {
            assert!(
                echo.wait(Duration::from_secs(20)).success(),
                "{}",
                echo.text()
            );
            assert!(
                echo.text().contains(needle),
                "{needle} not in {}",
                echo.text()
            );
        }

        let live = assert_live_map_is_voxpan_runs(&saved, &bag, d);
        assert!(
            on_request == live,
            "the map saved on request differs from the map saved at exit"
        );
    }

    /// Keyframes in the nodes: the perception node segments every 4th frame and sends the
    /// frames between with their depth as measured and no masks; the mapping node renders
    /// the map's masks at their pose, refines them on that depth and fills it. The map is
    /// `voxpan run --segment-every 4`'s, and not the map of every frame segmented (the
    /// carried frames did not map as segmented ones).
    #[test]
    fn nodes_segmenting_keyframes_make_the_map_voxpan_run_makes_with_them() {
        let test = "nodes_segmenting_keyframes_make_the_map_voxpan_run_makes_with_them";
        let Some(mapped) = nodes_mapped_the_bag(test, &[], &["--segment-every", "4"]) else {
            return;
        };
        let NodesMappedBag {
            dir,
            bag,
            saved,
            map_node,
            perceive_node,
        } = &mapped;
        let d = dir.path();
        let perceived = perceive_node.text();
        assert!(
            perceived.contains("20 frames in, 20 done, 5 segmented"),
            "{perceived}"
        );
        let summary = map_node.text();
        assert!(summary.contains("20 frames in, 20 done"), "{summary}");
        assert!(summary.contains("0 failed"), "{summary}");

        let keyframed = voxpan_run_map_with(bag, d, "every4", &["--segment-every", "4"]);
        assert_live_map_equals(saved, &keyframed);
        assert!(
            keyframed != voxpan_run_map(bag, d),
            "carried frames mapped as if segmented"
        );
    }

    /// `--consolidate-every 5`: the mapping node consolidates its live map every 5 frames,
    /// and its map is `voxpan run`'s with `[tracking] consolidate_every = 5` (on this world
    /// the passes change the map's labels, so a node that took the option without passing
    /// would differ).
    #[test]
    fn a_mapping_node_consolidates_its_live_map_as_often_as_asked() {
        let test = "a_mapping_node_consolidates_its_live_map_as_often_as_asked";
        let Some(mapped) = nodes_mapped_the_bag(test, &["--consolidate-every", "5"], &[]) else {
            return;
        };
        let every5 = voxpan_run_map_configured(&mapped.bag, mapped.dir.path(), "every5", 5, &[]);
        assert_live_map_equals(&mapped.saved, &every5);
    }

    /// What [`nodes_mapped_the_bag`] leaves: the test's folder, the bag, the map the mapping
    /// node saved, and the two stopped nodes (for their summaries).
    struct NodesMappedBag {
        dir: tempfile::TempDir,
        bag: PathBuf,
        saved: PathBuf,
        map_node: Proc,
        perceive_node: Proc,
    }

    /// The bag of [`folder_with_bag`] mapped over loopback by a mapping node with `map_extra`
    /// options and a perception node with `perceive_extra` (see [`Net::map_the_bag`]); `None`
    /// where the test is skipped.
    fn nodes_mapped_the_bag(
        test: &str,
        map_extra: &[&str],
        perceive_extra: &[&str],
    ) -> Option<NodesMappedBag> {
        let (dir, bag) = folder_with_bag(test)?;
        let d = dir.path();
        let net = Net::new(Layout::Loopback);
        let _master = net.master(d);
        let saved = d.join("live.voxpan");
        let (mut map_node, mut perceive_node) =
            net.listening_nodes_with(d, &saved, map_extra, perceive_extra);
        net.map_the_bag(d, &bag, &mut map_node, &mut perceive_node);
        Some(NodesMappedBag {
            dir,
            bag,
            saved,
            map_node,
            perceive_node,
        })
    }

    /// The distance service, asked while the node runs, answers as the map saved at that
    /// moment does once its distance field is rebuilt: the same distances (within half a
    /// voxel where the node's incremental field and the rebuild differ), unknown where
    /// unknown, and the same gradients where the distances are the same.
    fn assert_distance_service_answers_from(net: &Net, dir: &Path, mut map: PanopticMap) {
        use voxpan_core::nalgebra::Point3;
        map.update_esdf();
        let voxel = map.voxel_size();
        let observed = map.esdf_voxels();
        // Off-centre points among the observed voxels, and one far from anything seen.
        let mut points: Vec<[f64; 3]> = observed
            .iter()
            .step_by((observed.len() / 300).max(1))
            .map(|(v, _)| {
                let at = |a: usize, f: f64| (v[a] as f64 + f) * voxel;
                [at(0, 0.8), at(1, 0.35), at(2, 0.6)]
            })
            .collect();
        points.push([50.0, 50.0, 50.0]);
        let (distances, gradients) = net.query_distances(dir, &points);
        assert_eq!(distances.len(), points.len());
        assert_eq!(gradients.len(), points.len());
        let (mut same, mut known) = (0, 0);
        for (i, p) in points.iter().enumerate() {
            let p = Point3::new(p[0], p[1], p[2]);
            let (ours, ours_gradient) = match map.distance_and_gradient(&p) {
                Some((d, g)) => (Some(d as f64), Some(g.cast::<f64>())),
                None => (map.distance(&p).map(|d| d as f64), None),
            };
            match (ours, distances[i]) {
                (None, None) => {}
                (Some(ours), Some(theirs)) => {
                    known += 1;
                    assert!(
                        (ours - theirs).abs() <= 0.5 * voxel + 1e-6,
                        "{p:?}: {ours} vs {theirs}"
                    );
                    if (ours - theirs).abs() < 1e-6 {
                        same += 1;
                        assert_eq!(ours_gradient.is_some(), gradients[i].is_some(), "{p:?}");
                        if let (Some(a), Some(b)) = (ours_gradient, gradients[i]) {
                            let b = voxpan_core::nalgebra::Vector3::from(b);
                            assert!((a - b).norm() < 1e-4, "{p:?}: {a:?} vs {b:?}");
                        }
                    }
                }
                other => panic!("{p:?}: {other:?}"),
            }
        }
        assert_eq!(distances.last(), Some(&None), "far from anything seen");
        assert!(known > 100, "{known} of {} points known", points.len());
        assert!(same * 100 >= known * 95, "{same} of {known} the same");
    }

    /// A test's folder and the tiny world's ROS 1 bag in it; `None`: skipped (see [`tools`]).
    /// What the perception node subscribes to: the camera's topics as the test bags have them.
    const CAMERA_TOPICS: [&str; 7] = [
        "/camera/color/image_raw",
        "/camera/aligned_depth_to_color/image_raw",
        "/camera/color/camera_info",
        "/tf",
        "/tf_static",
        "/camera/segments/image",
        "/camera/segments/labels",
    ];

    fn folder_with_bag(test: &str) -> Option<(tempfile::TempDir, PathBuf)> {
        let py = tools(test)?;
        let dir = tempfile::tempdir().unwrap();
        let bag = ros1_bag(&py, dir.path());
        Some((dir, bag))
    }

    /// The tiny synthetic world's 20 frames as a ROS 1 bag in `dir`, written by PyPI rosbags.
    fn ros1_bag(py: &Path, dir: &Path) -> PathBuf {
        let options = ["--formats", "ros1", "--no-verify"].map(std::ffi::OsStr::new);
        crate::common::tiny_world_bags(py, dir, &options);
        dir.join("bags/s.bag")
    }

    /// A node that loses its master or its peer carries on: the master dies and a new one
    /// starts on its port, the perception node dies and another takes its place, and the map
    /// is still every frame's. The mapping node learns of the new perception node only from
    /// the new master, so only if it registered again with it; the master dies again while
    /// the bag plays (connected peers keep talking), and the save service is called through
    /// a third master.
    #[test]
    fn nodes_that_lose_their_master_or_their_peer_reconnect() {
        let test = "nodes_that_lose_their_master_or_their_peer_reconnect";
        let Some((dir, bag)) = folder_with_bag(test) else {
            return;
        };
        let d = dir.path();
        let net = Net::new(Layout::Loopback);
        let master = net.master(d);
        let saved = d.join("live.voxpan");
        let mut map_node = net.map_node(d, &saved);
        let first_perceive_node = net.perceive_node(d);
        until(Duration::from_secs(20), "both nodes to listen", || {
            map_node.count("listening") == 1 && first_perceive_node.count("listening") == 1
        });
        let registered_again = "topics and services again";

        drop(master);
        until(
            Duration::from_secs(10),
            "the nodes to see the master gone",
            || map_node.count(" lost (") == 1 && first_perceive_node.count(" lost (") == 1,
        );
        let master = net.master(d);
        until(
            Duration::from_secs(10),
            "the nodes to register again",
            || {
                map_node.count(registered_again) == 1
                    && first_perceive_node.count(registered_again) == 1
            },
        );
        // SIGKILL: a crash, no unregistering.
        drop(first_perceive_node);
        let mut perceive_node = net.perceive_node(d);
        until(Duration::from_secs(20), "the new perception node", || {
            perceive_node.count("listening") == 1
        });

        let mut play = net.command(Host::A, "rosbag", d);
        play.args(["play", "-q", "-d", "2", "-r", "0.25"]).arg(&bag);
        let mut play = Proc::spawn("rosbag play", play);
        until_integrated(5, &map_node, &[&perceive_node, &play]);
        drop(master);
        assert!(play.running(), "the bag was over before the master died");
        until_integrated(20, &map_node, &[&perceive_node, &play]);
        play.wait(Duration::from_secs(30));

        let _master = net.master(d);
        until(
            Duration::from_secs(10),
            "the map node to register again",
            || map_node.count(registered_again) == 2,
        );
        // Its publication too, as Debian's rostopic sees it.
        let info = net.ros_tool(d, &["rostopic", "info", "/voxpan/mesh"]);
        assert!(info.contains("/voxpan_map"), "{info}");
        net.call_save_service(d);
        assert!(perceive_node.interrupt(Duration::from_secs(20)).success());
        assert!(
            map_node.interrupt(Duration::from_secs(60)).success(),
            "{}",
            map_node.text()
        );
        let summary = map_node.text();
        assert!(summary.contains("20 frames in, 20 done"), "{summary}");
        assert!(summary.contains("dropped 0 busy + 0 lagged"), "{summary}");
        assert_live_map_is_voxpan_runs(&saved, &bag, d);
    }

    /// Anyone on a robot's network can publish on the nodes' topics (ROS 1 has no
    /// authentication): bodies of random bytes with the right type and MD5 sum, sent by a rospy
    /// peer (tools/ros/garbage_pub.py) on every topic either node subscribes to, as the master
    /// lists them, are each logged with the topic, counted as bad, and change nothing: the
    /// bag played afterwards makes the map voxpan run makes.
    #[test]
    fn garbage_on_every_topic_the_nodes_subscribe_to_is_counted_and_changes_nothing() {
        use std::collections::BTreeMap;
        let net = Net::new(Layout::Loopback);
        let Some((dir, bag)) = folder_with_bag(
            "garbage_on_every_topic_the_nodes_subscribe_to_is_counted_and_changes_nothing",
        ) else {
            return;
        };
        let (d, saved) = (dir.path(), dir.path().join("live.voxpan"));
        let _master = net.master(d);
        let (mut map_node, mut perceive_node) = net.listening_nodes(d, &saved);
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ros/garbage_pub.py");
        let sent = net.ros_tool(
            d,
            &[
                "/usr/bin/python3",
                script.to_str().unwrap(),
                "--count",
                "3",
                // The camera's topics: nothing publishes them yet, and the nodes' slave API
                // (roslibrust's) gives subscriptions' types as `*`.
                "--type",
                "/camera/color/image_raw=sensor_msgs/Image",
                "--type",
                "/camera/aligned_depth_to_color/image_raw=sensor_msgs/Image",
                "--type",
                "/camera/color/camera_info=sensor_msgs/CameraInfo",
                "--type",
                "/tf=tf2_msgs/TFMessage",
                "--type",
                "/tf_static=tf2_msgs/TFMessage",
                "--type",
                "/camera/segments/image=sensor_msgs/Image",
                "--type",
                "/camera/segments/labels=std_msgs/String",
                "/voxpan_perceive",
                "/voxpan_map",
            ],
        );
        // "garbage NODE TOPIC TYPE COUNT", a line for each node and topic.
        let mut topics: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
        for line in sent.lines().filter(|l| l.starts_with("garbage ")) {
            let words: Vec<&str> = line.split_whitespace().collect();
            assert_eq!((words.len(), words[4]), (5, "3"), "{line}");
            topics.entry(words[1]).or_default().push(words[2]);
        }
        let perceived = &topics["/voxpan_perceive"];
        for topic in CAMERA_TOPICS {
            assert!(perceived.contains(&topic), "{topic}: {sent}");
        }
        let mapped = &topics["/voxpan_map"];
        for topic in ["/voxpan/depth", "/voxpan/pose", "/voxpan/segments/labels"] {
            assert!(mapped.contains(&topic), "{topic}: {sent}");
        }
        for (node, process) in [
            ("/voxpan_perceive", &perceive_node),
            ("/voxpan_map", &map_node),
        ] {
            for topic in &topics[node] {
                until(
                    Duration::from_secs(20),
                    &format!("{node} to log garbage on {topic}"),
                    || process.count(&format!("bad message on {topic}: ")) >= 1,
                );
            }
        }

        net.play_to_end(d, &bag, "2");
        until_integrated(20, &map_node, &[&perceive_node]);
        for (node, process, limit_s) in [
            ("/voxpan_perceive", &mut perceive_node, 20),
            ("/voxpan_map", &mut map_node, 60),
        ] {
            let stopped = process.interrupt(Duration::from_secs(limit_s)).success();
            let text = process.text();
            assert!(stopped, "{node}: {text}");
            let bad = 3 * topics[node].len();
            assert!(text.contains("20 frames in, 20 done"), "{node}: {text}");
            assert!(
                text.contains(&format!(" {bad} bad messages")),
                "{node}: {bad} expected: {text}"
            );
        }
        assert_live_map_is_voxpan_runs(&saved, &bag, d);
    }

    /// The signals and calls a robot's supervisor stops a node with stop it as Ctrl-C does:
    /// SIGTERM (systemd, docker, roslaunch) ends the perception node with its summary, and
    /// `rosnode kill` (ROS 1's slave API shutdown) ends the mapping node, which integrates
    /// what it has, saves the map voxpan run makes and prints its summary. A `--save` path
    /// that is a folder is refused at start. A malformed image published by Debian's rostopic
    /// is logged with its reason as it arrives, counted, and changes nothing else.
    #[test]
    fn nodes_stop_cleanly_on_sigterm_and_rosnode_kill() {
        let test = "nodes_stop_cleanly_on_sigterm_and_rosnode_kill";
        let Some((dir, bag)) = folder_with_bag(test) else {
            return;
        };
        let d = dir.path();
        let net = Net::new(Layout::Loopback);
        let _master = net.master(d);

        let mut refused = net.ros1_node(d, Host::A, "map", &["--save", d.to_str().unwrap()]);
        assert!(!refused.wait(Duration::from_secs(20)).success());
        assert!(refused.text().contains("is a folder"), "{}", refused.text());

        let saved = d.join("live.voxpan");
        let (mut map_node, mut perceive_node) = net.listening_nodes(d, &saved);
        let garbage = "{header: {frame_id: c}, height: 2, width: 2, encoding: yuv422, step: 4, \
                       data: [1, 2, 3, 4, 5, 6, 7, 8]}";
        let topic = "/camera/color/image_raw";
        net.ros_tool(
            d,
            &["rostopic", "pub", "-1", topic, "sensor_msgs/Image", garbage],
        );
        until(
            Duration::from_secs(20),
            "the bad image to be logged",
            || perceive_node.count("bad message on /camera/color/image_raw: ") == 1,
        );
        assert!(
            perceive_node.text().contains("yuv422"),
            "{}",
            perceive_node.text()
        );
        net.play_to_end(d, &bag, "2");
        until_integrated(20, &map_node, &[&perceive_node]);

        // SAFETY: kill only sends a signal to our own child.
        unsafe { libc::kill(perceive_node.child.id() as i32, libc::SIGTERM) };
        assert!(
            perceive_node.wait(Duration::from_secs(20)).success(),
            "{}",
            perceive_node.text()
        );
        let perceived = perceive_node.text();
        assert!(perceived.contains("20 frames in, 20 done"), "{perceived}");
        assert!(perceived.contains("1 bad messages"), "{perceived}");

        let killed = net.ros_tool(d, &["rosnode", "kill", "/voxpan_map"]);
        assert!(killed.contains("killed"), "{killed}");
        assert!(
            map_node.wait(Duration::from_secs(60)).success(),
            "{}",
            map_node.text()
        );
        let summary = map_node.text();
        assert!(summary.contains("told to shut down"), "{summary}");
        assert!(summary.contains("20 frames in, 20 done"), "{summary}");
        assert_live_map_is_voxpan_runs(&saved, &bag, d);
    }

    /// Root for the two-host layouts (network namespaces need CAP_SYS_ADMIN; CI runs as
    /// root); `false`: skipped with VOXPAN_ALLOW_MISSING_DATA=1.
    fn root(test: &str) -> bool {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } == 0 {
            return true;
        }
        if voxpan_test_support::missing_data_allowed() {
            eprintln!("SKIPPED {test}: network namespaces need root");
            return false;
        }
        panic!("{test}: network namespaces need root, or set VOXPAN_ALLOW_MISSING_DATA=1");
    }

    #[cfg(feature = "ros2")]
    #[test]
    fn perceive_and_map_nodes_over_ros2_make_the_map_voxpan_run_makes() {
        ros2_nodes_make_the_map_voxpan_run_makes(
            "perceive_and_map_nodes_over_ros2_make_the_map_voxpan_run_makes",
            Layout::Loopback,
        );
    }

    #[cfg(feature = "ros2")]
    #[test]
    fn ros2_perception_and_mapping_on_two_hosts_make_the_map_voxpan_run_makes() {
        let test = "ros2_perception_and_mapping_on_two_hosts_make_the_map_voxpan_run_makes";
        if root(test) {
            ros2_nodes_make_the_map_voxpan_run_makes(test, Layout::TwoHosts);
        }
    }

    /// The ROS 2 peer: PyPI eclipse-zenoh and rosbags in target/ros-venv.
    #[cfg(feature = "ros2")]
    fn ros2_tools(test: &str) -> Option<PathBuf> {
        let venv = ros_venv_python();
        let ok = Command::new(&venv)
            .args(["-c", "import zenoh, xxhash, rosbags"])
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            return Some(venv);
        }
        if voxpan_test_support::missing_data_allowed() {
            eprintln!("SKIPPED {test}: target/ros-venv lacks eclipse-zenoh, xxhash or rosbags");
            return None;
        }
        panic!(
            "{test}: target/ros-venv lacks eclipse-zenoh, xxhash or rosbags: run \
             tools/ros/setup.sh --venv-only, or set VOXPAN_ALLOW_MISSING_DATA=1"
        );
    }

    /// The router and the camera (a peer playing a ROS 2 bag) on host a with the mapping
    /// node; the perception node on host b. The nodes start before the router; the perception
    /// node crashes and is replaced; the router dies while the bag plays, and a new router
    /// must see the nodes again. The camera plays only once
    /// voxpan's subscriptions are in the ROS graph (their liveliness tokens), and reports what
    /// it saw: every token parsed by rmw_zenoh's rules, and voxpan's topics decoded by rosbags.
    #[cfg(feature = "ros2")]
    fn ros2_nodes_make_the_map_voxpan_run_makes(test: &str, layout: Layout) {
        let Some(py) = ros2_tools(test) else {
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        crate::common::tiny_world_bags(
            &py,
            d,
            &[
                "--formats".as_ref(),
                "mcap".as_ref(),
                "--no-verify".as_ref(),
            ],
        );
        let bag = d.join("bags/s-mcap");
        let net = Net::new(layout);
        let router = format!("tcp/{}:{}", net.address(Host::A), net.port);
        let report = d.join("peer.json");
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ros/ros2_peer.py");
        let camera_topics = CAMERA_TOPICS;
        let node = |host: Host, role: &str, extra: &[&str]| {
            let mut c = net.command(host, env!("CARGO_BIN_EXE_voxpan"), d);
            let listen = format!("tcp/{}:0", net.address(host));
            c.args(["node", role, "--queue", "64", "--subscriber-queue", "64"])
                .args([
                    "--ros2",
                    "--zenoh-connect",
                    &router,
                    "--zenoh-listen",
                    &listen,
                ])
                .args(extra);
            Proc::spawn(role, c)
        };
        let saved = d.join("live.voxpan");
        // With the distance field on, as the ROS 1 nodes (and `voxpan run` to compare).
        let config = esdf_config(d);
        let mut map_node = node(
            Host::A,
            "map",
            &[
                "--save",
                saved.to_str().unwrap(),
                "--mesh-every",
                "5",
                "--config",
                config.to_str().unwrap(),
            ],
        );
        let perceive = || {
            node(
                Host::B,
                "perceive",
                &[
                    "--labels-topic",
                    "/camera/segments/image",
                    "--classes",
                    classes_csv(d).to_str().unwrap(),
                ],
            )
        };
        let first_perceive_node = perceive();
        let wait_for = [
            &camera_topics[..],
            &["/voxpan/depth", "/voxpan/segments/labels"],
        ]
        .concat()
        .join(",");
        // The router after the nodes (they keep trying it until it answers, as rmw_zenoh's
        // do); the camera is a peer beside it. The router dies while the bag plays: frames
        // keep flowing between the peers, as between rmw_zenoh's nodes. A new router on the
        // same port must then see the nodes' subscriptions again.
        std::thread::sleep(Duration::from_secs(1));
        let router_process = |name: &str| {
            let mut c = net.command(Host::A, py.to_str().unwrap(), d);
            c.arg(&script)
                .args(["--listen", &router, "--wait-for", &wait_for, "--report"])
                .arg(d.join(format!("{}.json", name.replace(' ', "-"))));
            Proc::spawn(name, c)
        };
        let first = router_process("first router");
        until(
            Duration::from_secs(60),
            "the nodes' subscriptions at the router",
            || first.count("subscriptions seen") == 1,
        );
        // The perception node crashes (SIGKILL) and another takes its place: the map node
        // must hear the new one's topics.
        drop(first_perceive_node);
        let mut perceive_node = perceive();
        until(Duration::from_secs(20), "the new perception node", || {
            perceive_node.count("listening") == 1
        });
        // Anyone on the network: bad samples on every key either node subscribes to, before
        // the camera starts (zenoh keeps no sample for later subscribers). Each is counted
        // as bad and logged with its topic.
        let mut junk = net.command(Host::A, py.to_str().unwrap(), d);
        junk.arg(&script)
            .args([
                "--connect",
                &router,
                "--wait-for",
                &wait_for,
                "--garbage",
                "3",
            ])
            .arg("--report")
            .arg(d.join("garbage.json"));
        let mut junk = Proc::spawn("garbage peer", junk);
        assert!(
            junk.wait(Duration::from_secs(60)).success(),
            "{}",
            junk.text()
        );
        // "garbage NODE TOPIC COUNT"
        let mut garbage: std::collections::BTreeMap<String, Vec<String>> = Default::default();
        for line in junk.text().lines().filter(|l| l.starts_with("garbage ")) {
            let w: Vec<&str> = line.split_whitespace().collect();
            assert_eq!((w.len(), w[3]), (4, "3"), "{line}");
            garbage
                .entry(w[1].to_owned())
                .or_default()
                .push(w[2].to_owned());
        }
        for (node, process, must) in [
            ("voxpan_perceive", &perceive_node, camera_topics[0]),
            ("voxpan_map", &map_node, "/voxpan/depth"),
        ] {
            let topics = garbage.get(node).cloned().unwrap_or_default();
            assert!(topics.iter().any(|t| t == must), "{node}: {}", junk.text());
            for topic in topics {
                until(
                    Duration::from_secs(20),
                    &format!("{node} to log garbage on {topic}"),
                    || process.count(&format!("bad message on {topic}: ")) >= 1,
                );
            }
        }
        let mut peer = net.command(Host::A, py.to_str().unwrap(), d);
        peer.arg(&script)
            .args(["--connect", &router])
            .arg("--bag")
            .arg(&bag)
            // A quarter of real time, as the ROS 1 test: no frame needs dropping.
            .args(["--rate", "0.25"])
            .args(["--wait-for", &wait_for])
            .args(["--echo", "/voxpan/depth=sensor_msgs/msg/Image"])
            .args(["--echo", "/voxpan/segments/labels=std_msgs/msg/String"])
            .args(["--echo", "/voxpan/camera_info=sensor_msgs/msg/CameraInfo"])
            .args(["--echo", "/voxpan/pose=geometry_msgs/msg/PoseStamped"])
            .args(["--echo", "/voxpan/mesh=visualization_msgs/msg/MarkerArray"])
            .args(["--echo", "/voxpan/costmap=nav_msgs/msg/OccupancyGrid"])
            .args(["--echo", "/voxpan/esdf_slice=sensor_msgs/msg/PointCloud2"])
            .arg("--report")
            .arg(&report);
        let mut peer = Proc::spawn("ros2_peer.py", peer);
        until_integrated(5, &map_node, &[&perceive_node, &peer, &first]);
        let no_router = format!("no zenoh router answers at {router}");
        let router_back = format!("the zenoh router at {router} answers");
        // (A node started before the first router may have said so once already.)
        let said = |p: &Proc, what: &str| p.count(what);
        let before = [
            said(&map_node, &no_router),
            said(&perceive_node, &no_router),
        ];
        drop(first);
        assert!(
            peer.count("played ") == 0,
            "the bag was over before the router died"
        );
        until(Duration::from_secs(60), "the bag to be played", || {
            peer.count("played 141 messages") == 1
        });
        // With the router gone, the nodes say so (they see no new node until one answers).
        for ((node, process), before) in [("map", &map_node), ("perceive", &perceive_node)]
            .into_iter()
            .zip(before)
        {
            until(
                Duration::from_secs(20),
                &format!("the {node} node to say no router answers"),
                || said(process, &no_router) == before + 1,
            );
        }
        let answered = said(&map_node, &router_back);
        until_integrated(20, &map_node, &[&perceive_node, &peer]);
        // The camera leaves (once it has the mesh update of frame 20) before the new router
        // starts: only voxpan's nodes can then tell it of their subscriptions.
        until(
            Duration::from_secs(30),
            "4 mesh updates and 2 costmaps at the camera",
            || {
                peer.count("echoed /voxpan/mesh 4") == 1
                    && peer.count("echoed /voxpan/costmap 2") == 1
                    && peer.count("echoed /voxpan/esdf_slice 2") == 1
            },
        );
        assert!(
            peer.interrupt(Duration::from_secs(30)).success(),
            "{}",
            peer.text()
        );
        let mut second = router_process("second router");
        until(
            Duration::from_secs(30),
            "the nodes' subscriptions at the second router",
            || second.count("subscriptions seen") == 1,
        );
        until(
            Duration::from_secs(20),
            "the map node to say the new router answers",
            || said(&map_node, &router_back) == answered + 1,
        );
        assert!(second.interrupt(Duration::from_secs(30)).success());
        assert!(perceive_node.interrupt(Duration::from_secs(20)).success());
        assert!(
            map_node.interrupt(Duration::from_secs(60)).success(),
            "{}",
            map_node.text()
        );
        for (node, text) in [
            ("voxpan_map", map_node.text()),
            ("voxpan_perceive", perceive_node.text()),
        ] {
            let bad = 3 * garbage[node].len();
            assert!(text.contains("20 frames in, 20 done"), "{node}: {text}");
            assert!(text.contains("dropped 0 busy + 0 lagged"), "{node}: {text}");
            assert!(
                text.contains(&format!(" {bad} bad messages")),
                "{node}: {bad} expected: {text}"
            );
        }

        // What the independent peer saw of voxpan on the ROS graph and on the wire.
        let seen: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        assert_eq!(seen["token_errors"], serde_json::json!([]), "{seen}");
        let tokens = seen["tokens"].as_array().unwrap();
        let has = |kind: &str, node: &str, topic: Option<&str>, ty: &str| {
            tokens.iter().any(|t| {
                t["kind"] == kind
                    && t["node"] == node
                    && topic.is_none_or(|topic| t["topic"] == topic)
                    && (ty.is_empty() || t["type"] == ty)
            })
        };
        assert!(has("NN", "voxpan_perceive", None, ""), "{seen}");
        assert!(has("NN", "voxpan_map", None, ""), "{seen}");
        // QoS as rmw_zenoh writes it: publishers reliable keep-all, subscriptions keep-last
        // --subscriber-queue.
        for t in tokens
            .iter()
            .filter(|t| t["node"].as_str().is_some_and(|n| n.starts_with("voxpan")))
        {
            match t["kind"].as_str() {
                Some("MP") => assert_eq!(t["qos"], "::2,:,:,:,,", "{t}"),
                Some("MS") => assert_eq!(t["qos"], "::,64:,:,:,,", "{t}"),
                _ => {}
            }
        }
        for topic in camera_topics {
            assert!(
                has("MS", "voxpan_perceive", Some(topic), ""),
                "{topic}: {seen}"
            );
        }
        assert!(
            has(
                "MP",
                "voxpan_perceive",
                Some("/voxpan/depth"),
                "sensor_msgs::msg::dds_::Image_"
            ),
            "{seen}"
        );
        assert!(
            has(
                "MP",
                "voxpan_map",
                Some("/voxpan/mesh"),
                "visualization_msgs::msg::dds_::MarkerArray_"
            ),
            "{seen}"
        );
        let echo = &seen["echo"];
        for topic in [
            "/voxpan/depth",
            "/voxpan/segments/labels",
            "/voxpan/camera_info",
            "/voxpan/pose",
        ] {
            assert_eq!(echo[topic]["count"], 20, "{topic}: {}", echo[topic]);
            assert_eq!(echo[topic]["lost"], 0, "{topic}: {}", echo[topic]);
            assert_eq!(echo[topic]["errors"], serde_json::json!([]), "{topic}");
        }
        assert_eq!(echo["/voxpan/depth"]["first"]["encoding"], "32FC1");
        assert_eq!(echo["/voxpan/depth"]["first"]["width"], 160);
        assert!(
            echo["/voxpan/segments/labels"]["first"]["data"]
                .as_str()
                .unwrap()
                .contains("\"segments\""),
            "{echo}"
        );
        // Every 5 frames, and at the end if anything changed since: at least 4 updates, none
        // lost.
        let mesh = &echo["/voxpan/mesh"];
        assert!(mesh["count"].as_u64().unwrap() >= 4, "{mesh}");
        assert_eq!(mesh["lost"], 0, "{mesh}");
        assert_eq!(mesh["errors"], serde_json::json!([]), "{mesh}");
        assert_eq!(mesh["first"]["types"], serde_json::json!([11]), "{mesh}");
        assert!(mesh["first"]["points"].as_u64().unwrap() > 0, "{mesh}");
        // The costmap and its clearance every 10 frames: a grid with free and occupied
        // cells, and a cloud of one float32 point per known cell.
        for topic in ["/voxpan/costmap", "/voxpan/esdf_slice"] {
            let e = &echo[topic];
            assert!(e["count"].as_u64().unwrap() >= 2, "{topic}: {e}");
            assert_eq!(e["lost"], 0, "{topic}: {e}");
            assert_eq!(e["errors"], serde_json::json!([]), "{topic}: {e}");
        }
        let grid = &echo["/voxpan/costmap"]["first"];
        assert!(grid["resolution"].as_f64().unwrap() > 0.0, "{grid}");
        let cells = |v: &str| grid["cells"][v].as_u64().unwrap();
        assert!(cells("0") > 0 && cells("100") > 0, "{grid}");
        let slice = &echo["/voxpan/esdf_slice"]["first"];
        assert_eq!(
            slice["fields"],
            serde_json::json!([["x", 0, 7], ["y", 4, 7], ["z", 8, 7], ["distance", 12, 7]]),
            "{slice}"
        );
        assert_eq!(
            slice["width"].as_u64().unwrap(),
            cells("0") + cells("100"),
            "{slice}"
        );
        assert_eq!(
            slice["bytes"].as_u64().unwrap(),
            16 * slice["width"].as_u64().unwrap()
        );

        assert_live_map_is_voxpan_runs(&saved, &bag, d);
    }
}
