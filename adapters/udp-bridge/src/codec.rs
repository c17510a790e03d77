//! The Ciber-Rato / Intellwheels XML datagrams: pure decode and encode functions, and the one
//! place the bridge touches quick-xml.
//!
//! Facts from `shared/research/ciberrato.md`: one XML document per datagram; clients may end
//! theirs with a NUL or not; everything we send ends with `\n\0` (the stock Python client drops
//! the last byte); numbers are printed as C's `%g`; element and attribute order follow the
//! simulator's `sendSensors` and `toXml`.

use std::fmt::Write as _;

use agent_sdk::map::Map;
use quick_xml::XmlVersion;
use quick_xml::events::attributes::AttrError;
use quick_xml::events::{BytesStart, Event};
use quick_xml::reader::Reader;

/// Datagrams longer than this are refused unread (the simulator's own buffers are 1 KiB).
pub const MAX_DATAGRAM: usize = 4096;

/// Why a datagram was not understood. It is counted and dropped; nothing changes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// Longer than [`MAX_DATAGRAM`].
    #[error("datagram of {0} bytes is longer than {MAX_DATAGRAM}")]
    TooLong(usize),
    /// Not UTF-8.
    #[error("datagram is not UTF-8")]
    NotUtf8,
    /// No element at all.
    #[error("datagram holds no XML element")]
    Empty,
    /// Malformed XML.
    #[error("malformed XML: {0}")]
    Xml(String),
    /// An attribute appears twice (in a registration: twice with different values).
    #[error("attribute {0} appears twice")]
    DuplicateAttribute(String),
    /// A robot registration whose `Id` is not a grid slot number (0 or more): the simulator
    /// answers it with a refusal rather than silence.
    #[error("robot Id=\"{0}\" is not a grid slot number")]
    BadRobotId(String),
    /// The root element is not one this socket takes.
    #[error("unexpected root element <{0}>")]
    UnknownRoot(String),
    /// A child element this message does not allow.
    #[error("unexpected child <{child}> in <{parent}>")]
    UnknownChild {
        /// The parent.
        parent: &'static str,
        /// The child.
        child: String,
    },
    /// An attribute that must be a number is not one (NaN and infinities included).
    #[error("attribute {attr}=\"{value}\" is not a finite number")]
    BadNumber {
        /// The attribute.
        attr: String,
        /// Its value.
        value: String,
    },
    /// An attribute's value is out of range.
    #[error("attribute {attr}=\"{value}\" is out of range")]
    OutOfRange {
        /// The attribute.
        attr: String,
        /// Its value.
        value: String,
    },
}

/// A parsed element: name, attributes, children, text.
#[derive(Debug, Clone, PartialEq, Default)]
struct Element {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Element>,
    text: String,
}

impl Element {
    fn attr(&self, name: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    /// The first of several spellings that is present.
    fn attr_any<'n>(&self, names: &[&'n str]) -> Option<(&'n str, &str)> {
        names.iter().find_map(|n| self.attr(n).map(|v| (*n, v)))
    }

    fn num(&self, names: &[&str]) -> Result<Option<f64>, DecodeError> {
        match self.attr_any(names) {
            None => Ok(None),
            Some((k, v)) => match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(DecodeError::BadNumber { attr: k.to_owned(), value: v.to_owned() }),
            },
        }
    }
}

/// Whether an attribute may repeat with the same value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Repeats {
    /// Registrations: the thesis's own example (Fig. 4.13) repeats `DIR="0.0"`.
    SameValueTolerated,
    /// Everything else (Actions, viewer commands): any repeat makes the datagram malformed.
    Refused,
}

fn start_element(e: &BytesStart<'_>, repeats: Repeats) -> Result<Element, DecodeError> {
    let name = e.name().as_ref().to_owned();
    let mut attrs: Vec<(String, String)> = Vec::new();
    // Duplicates are checked here, not by quick-xml: a registration may repeat an attribute
    // with the same value (the thesis's example does); a repeat with another value is
    // ambiguous and refused, and so is any repeat elsewhere (malformed input changes nothing).
    for a in e.attributes().with_checks(false) {
        let a = a.map_err(|err: AttrError| DecodeError::Xml(err.to_string()))?;
        let key = a.key.as_ref().to_owned();
        let value =
            a.normalized_value(XmlVersion::Implicit1_0).map_err(|e| DecodeError::Xml(e.to_string()))?.into_owned();
        match attrs.iter().find(|(k, _)| *k == key) {
            Some((_, v)) if *v == value && repeats == Repeats::SameValueTolerated => {}
            Some(_) => return Err(DecodeError::DuplicateAttribute(key)),
            None => attrs.push((key, value)),
        }
    }
    Ok(Element { name, attrs, ..Element::default() })
}

