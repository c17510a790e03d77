//! The ROS 2 messages a mobile base driver speaks, as Rust values that write themselves in
//! CDR, each with its type description (the fields in ROS 2's own order and types, Jazzy and
//! later), from which its RIHS01 hash is computed ([`crate::rihs`]).

use crate::cdr::{CdrError, Reader, Writer};

/// A field's element type, as `type_description_interfaces/msg/FieldType` numbers it.
#[derive(Debug, Clone, Copy)]
pub enum Ty {
    /// `int8`.
    Int8,
    /// `uint8` (a `.msg` `char` and `byte` too, as rosidl maps them).
    UInt8,
    /// `int32`.
    Int32,
    /// `uint32`.
    UInt32,
    /// `float32`.
    Float32,
    /// `float64`.
    Float64,
    /// `bool`.
    Bool,
    /// An unbounded `string`.
    String,
    /// Another message.
    Nested(&'static TypeDesc),
}

impl Ty {
    /// The `FieldType` id of a single value of this type.
    pub fn base_id(self) -> u32 {
        match self {
            Ty::Nested(_) => 1,
            Ty::Int8 => 2,
            Ty::UInt8 => 3,
            Ty::Int32 => 6,
            Ty::UInt32 => 7,
            Ty::Float32 => 10,
            Ty::Float64 => 11,
            Ty::Bool => 15,
            Ty::String => 17,
        }
    }
}

/// One value, a fixed array or an unbounded sequence.
#[derive(Debug, Clone, Copy)]
pub enum Shape {
    /// One value.
    One,
    /// `T[N]`.
    Array(u32),
    /// `T[]`.
    Seq,
}

/// A field of a message type.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// Its name.
    pub name: &'static str,
    /// Its element type.
    pub ty: Ty,
    /// One, an array or a sequence of them.
    pub shape: Shape,
}

/// A message type: its full name (`pkg/msg/Name`) and fields in declaration order.
#[derive(Debug)]
pub struct TypeDesc {
    /// `pkg/msg/Name`.
    pub name: &'static str,
    /// The fields, in order.
    pub fields: &'static [Field],
}

impl TypeDesc {
    /// The type's name as rmw_zenoh writes it in key expressions: `pkg::msg::dds_::Name_`.
    pub fn dds_name(&self) -> String {
        let mut parts = self.name.rsplitn(2, '/');
        let (name, ns) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
        format!("{}::dds_::{name}_", ns.replace('/', "::"))
    }
}

const fn one(name: &'static str, ty: Ty) -> Field {
    Field { name, ty, shape: Shape::One }
}

const fn array(name: &'static str, ty: Ty, n: u32) -> Field {
    Field { name, ty, shape: Shape::Array(n) }
}

const fn seq(name: &'static str, ty: Ty) -> Field {
    Field { name, ty, shape: Shape::Seq }
}

/// `builtin_interfaces/msg/Time`.
pub static TIME: TypeDesc =
    TypeDesc { name: "builtin_interfaces/msg/Time", fields: &[one("sec", Ty::Int32), one("nanosec", Ty::UInt32)] };
/// `std_msgs/msg/Header`.
pub static HEADER: TypeDesc =
    TypeDesc { name: "std_msgs/msg/Header", fields: &[one("stamp", Ty::Nested(&TIME)), one("frame_id", Ty::String)] };
