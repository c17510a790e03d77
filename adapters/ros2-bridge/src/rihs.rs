//! RIHS01 type hashes, computed as ROS 2 computes them (REP 2011; rosidl's
//! `rosidl_generator_type_description`): SHA-256 of a JSON text of the type's description and
//! of every type it nests, defaults, constants and comments left out.
//!
//! The JSON is `{"type_description": T, "referenced_type_descriptions": [R…]}`, each type
//! `{"type_name": …, "fields": [{"name": …, "type": {"type_id": …, "capacity": …,
//! "string_capacity": …, "nested_type_name": …}}…]}` in exactly that key order, with Python's
//! default separators (", " and ": "); the nested types once each, sorted by name.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::msgs::{Shape, Ty, TypeDesc};

/// The type's RIHS01 hash: `RIHS01_` and 64 lowercase hex digits.
pub fn rihs01(t: &'static TypeDesc) -> String {
    let json = description_json(t);
    let digest = ring::digest::digest(&ring::digest::SHA256, json.as_bytes());
    let mut s = String::with_capacity(7 + 64);
    s.push_str("RIHS01_");
    for b in digest.as_ref() {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// The JSON text the hash is taken of.
pub fn description_json(t: &'static TypeDesc) -> String {
    let mut nested = BTreeMap::new();
    collect(t, &mut nested);
    nested.remove(t.name);
    let mut s = String::from("{\"type_description\": ");
    individual(&mut s, t);
    s.push_str(", \"referenced_type_descriptions\": [");
    for (i, r) in nested.values().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        individual(&mut s, r);
    }
    s.push_str("]}");
    s
}

fn collect(t: &'static TypeDesc, into: &mut BTreeMap<&'static str, &'static TypeDesc>) {
    for f in t.fields {
        if let Ty::Nested(n) = f.ty
            && into.insert(n.name, n).is_none()
        {
            collect(n, into);
        }
    }
}

fn individual(s: &mut String, t: &TypeDesc) {
    let _ = write!(s, "{{\"type_name\": \"{}\", \"fields\": [", t.name);
    for (i, f) in t.fields.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        let (offset, capacity) = match f.shape {
            Shape::One => (0, 0),
            Shape::Array(n) => (48, n),
            Shape::Seq => (144, 0),
        };
        let nested = if let Ty::Nested(n) = f.ty { n.name } else { "" };
        let _ = write!(
            s,
            "{{\"name\": \"{}\", \"type\": {{\"type_id\": {}, \"capacity\": {capacity}, \"string_capacity\": 0, \"nested_type_name\": \"{nested}\"}}}}",
            f.name,
            f.ty.base_id() + offset,
        );
    }
    s.push_str("]}");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs;

    /// The hashes ROS 2 (Jazzy and later) gives these types, as the PyPI `rosbags` (0.11.9)
    /// computes them with `Typestore.hash_rihs01`; String's is also the one rmw_zenoh's
    /// `docs/design.md` shows in its key expression examples, Twist's the one in the ROS 2
    /// "Understanding topics" tutorial's `ros2 topic info --verbose`.
    #[test]
    fn hashes_are_the_ones_ros_2_computes() {
        for (t, want) in [
            (&msgs::STRING, "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"),
            (&msgs::BOOL, "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9"),
            (&msgs::HEADER, "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"),
            (&msgs::TIME, "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"),
            (&msgs::TWIST, "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"),
            (&msgs::TRANSFORM_STAMPED, "RIHS01_0a241f87d04668d94099cbb5ba11691d5ad32c2f29682e4eb5653424bd275206"),
            (&msgs::TF_MESSAGE, "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"),
            (&msgs::ODOMETRY, "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"),
            (&msgs::OCCUPANCY_GRID, "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7"),
            (&msgs::RANGE, "RIHS01_b42b62562e93cbfe9d42b82fe5994dfa3d63d7d5c90a317981703f7388adff3a"),
            (&msgs::LASER_SCAN, "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"),
            (&msgs::IMU, "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"),
            (&msgs::CLOCK, "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"),
        ] {
            assert_eq!(rihs01(t), want, "{}", t.name);
        }
    }

    #[test]
    fn the_json_is_ros_2s_text() {
        // rosidl's own text for std_msgs/msg/Bool, character for character.
        assert_eq!(
            description_json(&msgs::BOOL),
            "{\"type_description\": {\"type_name\": \"std_msgs/msg/Bool\", \"fields\": [{\"name\": \"data\", \"type\": {\"type_id\": 15, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}]}, \"referenced_type_descriptions\": []}"
        );
    }
}