/// Parses one datagram into a small tree (root, children, grandchildren' text ignored).
fn parse(datagram: &[u8], repeats: Repeats) -> Result<Element, DecodeError> {
    if datagram.len() > MAX_DATAGRAM {
        return Err(DecodeError::TooLong(datagram.len()));
    }
    // Clients may end with NUL (libRobSock, the Viewer) or not (pClient): read up to the first.
    let end = datagram.iter().position(|&b| b == 0).unwrap_or(datagram.len());
    let text = std::str::from_utf8(&datagram[..end]).map_err(|_| DecodeError::NotUtf8)?;
    let mut reader = Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut stack: Vec<Element> = Vec::new();
    let mut root: Option<Element> = None;
    loop {
        let ev = reader.read_event().map_err(|e| DecodeError::Xml(e.to_string()))?;
        match ev {
            Event::Start(e) => {
                if root.is_some() {
                    return Err(DecodeError::Xml("a second root element".into()));
                }
                if stack.len() >= 8 {
                    return Err(DecodeError::Xml("elements nested too deep".into()));
                }
                stack.push(start_element(&e, repeats)?);
            }
            Event::Empty(e) => {
                let el = start_element(&e, repeats)?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(el),
                    None if root.is_none() => root = Some(el),
                    None => return Err(DecodeError::Xml("a second root element".into())),
                }
            }
            Event::End(_) => {
                let el = stack.pop().ok_or_else(|| DecodeError::Xml("closing tag without an open one".into()))?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(el),
                    None => root = Some(el),
                }
            }
            Event::Text(t) => {
                if let Some(top) = stack.last_mut() {
                    let s: &str = &t;
                    top.text.push_str(s);
                }
            }
            Event::CData(c) => {
                if let Some(top) = stack.last_mut() {
                    let s: &str = &c;
                    top.text.push_str(s);
                }
            }
            Event::GeneralRef(r) => {
                if let Some(top) = stack.last_mut() {
                    let name: &str = &r;
                    let ch = match name {
                        "lt" => "<",
                        "gt" => ">",
                        "amp" => "&",
                        "apos" => "'",
                        "quot" => "\"",
                        _ => "",
                    };
                    top.text.push_str(ch);
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !stack.is_empty() {
        return Err(DecodeError::Xml(format!("<{}> is never closed", stack[0].name)));
    }
    root.ok_or(DecodeError::Empty)
}

/// Robot kinds of the Intellwheels `Type` attribute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotType {
    /// Moved by the simulator.
    Simulated,
    /// A physical chair pushing its pose.
    Real,
    /// A door.
    Door,
}

/// One `<IRSensor>` at registration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IrSensor {
    /// `Id`.
    pub id: u32,
    /// `X` (Intellwheels), metres from the centre of movement.
    pub x: Option<f64>,
    /// `Y` (Intellwheels).
    pub y: Option<f64>,
    /// `Angle`, degrees.
    pub angle_deg: f64,
    /// `Cone` (Intellwheels), degrees.
    pub cone_deg: Option<f64>,
}

/// A robot's registration (`<Robot>` or `<RobotBeacon>`), Intellwheels extensions included.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RobotRegistration {
    /// `Name`.
    pub name: String,
    /// `Id`: 1-based grid slot; 0 = first free.
    pub id: u32,
    /// `Width` (along the heading).
    pub width: Option<f64>,
    /// `Height` (also `Heigth`).
    pub height: Option<f64>,
    /// `COM` (also `COMass`).
    pub com: Option<f64>,
    /// `X`.
    pub x: Option<f64>,
    /// `Y`.
    pub y: Option<f64>,
    /// `Dir` (also `DIR`), degrees.
    pub dir: Option<f64>,
    /// `Type`.
    pub kind: Option<RobotType>,
    /// `MaxSpeed`.
    pub max_speed: Option<f64>,
    /// `AccelerationCurve` (also the thesis's `AccerelationCurve`).
    pub accel_curve: Option<f64>,
    /// `<IRSensor>` children.
    pub sensors: Vec<IrSensor>,
    /// `Height` of a `<RobotBeacon>`.
    pub beacon_height: Option<f64>,
}

/// What arrives on the registration port.
#[derive(Debug, Clone, PartialEq)]
pub enum Registration {
    /// A robot.
    Robot(RobotRegistration),
    /// A robot that is also a beacon.
    RobotBeacon(RobotRegistration),
    /// A viewer.
    View,
    /// A panel.
    Panel,
}

fn parse_id(el: &Element) -> Result<u32, DecodeError> {
    match el.attr("Id") {
        None => Ok(0),
        Some(v) => {
            v.trim().parse::<u32>().map_err(|_| DecodeError::OutOfRange { attr: "Id".into(), value: v.to_owned() })
        }
    }
}

