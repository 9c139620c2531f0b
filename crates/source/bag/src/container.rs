//! The bag files themselves: ROS 1 `.bag` (through `rosbag`), MCAP (through `mcap`) and ROS 2's
//! SQLite `.db3` (through `rusqlite`), behind one small interface: the connections, one pass over every message, and reading one message
//! again later by its [`Locator`] (so that images are decoded when a frame is loaded, not held
//! in memory).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use memmap2::Mmap;
use rosbag::{ChunkRecord, IndexRecord, MessageRecord, RosBag};

use crate::BagError;
use crate::msgs::Wire;

/// One topic's connection: its name, its type (normalised to `pkg/Type`), how it is encoded.
#[derive(Clone, Debug)]
pub struct Connection {
    pub topic: String,
    /// `sensor_msgs/Image` for both ROS 1's `sensor_msgs/Image` and ROS 2's
    /// `sensor_msgs/msg/Image`.
    pub msg_type: String,
    /// `None` when the payload encoding is neither ROS 1 nor CDR (MCAP can hold anything).
    pub wire: Option<Wire>,
}

/// Where a message is: its chunk and its position among the chunk's records (SQLite: chunk 0,
/// the message's row id).
#[derive(Clone, Copy, Debug)]
pub struct Locator {
    chunk: u64,
    ordinal: u64,
}

pub struct Container {
    path: PathBuf,
    kind: Kind,
}

enum Kind {
    Ros1 {
        bag: RosBag,
        /// `(position in the file, first and last record time)` of each chunk.
        chunks: Vec<(u64, u64, u64)>,
        /// ROS 1 connection id -> position in the connection list.
        ids: BTreeMap<u32, usize>,
    },
    Mcap {
        map: Mmap,
        // Boxed: the summary is large next to the ROS 1 variant.
        summary: Box<mcap::Summary>,
        ids: HashMap<u16, usize>,
    },
    Sqlite {
        // A mutex so that an opened bag can be shared between threads (a connection is Send
        // but not Sync); only one thread reads a bag at a time anyway.
        db: Mutex<rusqlite::Connection>,
        /// rosbag2 topic id -> position in the connection list.
        ids: HashMap<i64, usize>,
    },
}

pub struct Message<'a> {
    /// Index into [`Container::connections`].
    pub connection: usize,
    /// The record (receive) time, nanoseconds.
    pub log_time: u64,
    pub data: &'a [u8],
    pub at: Locator,
}

fn invalid(path: &Path, message: impl Into<String>) -> BagError {
    BagError::new(path, message)
}

const ROS1_MAGIC: &[u8] = b"#ROSBAG V2.0\n";
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";

/// The MCAP file of a ROS 2 bag folder (metadata.yaml + one .mcap), or `path` itself.
pub fn resolve(path: &Path) -> Result<PathBuf, BagError> {
    if !path.is_dir() {
        return Ok(path.to_owned());
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(|e| invalid(path, format!("cannot list: {e}")))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap" || x == "db3"))
        .collect();
    files.sort();
    match files.as_slice() {
        [one] => Ok(one.clone()),
        [] => {
            let compressed = std::fs::read_dir(path)
                .map(|d| {
                    d.filter_map(|e| e.ok())
                        .any(|e| e.file_name().to_string_lossy().ends_with(".zstd"))
                })
                .unwrap_or(false);
            Err(invalid(
                path,
                if compressed {
                    "a bag folder of zstd-compressed files (--compression-mode file): not \
                     read; `ros2 bag decompress` or `zstd -d` gives the .mcap or .db3"
                } else {
                    "a folder with no .mcap or .db3 bag in it"
                },
            ))
        }
        _ => Err(invalid(
            path,
            format!(
                "{} bag files (split bags are not read): name one of them",
                files.len()
            ),
        )),
    }
}

/// Whether `path` is a bag voxpan can try to open: by its first bytes or its name (an empty or
/// cut `.bag`, `.mcap`, `.db3` too), or a ROS 2 bag folder, even one without `metadata.yaml`.
pub fn looks_like_bag(path: &Path) -> bool {
    let bag_extension = |p: &Path| {
        p.extension()
            .is_some_and(|e| e == "bag" || e == "mcap" || e == "db3")
    };
    if path.is_dir() {
        // A ROS 2 bag folder, whole or without its metadata.yaml: the bag reader names what
        // is wrong with it, not the dataset readers.
        // (A flat or TUM folder with a recording saved into it stays a dataset.)
        let dataset = ["Intrinsics.txt", "rgb.txt", "depth.txt"]
            .iter()
            .any(|marker| path.join(marker).is_file());
        return path.join("metadata.yaml").is_file()
            || !dataset
                && std::fs::read_dir(path).is_ok_and(|entries| {
                    entries
                        .flatten()
                        .any(|e| e.path().is_file() && bag_extension(&e.path()))
                });
    }
    // Named as a bag (an empty or cut file too): the bag reader says why it cannot be read.
    if bag_extension(path) {
        return true;
    }
    let mut head = [0u8; 16];
    let n = File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .unwrap_or(0);
    head[..n].starts_with(ROS1_MAGIC)
        || head[..n].starts_with(MCAP_MAGIC)
        || head[..n].starts_with(SQLITE_MAGIC)
}

/// Checks that the schema and channel records of an MCAP file's summary section hold the
/// strings and bytes they declare: the `mcap` crate allocates a declared length (up to 4 GB)
/// before it checks that the record has it (found by fuzzing). The rest of the layout is left
/// to the crate, which checks it.
fn check_mcap_summary_lengths(file: &[u8]) -> Result<(), String> {
    const FOOTER: usize = 1 + 8 + 20;
    let le64 = |b: &[u8]| u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
    let Some(footer_at) = file.len().checked_sub(MCAP_MAGIC.len() + FOOTER) else {
        return Ok(());
    };
    let footer = &file[footer_at..footer_at + FOOTER];
    let summary_start = le64(&footer[9..]);
    if footer[0] != 0x02 || summary_start == 0 {
        return Ok(());
    }
    let mut at = usize::try_from(summary_start)
        .ok()
        .filter(|&s| s <= footer_at)
        .ok_or_else(|| format!("starts at byte {summary_start}, past the footer"))?;
    while at + 9 <= footer_at {
        let (opcode, body) = mcap_record(&file[at..footer_at])
            .ok_or_else(|| format!("the record at byte {at} runs past the summary section"))?;
        let fits = match opcode {
            // Schema: id, name, encoding, data.
            0x03 => Fields(body)
                .skip(2)
                .and_then(|f| f.prefixed()?.prefixed()?.prefixed()),
            // Channel: id, schema id, topic, message encoding, metadata.
            0x04 => Fields(body)
                .skip(4)
                .and_then(|f| f.prefixed()?.prefixed()?.string_map()),
            _ => Some(Fields(body)),
        };
        if fits.is_none() {
            return Err(format!(
                "the record at byte {at} declares a field longer than the record"
            ));
        }
        at += 9 + body.len();
    }
    Ok(())
}

/// A chunk record's header fields, and its records (compressed or not), all checked to lie
/// within the record.
struct ChunkHeader<'a> {
    uncompressed_size: u64,
    uncompressed_crc: u32,
    compression: &'a [u8],
    records: &'a [u8],
}

