//! The `rosbag2` metadata record a bag ends with: rosbag2's
//! `rosbag2_bagfile_information` (what `metadata.yaml` holds beside a bag)
//! as YAML under the key `serialized_metadata`, as rosbag2's MCAP plugin
//! and rosbags write it. It names the bag format's version, 8, which tells
//! a reader how to read `offered_qos_profiles` (version 8: rmw's numeric
//! enums; 9 spells them out): without it a reader of version 9 may take
//! the numbers for names it does not know.

use super::Qos;
use crate::ros2msg::TypeName;

/// The bag format version (Humble's, Iron's; Jazzy reads it).
pub const BAG_VERSION: u32 = 8;
/// The metadata record's name and key.
pub const RECORD: &str = "rosbag2";
pub const KEY: &str = "serialized_metadata";

/// A channel of the bag and its messages so far.
pub(super) struct Declared {
    pub id: u16,
    pub topic: String,
    pub type_name: TypeName,
    pub qos: Qos,
    /// Its keep-last depth.
    pub depth: u32,
    pub count: u64,
}

/// A string as a YAML scalar: JSON's double-quoted form is YAML's.
fn quoted(s: &str) -> String {
    serde_json::Value::from(s).to_string()
}

/// The YAML of `rosbag2_bagfile_information` (its inner mapping, as the
/// plugin stores it) for the file `file` holding `topics`, its messages'
/// log times from `first` to `last` (nanoseconds).
pub(super) fn serialized_metadata(
    file: &str,
    topics: &[Declared],
    span: Option<(u64, u64)>,
) -> String {
    let (start, duration) = span.map_or((0, 0), |(a, b)| (a, b.saturating_sub(a)));
    let count: u64 = topics.iter().map(|t| t.count).sum();
    let file = quoted(file);
    let mut y = format!(
        "version: {BAG_VERSION}\nstorage_identifier: mcap\nrelative_file_paths:\n- {file}\n\
         duration:\n  nanoseconds: {duration}\nstarting_time:\n  nanoseconds_since_epoch: {start}\n\
         message_count: {count}\ntopics_with_message_count:\n"
    );
    for t in topics {
        y.push_str(&format!(
            "- topic_metadata:\n    name: {}\n    type: {}\n    serialization_format: cdr\n    \
             offered_qos_profiles: {}\n    type_description_hash: ''\n  message_count: {}\n",
            quoted(&t.topic),
            quoted(&t.type_name.ros()),
            quoted(&t.qos.offered_profiles(t.depth)),
            t.count
        ));
    }
    y.push_str(&format!(
        "compression_format: ''\ncompression_mode: ''\nfiles:\n- path: {file}\n  starting_time:\n    \
         nanoseconds_since_epoch: {start}\n  duration:\n    nanoseconds: {duration}\n  message_count: {count}\n\
         custom_data: null\nros_distro: lightpose"
    ));
    y
}