/// Decodes a datagram sent to the registration port.
pub fn decode_registration(datagram: &[u8]) -> Result<Registration, DecodeError> {
    let el = parse(datagram, Repeats::SameValueTolerated)?;
    match el.name.as_str() {
        "View" => Ok(Registration::View),
        "Panel" => Ok(Registration::Panel),
        "Robot" | "RobotBeacon" => {
            let mut r = RobotRegistration {
                name: el.attr("Name").unwrap_or("").to_owned(),
                id: parse_id(&el).map_err(|_| DecodeError::BadRobotId(el.attr("Id").unwrap_or("").to_owned()))?,
                width: el.num(&["Width"])?,
                com: el.num(&["COM", "COMass"])?,
                x: el.num(&["X"])?,
                y: el.num(&["Y"])?,
                dir: el.num(&["Dir", "DIR"])?,
                max_speed: el.num(&["MaxSpeed"])?,
                accel_curve: el.num(&["AccelerationCurve", "AccerelationCurve"])?,
                ..RobotRegistration::default()
            };
            if el.name == "RobotBeacon" {
                r.beacon_height = el.num(&["Height"])?;
            } else {
                r.height = el.num(&["Height", "Heigth"])?;
            }
            r.kind = match el.attr("Type") {
                None => None,
                Some(t) if t.eq_ignore_ascii_case("simulated") => Some(RobotType::Simulated),
                Some(t) if t.eq_ignore_ascii_case("real") => Some(RobotType::Real),
                Some(t) if t.eq_ignore_ascii_case("door") => Some(RobotType::Door),
                Some(t) => return Err(DecodeError::OutOfRange { attr: "Type".into(), value: t.to_owned() }),
            };
            for c in &el.children {
                if c.name != "IRSensor" {
                    return Err(DecodeError::UnknownChild { parent: "Robot", child: c.name.clone() });
                }
                r.sensors.push(IrSensor {
                    id: parse_id(c)?,
                    x: c.num(&["X"])?,
                    y: c.num(&["Y"])?,
                    angle_deg: c.num(&["Angle"])?.unwrap_or(0.0),
                    cone_deg: c.num(&["Cone"])?,
                });
            }
            Ok(if el.name == "RobotBeacon" { Registration::RobotBeacon(r) } else { Registration::Robot(r) })
        }
        other => Err(DecodeError::UnknownRoot(other.to_owned())),
    }
}

/// A robot's `<Actions>`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Actions {
    /// `LeftMotor`, Ciber-Rato power (clamped to ±0.15 by the bridge).
    pub left: Option<f64>,
    /// `RightMotor`.
    pub right: Option<f64>,
    /// `EndLed`.
    pub end_led: Option<bool>,
    /// `ReturningLed`.
    pub returning_led: Option<bool>,
    /// `VisitingLed`.
    pub visiting_led: Option<bool>,
    /// Pushed pose of a Real robot: `X`, `Y` metres, `Dir`/`DIR` degrees.
    pub pose: Option<(f64, f64, f64)>,
    /// Names of the sensors requested (`<SensorRequests Name="Yes"/>`), in order.
    pub requests: Vec<String>,
    /// `<Say>` text.
    pub say: Option<Vec<u8>>,
    /// `<Sync/>` (pei2015 fork): the robot is done for this tick.
    pub sync: bool,
}

/// Decodes a datagram sent to a robot's port.
pub fn decode_actions(datagram: &[u8]) -> Result<Actions, DecodeError> {
    let el = parse(datagram, Repeats::Refused)?;
    if el.name != "Actions" {
        return Err(DecodeError::UnknownRoot(el.name));
    }
    let led = |name: &str| el.attr(name).map(|v| v == "On");
    let mut a = Actions {
        left: el.num(&["LeftMotor"])?,
        right: el.num(&["RightMotor"])?,
        end_led: led("EndLed"),
        returning_led: led("ReturningLed"),
        visiting_led: led("VisitingLed"),
        ..Actions::default()
    };
    if let (Some(x), Some(y)) = (el.num(&["X"])?, el.num(&["Y"])?) {
        a.pose = Some((x, y, el.num(&["Dir", "DIR"])?.unwrap_or(0.0)));
    }
    for c in &el.children {
        match c.name.as_str() {
            "SensorRequests" => {
                a.requests.extend(c.attrs.iter().filter(|(_, v)| v == "Yes").map(|(k, _)| k.clone()));
            }
            "Say" => a.say = Some(c.text.clone().into_bytes()),
            "Sync" => a.sync = true,
            other => return Err(DecodeError::UnknownChild { parent: "Actions", child: other.to_owned() }),
        }
    }
    Ok(a)
}