/// `std_msgs/msg/Bool`.
pub static BOOL: TypeDesc = TypeDesc { name: "std_msgs/msg/Bool", fields: &[one("data", Ty::Bool)] };
/// `std_msgs/msg/String`.
pub static STRING: TypeDesc = TypeDesc { name: "std_msgs/msg/String", fields: &[one("data", Ty::String)] };
/// `rosgraph_msgs/msg/Clock`.
pub static CLOCK: TypeDesc = TypeDesc { name: "rosgraph_msgs/msg/Clock", fields: &[one("clock", Ty::Nested(&TIME))] };
const XYZ: [Field; 3] = [one("x", Ty::Float64), one("y", Ty::Float64), one("z", Ty::Float64)];
/// `geometry_msgs/msg/Vector3`.
pub static VECTOR3: TypeDesc = TypeDesc { name: "geometry_msgs/msg/Vector3", fields: &XYZ };
/// `geometry_msgs/msg/Point`.
pub static POINT: TypeDesc = TypeDesc { name: "geometry_msgs/msg/Point", fields: &XYZ };
/// `geometry_msgs/msg/Quaternion`.
pub static QUATERNION: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/Quaternion",
    fields: &[one("x", Ty::Float64), one("y", Ty::Float64), one("z", Ty::Float64), one("w", Ty::Float64)],
};
/// `geometry_msgs/msg/Pose`.
pub static POSE: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/Pose",
    fields: &[one("position", Ty::Nested(&POINT)), one("orientation", Ty::Nested(&QUATERNION))],
};
/// `geometry_msgs/msg/PoseWithCovariance`.
pub static POSE_WITH_COVARIANCE: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/PoseWithCovariance",
    fields: &[one("pose", Ty::Nested(&POSE)), array("covariance", Ty::Float64, 36)],
};
/// `geometry_msgs/msg/Twist`.
pub static TWIST: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/Twist",
    fields: &[one("linear", Ty::Nested(&VECTOR3)), one("angular", Ty::Nested(&VECTOR3))],
};
/// `geometry_msgs/msg/TwistWithCovariance`.
pub static TWIST_WITH_COVARIANCE: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/TwistWithCovariance",
    fields: &[one("twist", Ty::Nested(&TWIST)), array("covariance", Ty::Float64, 36)],
};
/// `geometry_msgs/msg/Transform`.
pub static TRANSFORM: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/Transform",
    fields: &[one("translation", Ty::Nested(&VECTOR3)), one("rotation", Ty::Nested(&QUATERNION))],
};
/// `geometry_msgs/msg/TransformStamped`.
pub static TRANSFORM_STAMPED: TypeDesc = TypeDesc {
    name: "geometry_msgs/msg/TransformStamped",
    fields: &[
        one("header", Ty::Nested(&HEADER)),
        one("child_frame_id", Ty::String),
        one("transform", Ty::Nested(&TRANSFORM)),
    ],
};
/// `tf2_msgs/msg/TFMessage`.
pub static TF_MESSAGE: TypeDesc =
    TypeDesc { name: "tf2_msgs/msg/TFMessage", fields: &[seq("transforms", Ty::Nested(&TRANSFORM_STAMPED))] };
/// `nav_msgs/msg/Odometry`.
pub static ODOMETRY: TypeDesc = TypeDesc {
    name: "nav_msgs/msg/Odometry",
    fields: &[
        one("header", Ty::Nested(&HEADER)),
        one("child_frame_id", Ty::String),
        one("pose", Ty::Nested(&POSE_WITH_COVARIANCE)),
        one("twist", Ty::Nested(&TWIST_WITH_COVARIANCE)),
    ],
};
/// `nav_msgs/msg/MapMetaData`.
pub static MAP_META_DATA: TypeDesc = TypeDesc {
    name: "nav_msgs/msg/MapMetaData",
    fields: &[
        one("map_load_time", Ty::Nested(&TIME)),
        one("resolution", Ty::Float32),
        one("width", Ty::UInt32),
        one("height", Ty::UInt32),
        one("origin", Ty::Nested(&POSE)),
    ],
};
/// `nav_msgs/msg/OccupancyGrid`.
pub static OCCUPANCY_GRID: TypeDesc = TypeDesc {
    name: "nav_msgs/msg/OccupancyGrid",
    fields: &[one("header", Ty::Nested(&HEADER)), one("info", Ty::Nested(&MAP_META_DATA)), seq("data", Ty::Int8)],
};
/// `sensor_msgs/msg/Range` (with `variance`, as since Jazzy).
pub static RANGE: TypeDesc = TypeDesc {
    name: "sensor_msgs/msg/Range",
    fields: &[
        one("header", Ty::Nested(&HEADER)),
        one("radiation_type", Ty::UInt8),
        one("field_of_view", Ty::Float32),
        one("min_range", Ty::Float32),
        one("max_range", Ty::Float32),
        one("range", Ty::Float32),
        one("variance", Ty::Float32),
    ],
};
/// `sensor_msgs/msg/LaserScan`.
pub static LASER_SCAN: TypeDesc = TypeDesc {
    name: "sensor_msgs/msg/LaserScan",
    fields: &[
        one("header", Ty::Nested(&HEADER)),
        one("angle_min", Ty::Float32),
        one("angle_max", Ty::Float32),
        one("angle_increment", Ty::Float32),
        one("time_increment", Ty::Float32),
        one("scan_time", Ty::Float32),
        one("range_min", Ty::Float32),
        one("range_max", Ty::Float32),
        seq("ranges", Ty::Float32),
        seq("intensities", Ty::Float32),
    ],
};
/// `sensor_msgs/msg/Imu`.
pub static IMU: TypeDesc = TypeDesc {
    name: "sensor_msgs/msg/Imu",
    fields: &[
        one("header", Ty::Nested(&HEADER)),
        one("orientation", Ty::Nested(&QUATERNION)),
        array("orientation_covariance", Ty::Float64, 9),
        one("angular_velocity", Ty::Nested(&VECTOR3)),
        array("angular_velocity_covariance", Ty::Float64, 9),
        one("linear_acceleration", Ty::Nested(&VECTOR3)),
        array("linear_acceleration_covariance", Ty::Float64, 9),
    ],
};