/// The opcode and body of the MCAP record at the start of `bytes` (an opcode, a 64-bit
/// length, then the body); `None` when the header or the body runs past `bytes`.
fn mcap_record(bytes: &[u8]) -> Option<(u8, &[u8])> {
    let head = bytes.get(..9)?;
    let length = usize::try_from(u64::from_le_bytes(head[1..9].try_into().ok()?)).ok()?;
    Some((head[0], bytes.get(9..9usize.checked_add(length)?)?))
}

/// Reads the chunk record at the start of `record` (opcode and length first). The `mcap`
/// crate trusts the compression name's declared length, so it is checked here first, as the
/// summary's check does for schemas and channels.
fn mcap_chunk_header(record: &[u8]) -> Result<ChunkHeader<'_>, String> {
    let (_, body) = mcap_record(record).ok_or("the record runs past the file")?;
    let short = || "a field longer than the record".to_owned();
    // Start and end times, then the uncompressed size and CRC, then the compression's name.
    let fixed = body.get(..28).ok_or_else(short)?;
    let uncompressed_size = u64::from_le_bytes(fixed[16..24].try_into().expect("8 bytes"));
    let uncompressed_crc = u32::from_le_bytes(fixed[24..28].try_into().expect("4 bytes"));
    let name = Fields(body).skip(28).ok_or_else(short)?;
    let rest = name.prefixed().ok_or_else(short)?;
    let compression = &name.0[4..name.0.len() - rest.0.len()];
    let records = rest.0.get(..8).ok_or_else(short)?;
    let records = u64::from_le_bytes(records.try_into().expect("8 bytes"));
    let records = usize::try_from(records)
        .ok()
        .and_then(|n| rest.0.get(8..8usize.checked_add(n)?))
        .ok_or("its records run past the record")?;
    Ok(ChunkHeader {
        uncompressed_size,
        uncompressed_crc,
        compression,
        records,
    })
}

/// Checks that the chunk record at `offset` holds its compression name and its records.
fn check_mcap_chunk_header(file: &[u8], offset: u64) -> Result<(), String> {
    let at = usize::try_from(offset).map_err(|_| "past the file".to_owned())?;
    mcap_chunk_header(file.get(at..).ok_or("past the file")?).map(|_| ())
}

/// A message record's channel id, log time and data.
type McapMessage<'a> = (u16, u64, &'a [u8]);

/// A message record's fields; `None` for other records.
fn mcap_message(opcode: u8, data: &[u8]) -> Result<Option<McapMessage<'_>>, String> {
    if opcode != 0x05 {
        // Schemas and channels come from the summary; message indexes are not needed.
        return Ok(None);
    }
    // Channel id, sequence, log time, publish time, then the data.
    let header = data
        .get(..22)
        .ok_or("a message record shorter than its header")?;
    let channel = u16::from_le_bytes([header[0], header[1]]);
    let log_time = u64::from_le_bytes(header[6..14].try_into().expect("8 bytes"));
    Ok(Some((channel, log_time, &data[22..])))
}