/// A viewer's command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewerCommand {
    /// Send the lab.
    LabReq,
    /// Send the grid.
    GridReq,
    /// Start the run.
    Start,
    /// Stop (pause) the run.
    Stop,
    /// Remove a robot.
    RemoveRobot(u32),
    /// Reset (iris): the bridge answers `<Restart/>`; the hub is not reset.
    Reset,
}

/// Decodes a datagram sent to a viewer's port.
pub fn decode_viewer(datagram: &[u8]) -> Result<ViewerCommand, DecodeError> {
    let el = parse(datagram, Repeats::Refused)?;
    match el.name.as_str() {
        "LabReq" => Ok(ViewerCommand::LabReq),
        "GridReq" => Ok(ViewerCommand::GridReq),
        "Start" => Ok(ViewerCommand::Start),
        "Stop" => Ok(ViewerCommand::Stop),
        "Reset" => Ok(ViewerCommand::Reset),
        "Robot" if el.attr("Removed") == Some("Yes") => Ok(ViewerCommand::RemoveRobot(parse_id(&el)?)),
        other => Err(DecodeError::UnknownRoot(other.to_owned())),
    }
}

/// C's `%g`: six significant digits, trailing zeros dropped, exponent form outside
/// [1e-4, 1e6). Allocates: encoders write [`G`] in place instead.
pub fn g(x: f64) -> String {
    G(x).to_string()
}

/// A number as C's `%g` prints it, written in place by `write!` (no allocation): what every
/// encoder here uses for its numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct G(pub f64);

impl std::fmt::Display for G {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if x.is_nan() {
            return f.write_str("nan");
        }
        if x.is_infinite() {
            return f.write_str(if x > 0.0 { "inf" } else { "-inf" });
        }
        if x == 0.0 {
            return f.write_str("0");
        }
        // The exponent of the number rounded to six digits decides the form, as in C.
        let mut sci = Digits::default();
        write!(sci, "{x:.5e}")?;
        let (mant, exp) = sci.as_str().split_once('e').unwrap_or((sci.as_str(), "0"));
        let exp: i32 = exp.parse().unwrap_or(0);
        if !(-4..6).contains(&exp) {
            f.write_str(trim_zeros(mant))?;
            write!(f, "e{}{:02}", if exp < 0 { '-' } else { '+' }, exp.unsigned_abs())
        } else {
            let mut fixed = Digits::default();
            write!(fixed, "{:.*}", (5 - exp).max(0) as usize, x)?;
            f.write_str(trim_zeros(fixed.as_str()))
        }
    }
}

/// Drops a fraction's trailing zeros, and its point if nothing is left after it.
fn trim_zeros(s: &str) -> &str {
    if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.') } else { s }
}

/// Room on the stack for one number's text (`%g` needs at most 13 bytes, a fixed form with
/// nine decimals 18).
struct Digits {
    buf: [u8; 48],
    len: usize,
}

impl Default for Digits {
    fn default() -> Self {
        Self { buf: [0; 48], len: 0 }
    }
}

impl Digits {
    fn as_str(&self) -> &str {
        // Only `str`s are ever written, whole, so the bytes are UTF-8.
        std::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
}

impl std::fmt::Write for Digits {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let end = self.len + s.len();
        self.buf.get_mut(self.len..end).ok_or(std::fmt::Error)?.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// Text escaped for an XML attribute, written in place.
struct Escaped<'a>(&'a str);

impl std::fmt::Display for Escaped<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut rest = self.0;
        while let Some(i) = rest.find(['&', '<', '>', '"']) {
            f.write_str(&rest[..i])?;
            f.write_str(match rest.as_bytes()[i] {
                b'&' => "&amp;",
                b'<' => "&lt;",
                b'>' => "&gt;",
                _ => "&quot;",
            })?;
            rest = &rest[i + 1..];
        }
        f.write_str(rest)
    }
}

/// A message's bytes as CDATA text: invalid UTF-8 as U+FFFD, and `]]>` (which CDATA cannot
/// hold) split the standard way, written in place.
struct Cdata<'a>(&'a [u8]);

impl std::fmt::Display for Cdata<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for chunk in self.0.utf8_chunks() {
            let mut parts = chunk.valid().split("]]>");
            if let Some(first) = parts.next() {
                f.write_str(first)?;
            }
            for part in parts {
                f.write_str("]]]]><![CDATA[>")?;
                f.write_str(part)?;
            }
            if !chunk.invalid().is_empty() {
                f.write_str("\u{fffd}")?;
            }
        }
        Ok(())
    }
}

fn on(b: bool) -> &'static str {
    if b { "On" } else { "Off" }
}

