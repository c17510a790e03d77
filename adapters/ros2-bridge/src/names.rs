//! rmw_zenoh's names on the wire (its `docs/design.md`, rolling, and `liveliness_utils.cpp`):
//! the key expression a topic's samples travel on, the liveliness tokens that make nodes,
//! publishers and subscriptions visible to `ros2 node list` / `ros2 topic list`, the QoS those
//! tokens carry, and the attachment every sample carries.

use std::fmt::Write as _;

use crate::msgs::TypeDesc;
use crate::rihs::rihs01;

/// The liveliness tokens' key space.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// A topic's key expression: `<domain>/<fully qualified name without its outer
/// slashes>/<type in its dds_ form>/<RIHS01 hash>`; the name's inner slashes stay.
pub fn data_key(domain: u32, topic: &str, ty: &'static TypeDesc) -> String {
    format!("{domain}/{}/{}/{}", topic.trim_start_matches('/').trim_end_matches('/'), ty.dds_name(), rihs01(ty))
}

/// A name as a token writes it: every `/` replaced by `%`; an empty name (the root
/// namespace, no enclave) as `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() { "%".to_owned() } else { name.replace('/', "%") }
}

/// Reliability, as `rmw_qos_reliability_policy_e` numbers it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// Every sample is delivered (rmw_zenoh's default).
    Reliable = 1,
    /// Samples may be lost (sensor data, `/clock`).
    BestEffort = 2,
}

/// Durability, as `rmw_qos_durability_policy_e` numbers it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// A late subscriber gets the publisher's last `depth` samples (`/map`, `/tf_static`).
    TransientLocal = 1,
    /// Only what is published after it subscribed (rmw_zenoh's default).
    Volatile = 2,
}

/// The QoS of a keep-last publisher or subscription with infinite deadline, lifespan and
/// lease (what a base driver uses).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliable or best effort.
    pub reliability: Reliability,
    /// Volatile or transient-local.
    pub durability: Durability,
    /// Keep the last `depth` samples.
    pub depth: u32,
}

/// rmw_zenoh's default depth (`qos.cpp`): a field equal to it is left empty in a token.
pub const DEFAULT_DEPTH: u32 = 42;

impl Qos {
    /// rclcpp's `QoS(depth)`: reliable, volatile.
    pub const fn reliable(depth: u32) -> Self {
        Self { reliability: Reliability::Reliable, durability: Durability::Volatile, depth }
    }

    /// `rmw_qos_profile_sensor_data` with `depth`: best effort, volatile.
    pub const fn sensor_data(depth: u32) -> Self {
        Self { reliability: Reliability::BestEffort, durability: Durability::Volatile, depth }
    }

    /// A latched topic (`/map`, `/tf_static`): reliable, transient-local.
    pub const fn latched(depth: u32) -> Self {
        Self { reliability: Reliability::Reliable, durability: Durability::TransientLocal, depth }
    }

    /// The token's QoS field (`qos_to_keyexpr`):
    /// `<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>`,
    /// each value written only where it differs from rmw_zenoh's default (reliable,
    /// volatile, keep-last 42, infinite times, automatic liveliness).
    pub fn key(&self) -> String {
        let mut s = String::new();
        if self.reliability != Reliability::Reliable {
            let _ = write!(s, "{}", self.reliability as u8);
        }
        s.push(':');
        if self.durability != Durability::Volatile {
            let _ = write!(s, "{}", self.durability as u8);
        }
        s.push_str(":,");
        if self.depth != DEFAULT_DEPTH {
            let _ = write!(s, "{}", self.depth);
        }
        s.push_str(":,:,:,,");
        s
    }
}

/// What an entity token says an entity is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    /// A message publisher.
    Publisher,
    /// A message subscription.
    Subscription,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// A ROS 2 node as the graph knows it: its Zenoh session, id, namespace and name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// The Zenoh session's id as Zenoh prints it (lowercase hex, no leading zeros).
    pub zid: String,
    /// The node's id within its session.
    pub id: u32,
    /// Its namespace (`/` or `/chair1`).
    pub namespace: String,
    /// Its name.
    pub name: String,
}

impl Node {
    fn prefix(&self, entity: u32, kind: &str) -> String {
        // The enclave is SROS's; none here, so "%" as rcl's default "/" mangles to.
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{entity}/{kind}/%/{}/{}",
            self.domain,
            self.zid,
            self.id,
            mangle(if self.namespace == "/" { "" } else { &self.namespace }),
            self.name
        )
    }

    /// The node's token (kind `NN`, its id twice).
    pub fn token(&self) -> String {
        self.prefix(self.id, "NN")
    }

    /// The token of the node's publisher or subscription `entity` on `topic` (fully qualified).
    pub fn entity_token(&self, entity: u32, kind: EntityKind, topic: &str, ty: &'static TypeDesc, qos: Qos) -> String {
        format!("{}/{}/{}/{}/{}", self.prefix(entity, kind.code()), mangle(topic), ty.dds_name(), rihs01(ty), qos.key())
    }
}

