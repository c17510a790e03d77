//! The payloads of a session carried to agents on other machines (by the Zenoh bridge): the
//! same fixed-layout bytes as in shared memory, a header followed by its items, so nothing is
//! parsed on either side. Only the key expressions and the framing live here; neither side's
//! transport does.
//!
//! Key space, under a prefix (`iwsim/<session>` unless the bridge is told otherwise):
//!
//! | key | what | payload |
//! |---|---|---|
//! | `P/register` | queryable: hello, robot, ready, goodbye | [`RegisterRequest`] → [`RegisterResponse`] |
//! | `P/map` | queryable: the agents' map | → [`MapHeader`] + [`MapItem`]s |
//! | `P/agent/<id>/sensors` | the bridge puts, each tick | [`TickHeader`] + [`SensorBlock`]s |
//! | `P/agent/<id>/actions` | the agent puts | [`ActionHeader`] + [`ActionBlock`]s |
//! | `P/agent/<id>/alive` | the agent's liveliness token | — |
//! | `P/bridge/<instance>` | the bridge's liveliness token, one instance per run | — |
//! | `P/observe/world` | the bridge puts, each tick (`--observers world`) | [`WorldHeader`] + [`RobotState`]s |
//! | `P/observe/robots` | the bridge puts when they change; queryable | `u64` count + [`RobotInfo`]s |
//! | `P/observe/map` | queryable: the observers' map | → [`MapHeader`] + [`MapItem`]s |
//!
//! The `observe` keys carry the truth (every robot's true pose, the scenario's obstacles): for
//! a remote viewer, recorder or referee, never for an agent. A bridge serves them only when
//! told to (`iwsim zenoh --observers world`); whoever may reach its Zenoh endpoint may then
//! read them, so a bridge whose agents are under test keeps them off, or keeps its endpoint
//! to trusted hosts (see Zenoh's access control).
//!
//! An agent's id is tied to the Zenoh session that said hello for it, as the hub ties it to
//! the iceoryx2 port that did: the bridge answers a hello with a random secret of
//! [`SECRET_LEN`] bytes as the reply's attachment (a reply goes to the querier only), and every
//! later request and actions payload of that agent carries it as its attachment. One without
//! it, or with another agent's, is counted as foreign and dropped.
//!
//! The layouts' versions are checked once, at hello: the request carries [`schema`] as its
//! attachment and a bridge built with other layouts refuses it. Every payload after that is
//! checked for its size (see [`unframe`]).

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use core::mem::size_of;

use bytemuck::Pod;

use crate::{
    ActionBlock, ActionHeader, MapHeader, MapItem, RegisterRequest, RegisterResponse, RobotInfo, RobotState,
    SensorBlock, TickHeader, WorldHeader, type_name_of,
};

/// Bytes of an agent's secret (see the module's documentation).
pub const SECRET_LEN: usize = 16;

/// The default key prefix of a session.
pub fn prefix(session: &str) -> String {
    format!("iwsim/{session}")
}

/// `P/register`: hello, robot registrations, ready and goodbye, as queries.
pub fn register_key(prefix: &str) -> String {
    format!("{prefix}/register")
}

/// `P/map`: the agents' map, as a query.
pub fn map_key(prefix: &str) -> String {
    format!("{prefix}/map")
}

/// `P/agent/<id>/sensors`: agent `id`'s sensor blocks, each tick.
pub fn sensors_key(prefix: &str, agent_id: u32) -> String {
    format!("{prefix}/agent/{agent_id}/sensors")
}

/// `P/agent/<id>/actions`: agent `id`'s actions.
pub fn actions_key(prefix: &str, agent_id: u32) -> String {
    format!("{prefix}/agent/{agent_id}/actions")
}

/// `P/agent/*/actions`: every agent's actions (the bridge's subscription).
pub fn all_actions_key(prefix: &str) -> String {
    format!("{prefix}/agent/*/actions")
}

/// `P/agent/<id>/alive`: agent `id`'s liveliness token, held for as long as it is there.
pub fn alive_key(prefix: &str, agent_id: u32) -> String {
    format!("{prefix}/agent/{agent_id}/alive")
}

/// `P/agent/*/alive`: every agent's liveliness token (the bridge's liveliness subscription).
pub fn all_alive_key(prefix: &str) -> String {
    format!("{prefix}/agent/*/alive")
}