/// Ends a datagram written into `out`: a newline and the NUL the simulator sends.
fn finish_in(out: &mut Vec<u8>) {
    out.extend_from_slice(b"\n\0");
}

fn finish(mut s: String) -> Vec<u8> {
    s.push('\n');
    let mut v = s.into_bytes();
    v.push(0);
    v
}

/// What the registration reply's `<Parameters>` reports.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReplyParams {
    /// `SimTime` (ticks; 0 = no limit).
    pub sim_time: u64,
    /// `CycleTime`, ms.
    pub cycle_ms: u32,
    /// `CompassNoise`.
    pub compass_noise: f64,
    /// `BeaconNoise`.
    pub beacon_noise: f64,
    /// `ObstacleNoise`.
    pub obstacle_noise: f64,
    /// `MotorsNoise` (%).
    pub motors_noise: f64,
    /// `GPS`.
    pub gps: bool,
    /// `GPSLinNoise`.
    pub gps_lin_noise: f64,
    /// `GPSDirNoise`.
    pub gps_dir_noise: f64,
    /// `BeaconSensor`.
    pub beacon_sensor: bool,
    /// `CompassSensor`.
    pub compass_sensor: bool,
    /// `NBeacons`.
    pub n_beacons: usize,
    /// `NRequestsPerCycle`.
    pub requests_per_cycle: u32,
    /// Requestable: obstacle, beacon, ground, compass, collision.
    pub requestable: [bool; 5],
    /// Latencies: obstacle, beacon, ground, compass, collision.
    pub latency: [u32; 5],
    /// `BeaconAperture`, radians.
    pub beacon_aperture: f64,
    /// `KeyTime`, ticks.
    pub key_time: u64,
    /// `ReturnTimePenalty`, `ArrivalTimePenalty`, `CollisionWallPenalty`,
    /// `CollisionRobotPenalty`, `TargetReward`, `HomeReward`.
    pub scoring: [u32; 6],
    /// `ScoreSensor`: Measures carry `<Score>`.
    pub score_sensor: bool,
}

/// `<Reply Status="Ok"><Parameters …/></Reply>`: under 1024 bytes, as pClient reads it. The
/// attributes come in the real simulator's order, with `RequestsPerCycle` beside
/// `NRequestsPerCycle` (libRobSock reads the former). `ShowActions` is `True` as the real
/// simulator always says (it reads no such parameter).
pub fn encode_reply_ok(p: &ReplyParams) -> Vec<u8> {
    let [ro, rb, rg, rc, rcol] = p.requestable;
    let [lo, lb, lg, lc, lcol] = p.latency;
    let [return_time, arrival_time, wall, robot, target, home] = p.scoring;
    let mut s = String::with_capacity(900);
    let _ = write!(
        s,
        "<Reply Status=\"Ok\">\n\t<Parameters SimTime=\"{}\" CycleTime=\"{}\" CompassNoise=\"{}\" BeaconNoise=\"{}\" ObstacleNoise=\"{}\" MotorsNoise=\"{}\" KeyTime=\"{}\" GPS=\"{}\" GPSLinNoise=\"{}\" GPSDirNoise=\"{}\" BeaconSensor=\"{}\" CompassSensor=\"{}\" ScoreSensor=\"{}\" ShowActions=\"True\" NBeacons=\"{}\" NRequestsPerCycle=\"{}\" RequestsPerCycle=\"{}\" ObstacleRequestable=\"{}\" BeaconRequestable=\"{}\" GroundRequestable=\"{}\" CompassRequestable=\"{}\" CollisionRequestable=\"{}\" ObstacleLatency=\"{}\" BeaconLatency=\"{}\" GroundLatency=\"{}\" CompassLatency=\"{}\" CollisionLatency=\"{}\" BeaconAperture=\"{}\" ReturnTimePenalty=\"{}\" ArrivalTimePenalty=\"{}\" CollisionWallPenalty=\"{}\" CollisionRobotPenalty=\"{}\" TargetReward=\"{}\" HomeReward=\"{}\"/>\n</Reply>",
        p.sim_time,
        p.cycle_ms,
        G(p.compass_noise),
        G(p.beacon_noise),
        G(p.obstacle_noise),
        G(p.motors_noise),
        p.key_time,
        on(p.gps),
        G(p.gps_lin_noise),
        G(p.gps_dir_noise),
        on(p.beacon_sensor),
        on(p.compass_sensor),
        on(p.score_sensor),
        p.n_beacons,
        p.requests_per_cycle,
        p.requests_per_cycle,
        on(ro),
        on(rb),
        on(rg),
        on(rc),
        on(rcol),
        lo,
        lb,
        lg,
        lc,
        lcol,
        G(p.beacon_aperture),
        return_time,
        arrival_time,
        wall,
        robot,
        target,
        home,
    );
    finish(s)
}