/// Calls `f(channel id, log time, data)` for each message of the MCAP chunk `index` points
/// at, in order, until `f` returns `false`. Only message records are read, by their fixed
/// header, not with `Summary::stream_chunk`: that one parses every record inside the chunk,
/// and its parser allocates a string's declared length (up to 4 GB) before checking the
/// record holds it. No record may claim more than its chunk holds. An uncompressed chunk's
/// records are walked here (the crate's sans-io reader subtracts an oversized record's length
/// from what remains of the chunk without a check, the fuzzer found); a compressed one's are
/// decompressed by that reader, which bounds each record by the uncompressed size. Chunk CRCs
/// are checked as `stream_chunk` checks them.
fn mcap_chunk_messages(
    map: &[u8],
    index: &mcap::records::ChunkIndex,
    mut f: impl FnMut(u16, u64, &[u8]) -> bool,
) -> Result<(), String> {
    let chunk = usize::try_from(index.chunk_start_offset)
        .ok()
        .zip(usize::try_from(index.chunk_length).ok())
        .and_then(|(start, length)| map.get(start..start.checked_add(length)?))
        .ok_or("the chunk index points past the file")?;
    let header = mcap_chunk_header(chunk)?;
    if header.compression.is_empty() {
        if header.uncompressed_crc != 0 {
            let calculated = crc32fast::hash(header.records);
            if calculated != header.uncompressed_crc {
                return Err(format!(
                    "bad chunk CRC: saved {}, calculated {calculated}",
                    header.uncompressed_crc
                ));
            }
        }
        let mut rest = header.records;
        while !rest.is_empty() {
            let (opcode, data) = mcap_record(rest).ok_or("a record runs past its chunk")?;
            rest = &rest[9 + data.len()..];
            if let Some((channel, log_time, data)) = mcap_message(opcode, data)?
                && !f(channel, log_time, data)
            {
                return Ok(());
            }
        }
        return Ok(());
    }
    // The reader also holds the chunk's own header and compressed data to this limit.
    let limit = usize::try_from(header.uncompressed_size)
        .unwrap_or(usize::MAX)
        .max(chunk.len());
    let mut reader = mcap::sans_io::LinearReader::new_with_options(
        mcap::sans_io::LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(limit),
    );
    let mut input = chunk;
    while let Some(event) = reader.next_event() {
        let need = match event.map_err(|e| e.to_string())? {
            mcap::sans_io::LinearReadEvent::ReadRequest(need) => need,
            mcap::sans_io::LinearReadEvent::Record { data, opcode } => {
                if let Some((channel, log_time, data)) = mcap_message(opcode, data)?
                    && !f(channel, log_time, data)
                {
                    return Ok(());
                }
                continue;
            }
        };
        let n = need.min(input.len());
        reader.insert(n).copy_from_slice(&input[..n]);
        reader.notify_read(n);
        input = &input[n..];
    }
    Ok(())
}

/// What is left of a record's body, read field by field.
#[derive(Clone, Copy)]
struct Fields<'a>(&'a [u8]);

impl<'a> Fields<'a> {
    fn skip(self, n: usize) -> Option<Fields<'a>> {
        self.0.get(n..).map(Fields)
    }

    /// Past a field of a 32-bit length and that many bytes (a string or bytes); `None` when
    /// the body does not hold them.
    fn prefixed(self) -> Option<Fields<'a>> {
        let length = u32::from_le_bytes(self.0.get(..4)?.try_into().ok()?) as usize;
        self.0.get(4 + length..).map(Fields)
    }

    /// Past a map of strings to strings (a 32-bit byte length, then key and value strings),
    /// each string held by the map.
    fn string_map(self) -> Option<Fields<'a>> {
        let length = u32::from_le_bytes(self.0.get(..4)?.try_into().ok()?) as usize;
        let mut entries = Fields(self.0.get(4..4 + length)?);
        while !entries.0.is_empty() {
            entries = entries.prefixed()?.prefixed()?;
        }
        self.0.get(4 + length..).map(Fields)
    }
}

impl Container {
    pub fn open(path: &Path) -> Result<(Self, Vec<Connection>), BagError> {
        let file = File::open(path).map_err(|e| invalid(path, format!("cannot open: {e}")))?;
        // SAFETY: the bag is only read; a bag rewritten by another process while mapped could
        // give wrong bytes (each record is still bounds-checked), never unsafety in this code.
        let map =
            unsafe { Mmap::map(&file) }.map_err(|e| invalid(path, format!("cannot map: {e}")))?;
        let (kind, connections) = if map.starts_with(ROS1_MAGIC) {
            Self::open_ros1(path, &map)?
        } else if map.starts_with(MCAP_MAGIC) {
            Self::open_mcap(path, map)?
        } else if map.starts_with(SQLITE_MAGIC) {
            sqlite_complete(&map).map_err(|m| invalid(path, m))?;
            drop(map);
            Self::open_sqlite(path)?
        } else {
            return Err(invalid(
                path,
                "neither a ROS 1 bag (#ROSBAG V2.0), nor MCAP, nor a ROS 2 SQLite (.db3) bag",
            ));
        };
        let path = path.to_owned();
        Ok((Self { path, kind }, connections))
    }