/// `P/bridge/<instance>`: the liveliness token of one run of the bridge (`instance` drawn at
/// random when it starts); an agent that loses it has lost its hub, and one that sees another
/// instance's come knows the bridge was restarted and has forgotten it.
pub fn bridge_key(prefix: &str, instance: u64) -> String {
    format!("{prefix}/bridge/{instance:016x}")
}

/// `P/bridge/*`: every bridge instance's token (what agents watch).
pub fn all_bridges_key(prefix: &str) -> String {
    format!("{prefix}/bridge/*")
}

/// `P/observe/world`: every robot's true state, each tick (observers only).
pub fn observe_world_key(prefix: &str) -> String {
    format!("{prefix}/observe/world")
}

/// `P/observe/robots`: every robot's info (name, sensor geometry), put when it changes and
/// answered to queries (observers only).
pub fn observe_robots_key(prefix: &str) -> String {
    format!("{prefix}/observe/robots")
}

/// `P/observe/map`: the observers' map, as a query (observers only).
pub fn observe_map_key(prefix: &str) -> String {
    format!("{prefix}/observe/map")
}

/// The layouts an observer and the bridge must share: sent with an observer's first query
/// (for the observers' map).
pub fn observer_schema() -> String {
    [
        type_name_of::<WorldHeader>(),
        type_name_of::<RobotState>(),
        type_name_of::<RobotInfo>(),
        type_name_of::<MapHeader>(),
        type_name_of::<MapItem>(),
    ]
    .join(" ")
}

/// The default key prefix of an episode host (`iwsim env-host`).
pub const EPISODES_PREFIX: &str = "iwsim/episodes";

/// `E/start`: a query that starts an episode on the host (a lock-step hub of the scenario the
/// payload gives, one hub argument per line, and a bridge serving it with observers); the
/// answer is the new session's name.
pub fn episode_start_key(prefix: &str) -> String {
    format!("{prefix}/start")
}

/// `E/end`: a query that ends the episode whose session the payload names; the answer is the
/// hub's end-of-run summary (its `--json` line).
pub fn episode_end_key(prefix: &str) -> String {
    format!("{prefix}/end")
}

/// The agent id in a key `P/agent/<id>/…`, if the key is one.
pub fn agent_of_key(prefix: &str, key: &str) -> Option<u32> {
    let rest = key.strip_prefix(prefix)?.strip_prefix("/agent/")?;
    let (id, _) = rest.split_once('/')?;
    id.parse().ok()
}

/// The layouts both ends must share, by their versioned type names: sent with every hello.
pub fn schema() -> String {
    [
        type_name_of::<RegisterRequest>(),
        type_name_of::<RegisterResponse>(),
        type_name_of::<TickHeader>(),
        type_name_of::<SensorBlock>(),
        type_name_of::<ActionHeader>(),
        type_name_of::<ActionBlock>(),
        type_name_of::<MapHeader>(),
        type_name_of::<MapItem>(),
    ]
    .join(" ")
}

/// Why bytes from the network are not the payload they should be.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameError {
    /// Fewer bytes than the header.
    Short {
        /// Bytes received.
        len: usize,
        /// Bytes the header takes.
        header: usize,
    },
    /// The bytes after the header are not a whole number of items.
    Ragged {
        /// Bytes after the header.
        len: usize,
        /// Bytes one item takes.
        item: usize,
    },
    /// The header counts another number of items than follow it.
    Count {
        /// Items the header counts.
        said: usize,
        /// Items that follow.
        found: usize,
    },
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Short { len, header } => write!(f, "{len} bytes, shorter than its {header}-byte header"),
            Self::Ragged { len, item } => {
                write!(f, "{len} bytes after the header are not a whole number of {item}-byte items")
            }
            Self::Count { said, found } => write!(f, "the header counts {said} items but {found} follow"),
        }
    }
}

impl core::error::Error for FrameError {}

/// `header` followed by `items`, as one payload.
pub fn frame<H: Pod, T: Pod>(header: &H, items: &[T]) -> Vec<u8> {
    let mut out = Vec::with_capacity(size_of::<H>() + core::mem::size_of_val(items));
    out.extend_from_slice(bytemuck::bytes_of(header));
    out.extend_from_slice(bytemuck::cast_slice(items));
    out
}