/// `<Reply Status="Refused"></Reply>`, exactly as the simulator sends it.
pub fn encode_refused() -> Vec<u8> {
    finish("<Reply Status=\"Refused\"></Reply>".into())
}

/// One robot's measures for one tick, as the bridge assembles them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MeasuresData {
    /// `Time`.
    pub time: u64,
    /// `Collision` (None: not sent this tick).
    pub collision: Option<bool>,
    /// `Compass`, degrees (None: off or not requested).
    pub compass: Option<f64>,
    /// `Ground` (None: not sent; Some(−1): no target).
    pub ground: Option<i32>,
    /// IR values (already 1/d rounded to 0.1), by sensor id; None = not sent.
    pub ir: Vec<Option<f64>>,
    /// Beacon bearings, degrees, by beacon id: Some(None) = NotVisible, None = not sent.
    pub beacons: Vec<Option<Option<f64>>>,
    /// GPS X, Y.
    pub gps: Option<(f64, f64)>,
    /// `LineSensor`: bit `k` for element `k` (0 = leftmost), written `0`/`1` from element 0;
    /// None = not sent.
    pub line: Option<u8>,
    /// Messages heard: (speaker id, text).
    pub messages: Vec<(u32, Vec<u8>)>,
    /// `<Score>` (None: the score sensor is off).
    pub score: Option<ScoreData>,
    /// End, returning, visiting LEDs.
    pub leds: [bool; 3],
    /// `Buttons Start` and `Stop`.
    pub buttons: (bool, bool),
}

/// A robot's challenge standing as Measures (`<Score>`) and viewers (`<Robot>`) carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ScoreData {
    /// `Score` (Ciber-Rato keeps it in 32 bits: Measures print it signed, viewer datagrams
    /// unsigned).
    pub score: i32,
    /// `ArrivalTime`, ticks.
    pub arrival_time: u32,
    /// `ReturningTime`, ticks.
    pub returning_time: u32,
    /// `Collisions`: collision events.
    pub collisions: u32,
    /// `Collision`: this tick's collision.
    pub collision: bool,
    /// `VisitedMask`: bit `k` for target `k`.
    pub visited: u64,
    /// Targets in the lab (the mask's length).
    pub targets: usize,
}

impl ScoreData {
    fn write_mask(&self, out: &mut Vec<u8>) {
        out.extend((0..self.targets).map(|k| if k < 64 && self.visited >> k & 1 == 1 { b'1' } else { b'0' }));
    }
}

/// `<Measures>` in the simulator's element and attribute order, under 4096 bytes.
pub fn encode_measures(m: &MeasuresData) -> Vec<u8> {
    let mut out = Vec::with_capacity(512);
    encode_measures_into(m, &mut out);
    out
}

/// [`encode_measures`] into `out` (cleared first), so a buffer kept between ticks makes each
/// tick's datagram without allocating.
pub fn encode_measures_into(m: &MeasuresData, out: &mut Vec<u8>) {
    use std::io::Write as _;
    out.clear();
    // Writing to a Vec cannot fail.
    let _ = write!(out, "<Measures Time=\"{}\">\n\t<Sensors", m.time);
    if let Some(c) = m.collision {
        let _ = write!(out, " Collision=\"{}\"", if c { "Yes" } else { "No" });
    }
    if let Some(c) = m.compass {
        let _ = write!(out, " Compass=\"{}\"", G(c));
    }
    if let Some(gr) = m.ground {
        let _ = write!(out, " Ground=\"{gr}\"");
    }
    out.extend_from_slice(b">\n");
    for (id, v) in m.ir.iter().enumerate() {
        if let Some(v) = v {
            let _ = writeln!(out, "\t\t<IRSensor Id=\"{id}\" Value=\"{}\"/>", G(*v));
        }
    }
    for (id, b) in m.beacons.iter().enumerate() {
        match b {
            Some(Some(deg)) => {
                let _ = writeln!(out, "\t\t<BeaconSensor Id=\"{id}\" Value=\"{}\"/>", G(*deg));
            }
            Some(None) => {
                let _ = writeln!(out, "\t\t<BeaconSensor Id=\"{id}\" Value=\"NotVisible\"/>");
            }
            None => {}
        }
    }
    if let Some((x, y)) = m.gps {
        let _ = writeln!(out, "\t\t<GPS X=\"{}\" Y=\"{}\" />", G(x), G(y));
    }
    if let Some(bits) = m.line {
        out.extend_from_slice(b"\t\t<LineSensor Value=\"");
        out.extend((0..ipc_types::LINE_ELEMENTS).map(|k| if bits >> k & 1 == 1 { b'1' } else { b'0' }));
        out.extend_from_slice(b"\" />\n");
    }
    for (from, text) in &m.messages {
        let _ = writeln!(out, "\t\t<Message From=\"{from}\"><![CDATA[{}]]></Message>", Cdata(text));
    }
    if let Some(sc) = &m.score {
        let _ = write!(
            out,
            "\t\t<Score Score=\"{}\" ArrivalTime=\"{}\" ReturningTime=\"{}\" Collisions=\"{}\" Collision=\"{}\" VisitedMask=\"",
            sc.score,
            sc.arrival_time,
            sc.returning_time,
            sc.collisions,
            if sc.collision { "True" } else { "False" }
        );
        sc.write_mask(out);
        out.extend_from_slice(b"\" />\n");
    }
    let _ = write!(
        out,
        "\t</Sensors>\n\t<Leds EndLed=\"{}\" ReturningLed=\"{}\" VisitingLed=\"{}\"/>\n\t<Buttons Start=\"{}\" Stop=\"{}\"/>\n</Measures>",
        on(m.leds[0]),
        on(m.leds[1]),
        on(m.leds[2]),
        on(m.buttons.0),
        on(m.buttons.1)
    );
    finish_in(out);
}