    fn open_ros1(path: &Path, map: &[u8]) -> Result<(Kind, Vec<Connection>), BagError> {
        // `rosbag` slices the file at the header's index position without checking it: a
        // file cut short (a recording killed, a copy interrupted) must be caught here.
        let index_pos = ros1_index_pos(map).map_err(|m| invalid(path, m))?;
        if index_pos == 0 {
            return Err(invalid(
                path,
                "the bag has no index (the recording did not finish); `rosbag reindex` repairs it",
            ));
        }
        if index_pos > map.len() as u64 {
            return Err(invalid(
                path,
                format!(
                    "truncated: the file has {} bytes but its index should start at byte \
                     {index_pos} (cut short while copying or recording?)",
                    map.len()
                ),
            ));
        }
        let bag = RosBag::new(path).map_err(|e| invalid(path, e.to_string()))?;
        let mut ids = BTreeMap::new();
        let mut connections = Vec::new();
        let mut chunks = Vec::new();
        for record in bag.index_records() {
            match record.map_err(|e| invalid(path, format!("index: {e}")))? {
                IndexRecord::Connection(c) => {
                    if let std::collections::btree_map::Entry::Vacant(e) = ids.entry(c.id) {
                        e.insert(connections.len());
                        connections.push(Connection {
                            topic: c.topic.to_owned(),
                            msg_type: c.tp.replace("/msg/", "/"),
                            wire: Some(Wire::Ros1),
                        });
                    }
                }
                IndexRecord::ChunkInfo(c) => chunks.push((c.chunk_pos, c.start_time, c.end_time)),
                IndexRecord::IndexData(_) => {}
            }
        }
        chunks.sort_unstable();
        let kind = Kind::Ros1 { bag, chunks, ids };
        Ok((kind, connections))
    }

    fn open_mcap(path: &Path, map: Mmap) -> Result<(Kind, Vec<Connection>), BagError> {
        if !map.ends_with(MCAP_MAGIC) {
            return Err(invalid(
                path,
                format!(
                    "truncated: {} bytes and no closing MCAP magic (cut short while copying or \
                     recording?)",
                    map.len()
                ),
            ));
        }
        check_mcap_summary_lengths(&map)
            .map_err(|m| invalid(path, format!("summary section: {m}")))?;
        let summary = mcap::Summary::read(&map)
            .map_err(|e| invalid(path, format!("summary section: {e}")))?
            .ok_or_else(|| {
                invalid(
                    path,
                    "no summary section (chunk index): written by a recorder that did not finish",
                )
            })?;
        for index in &summary.chunk_indexes {
            check_mcap_chunk_header(&map, index.chunk_start_offset).map_err(|m| {
                invalid(
                    path,
                    format!("chunk at byte {}: {m}", index.chunk_start_offset),
                )
            })?;
        }
        if summary.chunk_indexes.is_empty()
            && summary.stats.as_ref().is_some_and(|s| s.message_count > 0)
        {
            return Err(invalid(
                path,
                "messages outside chunks: only chunked MCAP files are read",
            ));
        }
        let mut channel_ids: Vec<u16> = summary.channels.keys().copied().collect();
        channel_ids.sort_unstable();
        let connections = channel_ids
            .iter()
            .map(|id| {
                let c = &summary.channels[id];
                let msg_type = c
                    .schema
                    .as_ref()
                    .map(|s| s.name.replace("/msg/", "/"))
                    .unwrap_or_default();
                Connection {
                    topic: c.topic.clone(),
                    msg_type,
                    wire: (c.message_encoding == "cdr").then_some(Wire::Cdr),
                }
            })
            .collect();
        let ids = channel_ids
            .iter()
            .enumerate()
            .map(|(i, &c)| (c, i))
            .collect();
        let kind = Kind::Mcap {
            map,
            summary: Box::new(summary),
            ids,
        };
        Ok((kind, connections))
    }

    /// A rosbag2 SQLite bag: a `topics` table (id, name, type, serialization_format) and a
    /// `messages` table (id, topic_id, timestamp, data).
    fn open_sqlite(path: &Path) -> Result<(Kind, Vec<Connection>), BagError> {
        let sql = |e: rusqlite::Error| invalid(path, format!("SQLite: {e}"));
        let db = rusqlite::Connection::open_with_flags(
            path,
            rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(sql)?;
        let mut rows: Vec<(i64, String, String, String)> = {
            let mut query = db
                .prepare("SELECT id, name, type, serialization_format FROM topics")
                .map_err(|e| {
                    invalid(
                        path,
                        format!("not a rosbag2 SQLite bag (no readable topics table): {e}"),
                    )
                })?;
            query
                .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
                .map_err(sql)?
                .collect::<Result<_, _>>()
                .map_err(sql)?
        };
        rows.sort();
        let connections = rows
            .iter()
            .map(|(_, topic, msg_type, format)| Connection {
                topic: topic.clone(),
                msg_type: msg_type.replace("/msg/", "/"),
                wire: (format == "cdr").then_some(Wire::Cdr),
            })
            .collect();
        let ids = rows.iter().enumerate().map(|(i, r)| (r.0, i)).collect();
        let kind = Kind::Sqlite {
            db: Mutex::new(db),
            ids,
        };
        Ok((kind, connections))
    }

    /// "ROS 1", "MCAP" or "SQLite".
    pub fn format(&self) -> &'static str {
        match self.kind {
            Kind::Ros1 { .. } => "ROS 1",
            Kind::Mcap { .. } => "MCAP",
            Kind::Sqlite { .. } => "SQLite",
        }
    }