/// A payload's header and items, copied out (network bytes need not be aligned). The header's
/// count is checked by the caller, who knows which field holds it (see [`check_count`]).
pub fn unframe<H: Pod, T: Pod>(bytes: &[u8]) -> Result<(H, Vec<T>), FrameError> {
    let header = size_of::<H>();
    if bytes.len() < header {
        return Err(FrameError::Short { len: bytes.len(), header });
    }
    let rest = &bytes[header..];
    let item = size_of::<T>();
    if !rest.len().is_multiple_of(item) {
        return Err(FrameError::Ragged { len: rest.len(), item });
    }
    let items = rest.chunks_exact(item).map(bytemuck::pod_read_unaligned).collect();
    Ok((bytemuck::pod_read_unaligned(&bytes[..header]), items))
}

/// Reads a payload of exactly one `T`.
pub fn one<T: Pod>(bytes: &[u8]) -> Result<T, FrameError> {
    if bytes.len() != size_of::<T>() {
        return Err(FrameError::Short { len: bytes.len(), header: size_of::<T>() });
    }
    Ok(bytemuck::pod_read_unaligned(bytes))
}

/// That a header's count of items matches the items that follow it.
pub fn check_count(said: u32, found: usize) -> Result<(), FrameError> {
    if said as usize == found { Ok(()) } else { Err(FrameError::Count { said: said as usize, found }) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString;
    use alloc::vec;

    #[test]
    fn a_framed_tick_comes_back_as_it_went() {
        let h = TickHeader { tick: 7, count: 2, ..Default::default() };
        let blocks = [
            SensorBlock { robot_id: 3, ..bytemuck::Zeroable::zeroed() },
            SensorBlock { robot_id: 4, ..bytemuck::Zeroable::zeroed() },
        ];
        let bytes = frame(&h, &blocks);
        assert_eq!(bytes.len(), 40 + 2 * size_of::<SensorBlock>());
        // Off by one byte: the network owes no alignment.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&bytes);
        let (h2, b2): (TickHeader, Vec<SensorBlock>) = unframe(&shifted[1..]).expect("whole");
        assert_eq!((h2, b2.iter().map(|b| b.robot_id).collect::<Vec<_>>()), (h, vec![3, 4]));
        assert_eq!(check_count(h2.count, b2.len()), Ok(()));
    }

    #[test]
    fn short_ragged_and_miscounted_payloads_say_what_is_wrong() {
        let h = ActionHeader { tick: 1, agent_id: 2, count: 3 };
        let bytes = frame(&h, &[ActionBlock::motors(5, 0.1, 0.2)]);
        assert_eq!(
            unframe::<ActionHeader, ActionBlock>(&bytes[..5]).map(|_| ()),
            Err(FrameError::Short { len: 5, header: size_of::<ActionHeader>() })
        );
        let e =
            unframe::<ActionHeader, ActionBlock>(&bytes[..bytes.len() - 1]).map(|_| ()).expect_err("one byte short");
        assert!(matches!(e, FrameError::Ragged { .. }), "{e}");
        let (h2, items) = unframe::<ActionHeader, ActionBlock>(&bytes).expect("well formed");
        assert_eq!(
            check_count(h2.count, items.len()).expect_err("3 said, 1 sent").to_string(),
            "the header counts 3 items but 1 follow"
        );
        assert!(one::<RegisterResponse>(&[0; 3]).is_err());
    }

    #[test]
    fn keys_name_the_agent_they_belong_to() {
        let p = prefix("lab");
        assert_eq!(actions_key(&p, 12), "iwsim/lab/agent/12/actions");
        assert_eq!(agent_of_key(&p, &actions_key(&p, 12)), Some(12));
        assert_eq!(agent_of_key(&p, &alive_key(&p, 4)), Some(4));
        assert_eq!(agent_of_key(&p, "iwsim/other/agent/4/alive"), None);
        assert_eq!(agent_of_key(&p, "iwsim/lab/agent/x/alive"), None);
        assert!(schema().contains("iwsim::SensorBlock.v5"), "{}", schema());
        assert_eq!(observe_world_key(&p), "iwsim/lab/observe/world");
        // An observer's key is no agent's: the bridge's action subscription never matches it.
        assert_eq!(agent_of_key(&p, &observe_world_key(&p)), None);
        assert!(observer_schema().contains("RobotState"), "{}", observer_schema());
    }
}