/// One robot as viewers see it each tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ViewerRobot<'a> {
    /// `Name`.
    pub name: &'a str,
    /// `Id`.
    pub id: u32,
    /// `Time`.
    pub time: u64,
    /// `Score`, `ArrivalTime`, `ReturningTime`, `Collisions`, `Collision` and `VisitedMask`.
    pub score: ScoreData,
    /// `State` (Running, Stopped, Finished, Removed…).
    pub state: &'static str,
    /// Intellwheels `Width`.
    pub width: f64,
    /// Intellwheels `Height`.
    pub height: f64,
    /// Intellwheels `CenterOfMovement`.
    pub com: f64,
    /// Intellwheels `Type`.
    pub kind: &'static str,
    /// `Position X`, `Y`, `Dir` (degrees).
    pub pose: (f64, f64, f64),
}

/// `<Robot …><Position X Y Dir/></Robot>` for viewers (thesis Fig. 6.3 adds the body). The
/// score is printed unsigned, as the real simulator prints it here (a negative score wraps).
pub fn encode_viewer_robot(r: &ViewerRobot<'_>) -> Vec<u8> {
    let mut out = Vec::with_capacity(300);
    encode_viewer_robot_into(r, &mut out);
    out
}

/// [`encode_viewer_robot`] into `out` (cleared first), without allocating once `out` is warm.
pub fn encode_viewer_robot_into(r: &ViewerRobot<'_>, out: &mut Vec<u8>) {
    use std::io::Write as _;
    out.clear();
    let _ = write!(
        out,
        "<Robot Name=\"{}\" Id=\"{}\" Time=\"{}\" Score=\"{}\" ArrivalTime=\"{}\" ReturningTime=\"{}\" Collisions=\"{}\" Collision=\"{}\" VisitedMask=\"",
        Escaped(r.name),
        r.id,
        r.time,
        r.score.score as u32,
        r.score.arrival_time,
        r.score.returning_time,
        r.score.collisions,
        if r.score.collision { "True" } else { "False" },
    );
    r.score.write_mask(out);
    let _ = write!(
        out,
        "\" State=\"{}\" Width=\"{}\" Height=\"{}\" CenterOfMovement=\"{}\" Type=\"{}\">\n\t<Position X=\"{}\" Y=\"{}\" Dir=\"{}\"/>\n</Robot>",
        r.state,
        G(r.width),
        G(r.height),
        G(r.com),
        r.kind,
        G(r.pose.0),
        G(r.pose.1),
        G(r.pose.2),
    );
    finish_in(out);
}

/// `<Lab>` as the simulator sends it to viewers (no border wall, polygons not rows). A
/// scenario's obstacles are sent as walls: a Ciber-Rato viewer has no other way to draw them.
///
/// The name is the one the hub's map carries: whole up to 255 bytes (the map header's fixed
/// name), cut at a character boundary past that, where the simulator serves any length.
pub fn encode_lab(map: &Map) -> Vec<u8> {
    let mut s = String::with_capacity(4096);
    let _ = writeln!(
        s,
        "<Lab Name=\"{}\" Height=\"{}\" Width=\"{}\">",
        Escaped(&map.name),
        G(map.height_m),
        G(map.width_m)
    );
    for b in &map.beacons {
        let _ = writeln!(s, "\t<Beacon X=\"{}\" Y=\"{}\" Height=\"{}\"/>", G(b.pos.x), G(b.pos.y), G(b.height_m));
    }
    for t in &map.targets {
        let _ = writeln!(s, "\t<Target X=\"{}\" Y=\"{}\" Radius=\"{}\"/>", G(t.pos.x), G(t.pos.y), G(t.radius_m));
    }
    for w in &map.walls {
        let _ = writeln!(s, "\t<Wall Height=\"{}\">", G(w.height_m));
        for c in &w.corners {
            let _ = writeln!(s, "\t\t<Corner X=\"{}\" Y=\"{}\"/>", G(c.x), G(c.y));
        }
        s.push_str("\t</Wall>\n");
    }
    s.push_str("</Lab>");
    finish(s)
}