    fn sqlite_error(&self, what: &str, e: rusqlite::Error) -> BagError {
        self.error(format!("SQLite: {what}: {e}"))
    }

    fn error(&self, message: impl Into<String>) -> BagError {
        invalid(&self.path, message)
    }

    /// Calls `f` on every message, chunk by chunk (file order, not necessarily time order).
    pub fn scan(
        &self,
        f: &mut dyn FnMut(Message<'_>) -> Result<(), BagError>,
    ) -> Result<(), BagError> {
        match &self.kind {
            Kind::Ros1 { bag, chunks, ids } => {
                for &(pos, start, end) in chunks {
                    let chunk = self.ros1_chunk(bag, pos, start, end)?;
                    for (ordinal, record) in chunk.messages().enumerate() {
                        let record = record.map_err(|e| {
                            self.error(format!(
                                "{}: record {ordinal}: {e}",
                                chunk_name(pos, start, end)
                            ))
                        })?;
                        if let MessageRecord::MessageData(m) = record {
                            let connection = *ids.get(&m.conn_id).ok_or_else(|| {
                                self.error(format!(
                                    "{}: message of unknown connection {}",
                                    chunk_name(pos, start, end),
                                    m.conn_id
                                ))
                            })?;
                            f(Message {
                                connection,
                                log_time: m.time,
                                data: m.data,
                                at: Locator {
                                    chunk: pos,
                                    ordinal: ordinal as u64,
                                },
                            })?;
                        }
                    }
                }
            }
            Kind::Mcap { map, summary, ids } => {
                for (i, index) in summary.chunk_indexes.iter().enumerate() {
                    let name = || {
                        chunk_name(
                            index.chunk_start_offset,
                            index.message_start_time,
                            index.message_end_time,
                        )
                    };
                    let mut ordinal = 0u64;
                    let mut failed = None;
                    mcap_chunk_messages(map, index, |channel, log_time, data| {
                        let Some(&connection) = ids.get(&channel) else {
                            failed = Some(self.error(format!(
                                "{}: message {ordinal}: unknown channel {channel}",
                                name()
                            )));
                            return false;
                        };
                        let message = Message {
                            connection,
                            log_time,
                            data,
                            at: Locator {
                                chunk: i as u64,
                                ordinal,
                            },
                        };
                        ordinal += 1;
                        match f(message) {
                            Ok(()) => true,
                            Err(e) => {
                                failed = Some(e);
                                false
                            }
                        }
                    })
                    .map_err(|e| self.error(format!("{}: {e}", name())))?;
                    if let Some(e) = failed {
                        return Err(e);
                    }
                }
            }
            Kind::Sqlite { db, ids } => {
                let db = db.lock().unwrap_or_else(|p| p.into_inner());
                let mut query = db
                    .prepare("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id")
                    .map_err(|e| self.sqlite_error("messages table", e))?;
                let mut rows = query
                    .query([])
                    .map_err(|e| self.sqlite_error("messages table", e))?;
                loop {
                    let row = match rows.next() {
                        Ok(Some(row)) => row,
                        Ok(None) => break,
                        Err(e) => return Err(self.sqlite_error("reading messages", e)),
                    };
                    let fields = (|| -> rusqlite::Result<(i64, i64, i64, &[u8])> {
                        Ok((
                            row.get(0)?,
                            row.get(1)?,
                            row.get(2)?,
                            row.get_ref(3)?.as_blob()?,
                        ))
                    })();
                    let (id, topic, time, data) =
                        fields.map_err(|e| self.sqlite_error("a row of the messages table", e))?;
                    let connection = *ids.get(&topic).ok_or_else(|| {
                        self.error(format!(
                            "message {id} (at {} s) names unknown topic id {topic}",
                            crate::fmt_time(time)
                        ))
                    })?;
                    f(Message {
                        connection,
                        log_time: time.max(0) as u64,
                        data,
                        at: Locator {
                            chunk: 0,
                            ordinal: id as u64,
                        },
                    })?;
                }
            }
        }
        Ok(())
    }

    /// Reads several messages, decompressing each chunk once (a frame's colour, depth and
    /// label images are often in one chunk, and a bz2 chunk takes tens of milliseconds):
    /// `f(i, payload)` for each `ats[i]`.
    pub fn read_many(
        &self,
        ats: &[Locator],
        f: &mut dyn FnMut(usize, &[u8]),
    ) -> Result<(), BagError> {
        let mut done = vec![false; ats.len()];
        for first in 0..ats.len() {
            if done[first] {
                continue;
            }
            let chunk = ats[first].chunk;
            let wanted: Vec<usize> = (first..ats.len())
                .filter(|&i| !done[i] && ats[i].chunk == chunk)
                .collect();
            let mut found = |ordinal: u64, data: &[u8]| {
                for &i in &wanted {
                    if ats[i].ordinal == ordinal {
                        done[i] = true;
                        f(i, data);
                    }
                }
            };
            let last = wanted.iter().map(|&i| ats[i].ordinal).max().unwrap_or(0) as usize;
            match &self.kind {
                Kind::Sqlite { db, .. } => {
                    let db = db.lock().unwrap_or_else(|p| p.into_inner());
                    let mut query = db
                        .prepare("SELECT data FROM messages WHERE id = ?1")
                        .map_err(|e| self.sqlite_error("messages table", e))?;
                    for &i in &wanted {
                        let id = ats[i].ordinal as i64;
                        let mut rows = query
                            .query([id])
                            .map_err(|e| self.sqlite_error("messages table", e))?;
                        if let Some(row) = rows
                            .next()
                            .map_err(|e| self.sqlite_error(&format!("message {id}"), e))?
                        {
                            let data = row
                                .get_ref(0)
                                .and_then(|v| Ok(v.as_blob()?))
                                .map_err(|e| self.sqlite_error(&format!("message {id}"), e))?;
                            found(id as u64, data);
                        }
                    }
                }
                Kind::Ros1 { bag, chunks, .. } => {
                    let Some(&(pos, start, end)) = chunks.iter().find(|c| c.0 == chunk) else {
                        break;
                    };
                    let records = self.ros1_chunk(bag, pos, start, end)?;
                    for (ordinal, record) in records.messages().enumerate().take(last + 1) {
                        match record {
                            Ok(MessageRecord::MessageData(m)) => found(ordinal as u64, m.data),
                            Ok(_) => {}
                            Err(e) => {
                                return Err(
                                    self.error(format!("{}: {e}", chunk_name(pos, start, end)))
                                );
                            }
                        }
                    }
                }
                Kind::Mcap { map, summary, .. } => {
                    let Some(index) = summary.chunk_indexes.get(chunk as usize) else {
                        break;
                    };
                    let mut ordinal = 0u64;
                    mcap_chunk_messages(map, index, |_, _, data| {
                        found(ordinal, data);
                        ordinal += 1;
                        ordinal <= last as u64
                    })
                    .map_err(|e| self.error(e.to_string()))?;
                }
            }
        }
        if let Some(i) = done.iter().position(|d| !d) {
            return Err(self.error(format!("no message at {:?} (the file changed?)", ats[i])));
        }
        Ok(())
    }

    fn ros1_chunk<'a>(
        &self,
        bag: &'a RosBag,
        pos: u64,
        start: u64,
        end: u64,
    ) -> Result<rosbag::record_types::Chunk<'a>, BagError> {
        let mut records = bag.chunk_records();
        let bad = |e: String| self.error(format!("{}: {e}", chunk_name(pos, start, end)));
        records.seek(pos).map_err(|e| bad(e.to_string()))?;
        match records.next() {
            Some(Ok(ChunkRecord::Chunk(chunk))) => Ok(chunk),
            Some(Ok(_)) => Err(bad("the index points at no chunk".into())),
            Some(Err(e)) => Err(bad(e.to_string())),
            None => Err(bad("past the end of the file".into())),
        }
    }
}

