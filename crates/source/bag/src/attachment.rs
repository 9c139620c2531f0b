//! The attachment rmw_zenoh puts on every sample (sequence number, source timestamp, publisher
//! id): read from anyone on the network, so it lives beside the other inbound decoders.

/// The metadata every sample carries; rmw_zenoh drops a sample without it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Attachment {
    /// Per publisher, from 1.
    pub sequence: i64,
    /// When it was published, nanoseconds since the Unix epoch.
    pub timestamp_ns: i64,
    pub publisher_id: [u8; 16],
}

/// The attachment's length in rmw_zenoh's current layout.
pub const ATTACHMENT_LEN: usize = 33;

impl Attachment {
    /// zenoh's serializer on (i64, i64, [u8; 16]): two little-endian integers, then the array
    /// as a LEB128 length (16 = one byte 0x10) and its bytes.
    pub fn to_bytes(&self) -> [u8; ATTACHMENT_LEN] {
        let mut out = [0u8; ATTACHMENT_LEN];
        out[..8].copy_from_slice(&self.sequence.to_le_bytes());
        out[8..16].copy_from_slice(&self.timestamp_ns.to_le_bytes());
        out[16] = 16;
        out[17..].copy_from_slice(&self.publisher_id);
        out
    }

    /// Reads the current layout and the one rmw_zenoh Jazzy 0.2.0-0.2.3 sent (each field
    /// preceded by its name as a length-prefixed string).
    pub fn parse(bytes: &[u8]) -> Result<Attachment, String> {
        if bytes.len() == ATTACHMENT_LEN && bytes[16] == 16 {
            let i64_at =
                |at: usize| i64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
            let mut publisher_id = [0u8; 16];
            publisher_id.copy_from_slice(&bytes[17..]);
            return Ok(Attachment {
                sequence: i64_at(0),
                timestamp_ns: i64_at(8),
                publisher_id,
            });
        }
        let mut rest = bytes;
        let mut field = |name: &str, len: usize| take_field(&mut rest, name, len);
        let sequence = i64::from_le_bytes(field("sequence_number", 8)?.try_into().expect("8"));
        let timestamp_ns = i64::from_le_bytes(field("source_timestamp", 8)?.try_into().expect("8"));
        let gid = field("source_gid", 17)?;
        if gid[0] != 16 {
            return Err(format!(
                "attachment: a source_gid of {} bytes, not 16",
                gid[0]
            ));
        }
        let mut publisher_id = [0u8; 16];
        publisher_id.copy_from_slice(&gid[1..]);
        if !rest.is_empty() {
            return Err(format!("attachment: {} bytes after its fields", rest.len()));
        }
        Ok(Attachment {
            sequence,
            timestamp_ns,
            publisher_id,
        })
    }
}

/// One `name`d field of the old attachment layout: the name as a length-prefixed string, then
/// `len` bytes of value.
fn take_field<'a>(rest: &mut &'a [u8], name: &str, len: usize) -> Result<&'a [u8], String> {
    let cur: &'a [u8] = rest;
    let key_len = *cur.first().ok_or("attachment cut short")? as usize;
    let key = cur.get(1..1 + key_len).ok_or("attachment cut short")?;
    if key != name.as_bytes() {
        return Err(format!(
            "attachment: expected field {name:?}, found {:?}",
            String::from_utf8_lossy(key)
        ));
    }
    let value = cur
        .get(1 + key_len..1 + key_len + len)
        .ok_or("attachment cut short")?;
    *rest = &cur[1 + key_len + len..];
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attachments_round_trip_in_both_layouts() {
        let a = Attachment {
            sequence: 7,
            timestamp_ns: 1_234_567_890_123_456_789,
            publisher_id: std::array::from_fn(|i| i as u8 * 3),
        };
        assert_eq!(Attachment::parse(&a.to_bytes()).unwrap(), a);
        let mut old = Vec::new();
        for (name, value) in [
            ("sequence_number", a.sequence.to_le_bytes().to_vec()),
            ("source_timestamp", a.timestamp_ns.to_le_bytes().to_vec()),
            ("source_gid", [&[16u8][..], &a.publisher_id].concat()),
        ] {
            old.push(name.len() as u8);
            old.extend_from_slice(name.as_bytes());
            old.extend_from_slice(&value);
        }
        assert_eq!(old.len(), 77);
        assert_eq!(Attachment::parse(&old).unwrap(), a);
        assert!(Attachment::parse(&old[..50]).is_err());
        assert!(Attachment::parse(&[0u8; 12]).is_err());
    }
}