/// `<Grid>` as the simulator sends it.
pub fn encode_grid(map: &Map) -> Vec<u8> {
    let mut s = String::from("<Grid>\n");
    for p in &map.grid {
        let _ = writeln!(s, "\t<Position X=\"{}\" Y=\"{}\" Dir=\"{}\"/>", G(p.pos.x), G(p.pos.y), G(p.heading_deg));
    }
    s.push_str("</Grid>");
    finish(s)
}

/// `<Restart/>`, sent to viewers after a `<Reset/>`.
pub fn encode_restart() -> Vec<u8> {
    finish("<Restart/>".into())
}

/// Decodes a `<Measures>` as a client reads it, every sensor the simulator sent: the reverse
/// of [`encode_measures`]. Elements a client does not know are passed over, as the stock
/// clients' handlers do.
pub fn decode_measures(datagram: &[u8]) -> Result<MeasuresData, DecodeError> {
    let el = parse(datagram, Repeats::Refused)?;
    if el.name != "Measures" {
        return Err(DecodeError::UnknownRoot(el.name));
    }
    let on = |e: &Element, name: &str| e.attr(name) == Some("On");
    let mut m = MeasuresData { time: el.num(&["Time"])?.map_or(0, |t| t.max(0.0) as u64), ..MeasuresData::default() };
    for c in &el.children {
        match c.name.as_str() {
            "Sensors" => {
                m.collision = c.attr("Collision").map(|v| v == "Yes");
                m.compass = c.num(&["Compass"])?;
                m.ground = c.num(&["Ground"])?.map(|g| g as i32);
                for s in &c.children {
                    match s.name.as_str() {
                        "IRSensor" | "BeaconSensor" => {
                            // Ids index a robot's sensors (at most 8) or the lab's beacons.
                            let id = parse_id(s)? as usize;
                            if id >= 64 {
                                return Err(DecodeError::OutOfRange { attr: "Id".into(), value: id.to_string() });
                            }
                            if s.name == "IRSensor" {
                                m.ir.resize(m.ir.len().max(id + 1), None);
                                m.ir[id] = s.num(&["Value"])?;
                            } else {
                                m.beacons.resize(m.beacons.len().max(id + 1), None);
                                m.beacons[id] = if s.attr("Value") == Some("NotVisible") {
                                    Some(None)
                                } else {
                                    Some(s.num(&["Value"])?)
                                };
                            }
                        }
                        "GPS" => m.gps = s.num(&["X"])?.zip(s.num(&["Y"])?),
                        "LineSensor" => {
                            m.line = s.attr("Value").map(|v| {
                                v.bytes()
                                    .take(8)
                                    .enumerate()
                                    .fold(0u8, |bits, (k, c)| bits | (u8::from(c == b'1') << k))
                            });
                        }
                        "Message" => {
                            let from = s.num(&["From"])?.map_or(0, |f| f.max(0.0) as u32);
                            m.messages.push((from, s.text.as_bytes().to_vec()));
                        }
                        "Score" => {
                            let whole = |name: &str| -> Result<u32, DecodeError> {
                                Ok(s.num(&[name])?.map_or(0, |v: f64| v.clamp(0.0, f64::from(u32::MAX)) as u32))
                            };
                            let mask = s.attr("VisitedMask").unwrap_or("");
                            m.score = Some(ScoreData {
                                score: s.num(&["Score"])?.map_or(0, |v: f64| v as i32),
                                arrival_time: whole("ArrivalTime")?,
                                returning_time: whole("ReturningTime")?,
                                collisions: whole("Collisions")?,
                                collision: s.attr("Collision") == Some("True"),
                                visited: mask
                                    .bytes()
                                    .take(64)
                                    .enumerate()
                                    .fold(0u64, |bits, (k, c)| bits | (u64::from(c == b'1') << k)),
                                targets: mask.len(),
                            });
                        }
                        _ => {}
                    }
                }
            }
            "Leds" => m.leds = [on(c, "EndLed"), on(c, "ReturningLed"), on(c, "VisitingLed")],
            "Buttons" => m.buttons = (on(c, "Start"), on(c, "Stop")),
            _ => {}
        }
    }
    Ok(m)
}

#[cfg(test)]
#[path = "codec_tests.rs"]
mod tests;