/// A message that writes itself in CDR.
pub trait Message {
    /// Its type.
    const TYPE: &'static TypeDesc;

    /// Writes the fields (the header is the writer's).
    fn write(&self, w: &mut Writer);

    /// The whole message, encapsulation header first.
    fn to_cdr(&self) -> Vec<u8> {
        let mut w = Writer::new();
        self.write(&mut w);
        w.finish()
    }
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds past them.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after zero.
    pub fn from_ns(ns: u64) -> Self {
        Self { sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32, nanosec: (ns % 1_000_000_000) as u32 }
    }

    /// The time `s` seconds after zero (to the nanosecond).
    pub fn from_secs(s: f64) -> Self {
        Self::from_ns((s.max(0.0) * 1e9).round() as u64)
    }

    fn write(&self, w: &mut Writer) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// In which frame.
    pub frame_id: String,
}

impl Header {
    fn write(&self, w: &mut Writer) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }
}

fn xyz(w: &mut Writer, v: [f64; 3]) {
    for x in v {
        w.f64(x);
    }
}

/// A rotation about z by `yaw` radians, as a quaternion `[x, y, z, w]`.
pub fn yaw_quaternion(yaw: f64) -> [f64; 4] {
    let (s, c) = (yaw / 2.0).sin_cos();
    [0.0, 0.0, s, c]
}

/// `rosgraph_msgs/msg/Clock`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Clock {
    /// The simulation's time.
    pub clock: Time,
}

impl Message for Clock {
    const TYPE: &'static TypeDesc = &CLOCK;
    fn write(&self, w: &mut Writer) {
        self.clock.write(w);
    }
}

/// `std_msgs/msg/Bool`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Bool {
    /// The value.
    pub data: bool,
}

impl Message for Bool {
    const TYPE: &'static TypeDesc = &BOOL;
    fn write(&self, w: &mut Writer) {
        w.bool(self.data);
    }
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// m/s along x, y, z.
    pub linear: [f64; 3],
    /// rad/s about x, y, z.
    pub angular: [f64; 3],
}

impl Message for Twist {
    const TYPE: &'static TypeDesc = &TWIST;
    fn write(&self, w: &mut Writer) {
        xyz(w, self.linear);
        xyz(w, self.angular);
    }
}

impl Twist {
    /// Reads one from a whole CDR message.
    pub fn from_cdr(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(bytes)?;
        let mut t = Self::default();
        for (v, what) in [(&mut t.linear, "linear"), (&mut t.angular, "angular")] {
            for x in v.iter_mut() {
                *x = r.f64(what)?;
            }
        }
        Ok(t)
    }
}

/// `nav_msgs/msg/Odometry` (twist in the child frame, as REP 105 has it).
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Stamp and the pose's frame (`odom`).
    pub header: Header,
    /// The twist's frame (`base_link`).
    pub child_frame_id: String,
    /// x, y, z metres.
    pub position: [f64; 3],
    /// x, y, z, w.
    pub orientation: [f64; 4],
    /// The pose's covariance, row-major 6×6.
    pub pose_covariance: [f64; 36],
    /// The twist.
    pub twist: Twist,
    /// The twist's covariance, row-major 6×6.
    pub twist_covariance: [f64; 36],
}

impl Message for Odometry {
    const TYPE: &'static TypeDesc = &ODOMETRY;
    fn write(&self, w: &mut Writer) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        xyz(w, self.position);
        for q in self.orientation {
            w.f64(q);
        }
        for c in self.pose_covariance {
            w.f64(c);
        }
        self.twist.write(w);
        for c in self.twist_covariance {
            w.f64(c);
        }
    }
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    /// Stamp and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// x, y, z metres.
    pub translation: [f64; 3],
    /// x, y, z, w.
    pub rotation: [f64; 4],
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

impl Message for TfMessage {
    const TYPE: &'static TypeDesc = &TF_MESSAGE;
    fn write(&self, w: &mut Writer) {
        w.len(self.transforms.len());
        for t in &self.transforms {
            t.header.write(w);
            w.string(&t.child_frame_id);
            xyz(w, t.translation);
            for q in t.rotation {
                w.f64(q);
            }
        }
    }
}

