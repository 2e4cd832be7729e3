//! The one wire encoding of every [`Message`]: a protocol version byte followed by the
//! message in postcard (a compact, varint-based serde format). Decoding never panics on
//! arbitrary bytes; it says what was wrong.

use crate::msgs::Message;

/// Version of the wire format; bump on any incompatible change to [`Message`].
pub const PROTOCOL_VERSION: u8 = 1;

/// Why bytes could not be decoded into a message.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CodecError {
    /// No bytes at all.
    #[error("empty message: expected a version byte")]
    Empty,
    /// The sender speaks another version of the protocol.
    #[error("protocol version {found}, this build speaks {expected}")]
    Version {
        /// The version byte that arrived.
        found: u8,
        /// The version this build speaks.
        expected: u8,
    },
    /// The body is not a valid message.
    #[error("malformed message body: {0}")]
    Body(String),
    /// A valid message followed by extra bytes.
    #[error("{0} unexpected bytes after the message")]
    Trailing(usize),
}

/// Encodes a message for the wire.
pub fn encode(msg: &Message) -> Vec<u8> {
    let mut out = vec![PROTOCOL_VERSION];
    // Serialising an in-memory enum of plain data into a Vec cannot fail.
    postcard::to_io(msg, &mut out).expect("postcard serialisation into a Vec is infallible");
    out
}

/// Decodes bytes from the wire.
pub fn decode(bytes: &[u8]) -> Result<Message, CodecError> {
    let (&version, body) = bytes.split_first().ok_or(CodecError::Empty)?;
    if version != PROTOCOL_VERSION {
        return Err(CodecError::Version {
            found: version,
            expected: PROTOCOL_VERSION,
        });
    }
    let (msg, rest) =
        postcard::take_from_bytes::<Message>(body).map_err(|e| CodecError::Body(e.to_string()))?;
    if !rest.is_empty() {
        return Err(CodecError::Trailing(rest.len()));
    }
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{Header, LaserScan, TwistStamped};
    use crate::time::Time;
    use proptest::prelude::*;

    fn scan(ranges: Vec<f32>) -> Message {
        Message::LaserScan(LaserScan {
            header: Header {
                stamp: Time::from_ns(123_456_789),
                frame_id: "rover1/laser".into(),
            },
            angle_min_rad: -3.1,
            angle_max_rad: 3.1,
            angle_increment_rad: 0.017,
            range_min_m: 0.15,
            range_max_m: 12.0,
            ranges_m: ranges,
            ..Default::default()
        })
    }

    #[test]
    fn version_and_trailing_bytes_are_checked() {
        let mut bytes = encode(&scan(vec![1.0, f32::INFINITY]));
        assert_eq!(decode(&bytes), Ok(scan(vec![1.0, f32::INFINITY])));
        bytes.push(0);
        assert_eq!(decode(&bytes), Err(CodecError::Trailing(1)));
        bytes[0] = 9;
        assert!(matches!(
            decode(&bytes),
            Err(CodecError::Version { found: 9, .. })
        ));
        assert_eq!(decode(&[]), Err(CodecError::Empty));
        let truncated = &encode(&scan(vec![1.0; 10]))[..20];
        assert!(matches!(decode(truncated), Err(CodecError::Body(_))));
    }

    #[test]
    fn encoding_is_compact() {
        // 360 f32 ranges dominate a scan; overhead beyond them stays small.
        let bytes = encode(&scan(vec![2.5; 360]));
        assert!(bytes.len() < 360 * 4 + 64, "{} bytes", bytes.len());
        let cmd = encode(&Message::CmdVel(TwistStamped::default()));
        assert!(cmd.len() < 60, "{} bytes", cmd.len());
    }

    #[test]
    fn the_landers_transforms_round_trip_in_a_few_dozen_bytes() {
        use crate::msgs::{MapTransform, MapTransforms};
        let msg = Message::MapTransforms(MapTransforms {
            header: Header {
                stamp: Time::from_ns(120_000_000_000),
                frame_id: "rover1/map".into(),
            },
            maps: vec![
                MapTransform {
                    child_frame_id: "rover2/map".into(),
                    pose: Some(crate::geometry::Point2::new(0.12, -0.36)),
                    yaw_rad: 0.012,
                    confidence: 0.98,
                    confirmed: true,
                },
                MapTransform {
                    child_frame_id: "rover3/map".into(),
                    pose: None,
                    ..Default::default()
                },
            ],
        });
        let bytes = encode(&msg);
        assert_eq!(decode(&bytes), Ok(msg));
        assert!(bytes.len() < 120, "{} bytes", bytes.len());
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = decode(&bytes);
            let mut versioned = bytes.clone();
            versioned.insert(0, PROTOCOL_VERSION);
            let _ = decode(&versioned);
        }

        #[test]
        fn scans_round_trip(ranges in proptest::collection::vec(0.0f32..20.0, 0..400)) {
            let msg = scan(ranges);
            prop_assert_eq!(decode(&encode(&msg)), Ok(msg));
        }
    }
}