/// A publisher's id, as rmw_zenoh derives it: XXH3-128 of its token, low half first.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// The attachment rmw_zenoh requires on every sample (a subscriber drops one without it):
/// the publisher's sequence number and the source time (ns since the Unix epoch), each an
/// `i64` little-endian, then the id's length (16) and the id, as zenoh-ext's serializer
/// writes the tuple `(i64, i64, [u8; 16])`.
pub fn attachment(seq: i64, time_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut a = [0u8; 33];
    a[..8].copy_from_slice(&seq.to_le_bytes());
    a[8..16].copy_from_slice(&time_ns.to_le_bytes());
    a[16] = 16;
    a[17..].copy_from_slice(gid);
    a
}

/// The key of the query a transient-local (zenoh-ext advanced) publisher answers from its
/// cache, and of the token that tells late subscribers it is there:
/// `<data key>/@adv/pub/<zid>/<entity>/_`.
pub fn cache_key(data_key: &str, zid: &str, entity: u32) -> String {
    format!("{data_key}/@adv/pub/{zid}/{entity}/_")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::STRING;

    // The goldens below are rmw_zenoh's `docs/design.md` (rolling, 99a6a2bd), sections "Topic
    // and Service name mapping to Zenoh key expressions" and "Graph Cache", character for
    // character.
    const HASH: &str = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";

    #[test]
    fn data_keys_are_design_mds() {
        assert_eq!(data_key(0, "/chatter", &STRING), format!("0/chatter/std_msgs::msg::dds_::String_/{HASH}"));
        assert_eq!(
            data_key(0, "/robot1/chatter", &STRING),
            format!("0/robot1/chatter/std_msgs::msg::dds_::String_/{HASH}")
        );
    }

    #[test]
    fn tokens_are_design_mds() {
        let listener = Node {
            domain: 2,
            zid: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
            id: 0,
            namespace: "/".into(),
            name: "listener".into(),
        };
        assert_eq!(listener.token(), "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener");
        assert_eq!(
            listener.entity_token(10, EntityKind::Subscription, "/chatter", &STRING, Qos::reliable(10)),
            format!(
                "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/{HASH}/::,10:,:,:,,"
            )
        );
        let talker = Node { zid: "8b20917502ee955ac4476e0266340d5c".into(), name: "talker".into(), ..listener };
        let token = talker.entity_token(10, EntityKind::Publisher, "/chatter", &STRING, Qos::reliable(7));
        assert_eq!(
            token,
            format!(
                "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{HASH}/::,7:,:,:,,"
            )
        );
        // Its id, as rmw_zenoh's own XXH3 code computes it from that token.
        assert_eq!(
            gid(&token),
            [0xac, 0x17, 0x0f, 0x31, 0xea, 0xdc, 0xd9, 0xff, 0x0c, 0xd8, 0x6d, 0x7a, 0x17, 0x90, 0x7d, 0x1c]
        );
    }

    #[test]
    fn namespaces_and_qos_are_written_as_rmw_zenoh_writes_them() {
        let node = Node { domain: 0, zid: "1".into(), id: 3, namespace: "/chair1".into(), name: "iwsim".into() };
        assert_eq!(node.token(), "@ros2_lv/0/1/3/3/NN/%/%chair1/iwsim");
        assert_eq!(Qos::latched(1).key(), ":1:,1:,:,:,,");
        assert_eq!(Qos::sensor_data(5).key(), "2::,5:,:,:,,");
        assert_eq!(Qos::reliable(DEFAULT_DEPTH).key(), "::,:,:,:,,");
        assert_eq!(Qos::reliable(100).key(), "::,100:,:,:,,");
    }

    #[test]
    fn the_attachment_is_zenoh_exts_serialization_of_the_tuple() {
        let gid = [0xac, 0x17, 0x0f, 0x31, 0xea, 0xdc, 0xd9, 0xff, 0x0c, 0xd8, 0x6d, 0x7a, 0x17, 0x90, 0x7d, 0x1c];
        let a = attachment(1, 1_700_000_000_000_000_000, &gid);
        let want = [
            0x01, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x2a, 0x36, 0xfe, 0x9c, 0x97, 0x17, 0x10, 0xac, 0x17, 0x0f, 0x31,
            0xea, 0xdc, 0xd9, 0xff, 0x0c, 0xd8, 0x6d, 0x7a, 0x17, 0x90, 0x7d, 0x1c,
        ];
        assert_eq!(a, want);
    }
}