/// `sensor_msgs/msg/Range`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Range {
    /// Stamp and the sensor's frame.
    pub header: Header,
    /// 0 ultrasound, 1 infrared.
    pub radiation_type: u8,
    /// The cone's full opening, radians.
    pub field_of_view: f32,
    /// Metres.
    pub min_range: f32,
    /// Metres.
    pub max_range: f32,
    /// Metres; `+inf` for nothing in reach (REP 117).
    pub range: f32,
    /// The reading's variance, m² (0: unknown).
    pub variance: f32,
}

/// `Range::radiation_type` of a sonar.
pub const ULTRASOUND: u8 = 0;
/// `Range::radiation_type` of an infrared ranger.
pub const INFRARED: u8 = 1;

impl Message for Range {
    const TYPE: &'static TypeDesc = &RANGE;
    fn write(&self, w: &mut Writer) {
        self.header.write(w);
        w.u8(self.radiation_type);
        for v in [self.field_of_view, self.min_range, self.max_range, self.range, self.variance] {
            w.f32(v);
        }
    }
}

/// `sensor_msgs/msg/LaserScan`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaserScan {
    /// Stamp and the scan's frame.
    pub header: Header,
    /// Radians.
    pub angle_min: f32,
    /// Radians.
    pub angle_max: f32,
    /// Radians between readings.
    pub angle_increment: f32,
    /// Seconds between readings.
    pub time_increment: f32,
    /// Seconds between scans.
    pub scan_time: f32,
    /// Metres.
    pub range_min: f32,
    /// Metres.
    pub range_max: f32,
    /// Metres, one per angle.
    pub ranges: Vec<f32>,
    /// Empty, or one per angle.
    pub intensities: Vec<f32>,
}

impl Message for LaserScan {
    const TYPE: &'static TypeDesc = &LASER_SCAN;
    fn write(&self, w: &mut Writer) {
        self.header.write(w);
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(v);
        }
        w.f32s(&self.ranges);
        w.f32s(&self.intensities);
    }
}

/// `sensor_msgs/msg/Imu`.
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    /// Stamp and the sensor's frame.
    pub header: Header,
    /// x, y, z, w.
    pub orientation: [f64; 4],
    /// Row-major 3×3; `[-1, 0, …]` for "not given" (REP 145).
    pub orientation_covariance: [f64; 9],
    /// rad/s.
    pub angular_velocity: [f64; 3],
    /// Row-major 3×3.
    pub angular_velocity_covariance: [f64; 9],
    /// m/s².
    pub linear_acceleration: [f64; 3],
    /// Row-major 3×3.
    pub linear_acceleration_covariance: [f64; 9],
}

impl Message for Imu {
    const TYPE: &'static TypeDesc = &IMU;
    fn write(&self, w: &mut Writer) {
        self.header.write(w);
        for q in self.orientation {
            w.f64(q);
        }
        for (v, c) in [
            (None, &self.orientation_covariance),
            (Some(self.angular_velocity), &self.angular_velocity_covariance),
            (Some(self.linear_acceleration), &self.linear_acceleration_covariance),
        ] {
            if let Some(v) = v {
                xyz(w, v);
            }
            for &x in c {
                w.f64(x);
            }
        }
    }
}

/// `nav_msgs/msg/OccupancyGrid`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OccupancyGrid {
    /// Stamp and the map's frame.
    pub header: Header,
    /// When the map was made.
    pub map_load_time: Time,
    /// Metres per cell.
    pub resolution: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// The cell (0, 0)'s corner: x, y, z metres.
    pub origin_position: [f64; 3],
    /// The grid's rotation, x, y, z, w.
    pub origin_orientation: [f64; 4],
    /// Row-major from (0, 0): 0 free, 100 occupied, −1 unknown.
    pub data: Vec<i8>,
}