/// A chunk in error messages: where it is and the times of its messages.
fn chunk_name(pos: u64, start_ns: u64, end_ns: u64) -> String {
    format!(
        "chunk at byte {pos} (messages {} .. {} s)",
        crate::fmt_time(start_ns as i64),
        crate::fmt_time(end_ns as i64)
    )
}

/// Checks a SQLite file's length against the size its header states (page size × page count),
/// so that a bag cut short is called truncated instead of SQLite's "disk image is malformed" on
/// some later query. The stated size is only valid when the header's change counter matches its
/// "version valid for" field (SQLite's file format, section 1.3).
fn sqlite_complete(map: &[u8]) -> Result<(), String> {
    let be32 = |at: usize| -> Option<u32> {
        map.get(at..at + 4)
            .map(|b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (Some(page_size), Some(change), Some(pages), Some(valid_for)) = (
        map.get(16..18).map(|b| u16::from_be_bytes([b[0], b[1]])),
        be32(24),
        be32(28),
        be32(92),
    ) else {
        return Err(format!(
            "truncated: {} bytes, shorter than a SQLite header",
            map.len()
        ));
    };
    // A stored page size of 1 means 65536.
    let page_size = if page_size == 1 {
        65536
    } else {
        page_size as u64
    };
    let stated = page_size * pages as u64;
    if change == valid_for && pages > 0 && (map.len() as u64) < stated {
        return Err(format!(
            "truncated: the file has {} bytes but its SQLite header says {stated} \
             ({pages} pages of {page_size}); cut short while copying or recording?",
            map.len()
        ));
    }
    Ok(())
}

/// The `index_pos` field of a ROS 1 bag's header record.
fn ros1_index_pos(map: &[u8]) -> Result<u64, String> {
    let rest = &map[ROS1_MAGIC.len()..];
    let len = |b: &[u8]| -> Option<usize> {
        b.get(..4)
            .map(|x| u32::from_le_bytes([x[0], x[1], x[2], x[3]]) as usize)
    };
    let header_len = len(rest).ok_or("truncated: no bag header")?;
    let mut fields = rest
        .get(4..4 + header_len)
        .ok_or("truncated inside the bag header")?;
    while !fields.is_empty() {
        let n = len(fields).ok_or("malformed bag header")?;
        let field = fields.get(4..4 + n).ok_or("malformed bag header")?;
        if let Some(v) = field.strip_prefix(b"index_pos=") {
            let v: [u8; 8] = v.try_into().map_err(|_| "malformed index_pos")?;
            return Ok(u64::from_le_bytes(v));
        }
        fields = &fields[4 + n..];
    }
    Err("the bag header has no index_pos".into())
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::{MCAP_MAGIC, check_mcap_summary_lengths, mcap_chunk_messages};

    /// An MCAP file of its magic, a summary section holding one channel record whose topic
    /// declares `topic_length` bytes (and holds `topic`), its footer and magic.
    fn mcap_with_channel(topic_length: u32, topic: &[u8], metadata: &[u8]) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend_from_slice(&1u16.to_le_bytes()); // channel id
        body.extend_from_slice(&0u16.to_le_bytes()); // schema id
        body.extend_from_slice(&topic_length.to_le_bytes());
        body.extend_from_slice(topic);
        body.extend_from_slice(&3u32.to_le_bytes());
        body.extend_from_slice(b"cdr");
        body.extend_from_slice(&(metadata.len() as u32).to_le_bytes());
        body.extend_from_slice(metadata);
        let mut file = MCAP_MAGIC.to_vec();
        let summary_start = file.len() as u64;
        file.push(0x04);
        file.extend_from_slice(&(body.len() as u64).to_le_bytes());
        file.extend_from_slice(&body);
        file.push(0x02);
        file.extend_from_slice(&20u64.to_le_bytes());
        file.extend_from_slice(&summary_start.to_le_bytes());
        file.extend_from_slice(&0u64.to_le_bytes());
        file.extend_from_slice(&0u32.to_le_bytes());
        file.extend_from_slice(MCAP_MAGIC);
        file
    }

    /// An uncompressed MCAP chunk record holding `records`, and its index.
    fn mcap_chunk(records: &[(u8, Vec<u8>)]) -> (Vec<u8>, mcap::records::ChunkIndex) {
        let mut inner = Vec::new();
        for (opcode, body) in records {
            inner.push(*opcode);
            inner.extend_from_slice(&(body.len() as u64).to_le_bytes());
            inner.extend_from_slice(body);
        }
        let mut body = Vec::new();
        body.extend_from_slice(&[0; 16]); // message start and end times
        body.extend_from_slice(&(inner.len() as u64).to_le_bytes()); // uncompressed size
        body.extend_from_slice(&0u32.to_le_bytes()); // no CRC
        body.extend_from_slice(&0u32.to_le_bytes()); // compression "": none
        body.extend_from_slice(&(inner.len() as u64).to_le_bytes());
        body.extend_from_slice(&inner);
        let mut file = MCAP_MAGIC.to_vec();
        let start = file.len() as u64;
        file.push(0x06);
        file.extend_from_slice(&(body.len() as u64).to_le_bytes());
        file.extend_from_slice(&body);
        let index = mcap::records::ChunkIndex {
            message_start_time: 0,
            message_end_time: 0,
            chunk_start_offset: start,
            chunk_length: file.len() as u64 - start,
            message_index_offsets: BTreeMap::new(),
            message_index_length: 0,
            compression: String::new(),
            compressed_size: inner.len() as u64,
            uncompressed_size: inner.len() as u64,
        };
        (file, index)
    }

    fn message_record(channel: u16, log_time: u64, data: &[u8]) -> (u8, Vec<u8>) {
        let mut body = channel.to_le_bytes().to_vec();
        body.extend_from_slice(&7u32.to_le_bytes()); // sequence
        body.extend_from_slice(&log_time.to_le_bytes());
        body.extend_from_slice(&log_time.to_le_bytes()); // publish time
        body.extend_from_slice(data);
        (0x05, body)
    }

    fn chunk_messages(
        file: &[u8],
        index: &mcap::records::ChunkIndex,
    ) -> Result<Vec<(u16, u64, Vec<u8>)>, String> {
        let mut out = Vec::new();
        mcap_chunk_messages(file, index, |c, t, d| {
            out.push((c, t, d.to_vec()));
            true
        })?;
        Ok(out)
    }

    #[test]
    fn chunk_records_are_read_without_trusting_their_strings() {
        // A schema inside the chunk whose name declares 4 GB in a 10-byte record: the mcap
        // crate's parser would allocate the declared length; the messages around it are read.
        let mut schema = 1u16.to_le_bytes().to_vec();
        schema.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        schema.extend_from_slice(b"ros");
        let records = [
            message_record(1, 10, b"first"),
            (0x03, schema),
            message_record(2, 20, b"second"),
        ];
        let (file, index) = mcap_chunk(&records);
        let read = chunk_messages(&file, &index).unwrap();
        assert_eq!(
            read,
            [(1, 10, b"first".to_vec()), (2, 20, b"second".to_vec())]
        );
        // Stopping early reads no more.
        let mut seen = 0;
        mcap_chunk_messages(&file, &index, |_, _, _| {
            seen += 1;
            false
        })
        .unwrap();
        assert_eq!(seen, 1);
    }

    #[test]
    fn chunk_records_longer_than_the_chunk_are_refused() {
        // A record inside declaring 4 GB: refused by the chunk's own size, not allocated.
        let (mut file, index) = mcap_chunk(&[message_record(1, 10, b"data")]);
        let at = index.chunk_start_offset as usize + 9 + 36 + 1;
        file[at..at + 8].copy_from_slice(&0xFFFF_FFF0u64.to_le_bytes());
        assert!(chunk_messages(&file, &index).is_err());
        // A record declaring more than is left of its chunk, though less than the chunk's
        // size (the mcap crate's reader subtracted it from what remained, and overflowed).
        let (mut file, index) = mcap_chunk(&[
            message_record(1, 10, b"data"),
            message_record(2, 20, b"more"),
        ]);
        let second = index.chunk_start_offset as usize + 9 + 36 + 9 + 26 + 1;
        file[second..second + 8].copy_from_slice(&30u64.to_le_bytes());
        let e = chunk_messages(&file, &index).unwrap_err();
        assert!(e.contains("past its chunk"), "{e}");
        // A message record too short for its header.
        let (file, index) = mcap_chunk(&[(0x05, vec![1, 0, 7])]);
        let e = chunk_messages(&file, &index).unwrap_err();
        assert!(e.contains("shorter than its header"), "{e}");
        // A chunk whose records do not match its CRC (0 means none was written).
        let (mut file, index) = mcap_chunk(&[message_record(1, 10, b"data")]);
        let at = index.chunk_start_offset as usize + 9 + 24;
        file[at..at + 4].copy_from_slice(&0x1234_5678u32.to_le_bytes());
        let e = chunk_messages(&file, &index).unwrap_err();
        assert!(e.to_lowercase().contains("crc"), "{e}");
        // An index pointing past the file.
        let (file, mut index) = mcap_chunk(&[message_record(1, 10, b"data")]);
        index.chunk_length += 1;
        let e = chunk_messages(&file, &index).unwrap_err();
        assert!(e.contains("past the file"), "{e}");
    }

    #[test]
    fn compressed_chunks_are_read_through_the_crates_reader() {
        for compression in [mcap::Compression::Zstd, mcap::Compression::Lz4] {
            let mut out = std::io::Cursor::new(Vec::new());
            let mut writer = mcap::WriteOptions::new()
                .compression(Some(compression))
                .chunk_size(Some(64))
                .create(&mut out)
                .unwrap();
            let channel = writer
                .add_channel(0, "/t", "cdr", &BTreeMap::new())
                .unwrap();
            for i in 0..10u64 {
                let header = mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: i as u32,
                    log_time: i,
                    publish_time: i,
                };
                writer
                    .write_to_known_channel(&header, &[i as u8; 40])
                    .unwrap();
            }
            writer.finish().unwrap();
            drop(writer);
            let file = out.into_inner();
            let summary = mcap::Summary::read(&file).unwrap().unwrap();
            assert!(summary.chunk_indexes.len() > 1, "{compression:?}");
            let mut read = Vec::new();
            for index in &summary.chunk_indexes {
                assert!(!index.compression.is_empty());
                read.extend(chunk_messages(&file, index).unwrap());
            }
            let expected: Vec<_> = (0..10u64)
                .map(|i| (channel, i, vec![i as u8; 40]))
                .collect();
            assert_eq!(read, expected, "{compression:?}");
        }
    }

    #[test]
    fn summary_strings_longer_than_their_record_are_refused() {
        let entry = |key: &[u8], value_length: u32, value: &[u8]| {
            let mut m = (key.len() as u32).to_le_bytes().to_vec();
            m.extend_from_slice(key);
            m.extend_from_slice(&value_length.to_le_bytes());
            m.extend_from_slice(value);
            m
        };
        let good = entry(b"offered_qos_profiles", 2, b"[]");
        assert_eq!(
            check_mcap_summary_lengths(&mcap_with_channel(4, b"/tf_", &good)),
            Ok(())
        );
        // A topic that claims 4 GB, and a metadata value that runs past its map.
        for file in [
            mcap_with_channel(0xFFFF_FFF0, b"/tf_", &good),
            mcap_with_channel(4, b"/tf_", &entry(b"k", 0xFFFF_FFF0, b"v")),
        ] {
            let err = check_mcap_summary_lengths(&file).unwrap_err();
            assert!(err.contains("longer than the record"), "{err}");
        }
    }
}