impl Message for OccupancyGrid {
    const TYPE: &'static TypeDesc = &OCCUPANCY_GRID;
    fn write(&self, w: &mut Writer) {
        self.header.write(w);
        self.map_load_time.write(w);
        w.f32(self.resolution);
        w.u32(self.width);
        w.u32(self.height);
        xyz(w, self.origin_position);
        for q in self.origin_orientation {
            w.f64(q);
        }
        w.i8s(&self.data);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden bytes from the PyPI `rosbags` (0.11.9, store ROS2_JAZZY): `typestore.serialize_cdr`
    /// of the same values, header included.
    fn golden(hex: &str) -> Vec<u8> {
        (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex")).collect()
    }

    fn stamp() -> Time {
        Time { sec: 1, nanosec: 5 }
    }

    #[test]
    // 1.0472 is the golden's field of view as written for rosbags, not an approximation of π/3.
    #[allow(clippy::approx_constant)]
    fn messages_are_the_bytes_rosbags_writes() {
        let twist = Twist { linear: [0.5, 0.0, 0.0], angular: [0.0, 0.0, 0.25] };
        assert_eq!(
            twist.to_cdr(),
            golden(
                "00010000000000000000e03f0000000000000000000000000000000000000000000000000000000000000000000000000000d03f"
            )
        );
        assert_eq!(Twist::from_cdr(&twist.to_cdr()), Ok(twist));
        assert_eq!(Clock { clock: Time::from_ns(12_300_000_000) }.to_cdr(), golden("000100000c00000000a3e111"));
        assert_eq!(Bool { data: true }.to_cdr(), golden("0001000001"));
        let range = Range {
            header: Header { stamp: stamp(), frame_id: "chair1/prox0".into() },
            radiation_type: INFRARED,
            field_of_view: 1.0472,
            min_range: 0.0,
            max_range: 2.0,
            range: 0.75,
            variance: 0.0,
        };
        assert_eq!(
            range.to_cdr(),
            golden(
                "0001000001000000050000000d0000006368616972312f70726f783000010000a60a863f00000000000000400000403f00000000"
            )
        );
        let scan = LaserScan {
            header: Header { stamp: stamp(), frame_id: "laser".into() },
            angle_min: -0.5,
            angle_max: 0.5,
            angle_increment: 0.5,
            time_increment: 0.0,
            scan_time: 0.1,
            range_min: 0.1,
            range_max: 10.0,
            ranges: vec![1.0, 1.5, 2.0],
            intensities: vec![],
        };
        assert_eq!(
            scan.to_cdr(),
            golden(
                "000100000100000005000000060000006c61736572000000000000bf0000003f0000003f00000000cdcccc3dcdcccc3d00002041030000000000803f0000c03f0000004000000000"
            )
        );
        let tf = TfMessage {
            transforms: vec![TransformStamped {
                header: Header { stamp: stamp(), frame_id: "odom".into() },
                child_frame_id: "base_link".into(),
                translation: [1.0, 2.0, 0.0],
                rotation: [0.0, 0.0, 0.1, 0.995],
            }],
        };
        assert_eq!(
            tf.to_cdr(),
            golden(
                "00010000010000000100000005000000050000006f646f6d000000000a000000626173655f6c696e6b000000000000000000f03f00000000000000400000000000000000000000000000000000000000000000009a9999999999b93fd7a3703d0ad7ef3f"
            )
        );
        let grid = OccupancyGrid {
            header: Header { stamp: stamp(), frame_id: "map".into() },
            map_load_time: Time::default(),
            resolution: 0.1,
            width: 2,
            height: 2,
            origin_position: [0.0; 3],
            origin_orientation: [0.0, 0.0, 0.0, 1.0],
            data: vec![0, 100, -1, 0],
        };
        assert_eq!(
            grid.to_cdr(),
            golden(
                "000100000100000005000000040000006d6170000000000000000000cdcccc3d020000000200000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000f03f040000000064ff00"
            )
        );
    }

    #[test]
    fn odometry_is_the_bytes_rosbags_writes() {
        let odom = Odometry {
            header: Header { stamp: Time::default(), frame_id: "odom".into() },
            child_frame_id: "base_link".into(),
            position: [1.0, 2.0, 0.0],
            orientation: [0.0, 0.0, 0.1, 0.995],
            pose_covariance: [0.0; 36],
            twist: Twist::default(),
            twist_covariance: [0.0; 36],
        };
        // rosbags: 724 bytes; the header, the two frame names, the pose, then zeros.
        let mut want = golden(
            "000100000000000000000000050000006f646f6d000000000a000000626173655f6c696e6b00000000000000000000000000f03f00000000000000400000000000000000000000000000000000000000000000009a9999999999b93fd7a3703d0ad7ef3f",
        );
        want.resize(724, 0);
        assert_eq!(odom.to_cdr(), want);
    }

    #[test]
    fn dds_names_are_rmw_zenohs() {
        assert_eq!(TWIST.dds_name(), "geometry_msgs::msg::dds_::Twist_");
        assert_eq!(STRING.dds_name(), "std_msgs::msg::dds_::String_");
    }
}
