//! What a robot's sensors report each tick, and the messages it hears.

use thiserror::Error;

use super::RobotHandle;
use super::body::MAX_PROXIMITY;
use crate::math::Real;

/// At most this many beacons in a lab (the beacon sensor has one reading per beacon).
pub const MAX_BEACONS: usize = 16;
/// A robot may say at most this many bytes per tick.
pub const MAX_MESSAGE_BYTES: usize = 100;
/// A robot hears at most this many bytes per tick; later messages are dropped.
pub const MAX_INBOX_BYTES: usize = 400;

/// Elements of the line sensor (Ciber-Rato's, from its iris-ua version on).
pub const LINE_ELEMENTS: usize = 7;

/// Where line-sensor element `k` (0 = leftmost) looks, in the robot's frame from its centre of
/// movement (x ahead, y to the left), metres: a row across the robot 0.438 ahead, from 0.24
/// left to 0.24 right, 0.08 apart, as Ciber-Rato places it on its robot of diameter 1.
pub fn line_element(k: usize) -> (Real, Real) {
    (0.438, 0.24 - 0.08 * k as Real)
}

/// GPS fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GpsReading {
    /// x, metres.
    pub x_m: Real,
    /// y, metres.
    pub y_m: Real,
    /// Heading, degrees in (−180, 180].
    pub heading_deg: Real,
}

/// One tick's sensor readings of one robot, in SI units (degrees for angles).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorReadings {
    /// The tick these readings were reported at (latency makes the measurement older).
    pub tick: u64,
    /// Distance to the nearest obstacle in each proximity sensor's cone, metres, capped at the
    /// sensor's range; only the first `proximity_count` are meaningful.
    pub proximity_m: [Real; MAX_PROXIMITY],
    /// How many proximity sensors the robot has.
    pub proximity_count: u8,
    /// Compass heading in degrees, (−180, 180]; `None` when the compass is off.
    pub compass_deg: Option<Real>,
    /// GPS fix; `None` when GPS is off.
    pub gps: Option<GpsReading>,
    /// Bearing to each beacon relative to the heading, degrees; `None` when hidden, out of the
    /// aperture, or the beacon sensor is off. Only the first `beacon_count` are meaningful.
    pub beacons_deg: [Option<Real>; MAX_BEACONS],
    /// How many beacons the lab has.
    pub beacon_count: u8,
    /// Index of the target area under the centre of movement.
    pub ground: Option<u16>,
    /// The line sensor: bit `k` set when element `k` reads a line on the floor (element 0 is
    /// the leftmost of [`LINE_ELEMENTS`]; see [`line_element`]).
    pub line: u8,
    /// The robot's last move was refused (or, for a Real robot, it overlaps something).
    pub collision: bool,
    /// Cumulative wheel encoder ticks, left and right.
    pub encoder_ticks: [i64; 2],
}

impl SensorReadings {
    /// Readings before anything was measured: what latency reports for its first ticks.
    pub const EMPTY: SensorReadings = SensorReadings {
        tick: 0,
        proximity_m: [0.0; MAX_PROXIMITY],
        proximity_count: 0,
        compass_deg: None,
        gps: None,
        beacons_deg: [None; MAX_BEACONS],
        beacon_count: 0,
        ground: None,
        line: 0,
        collision: false,
        encoder_ticks: [0, 0],
    };

    /// The proximity distances of the robot's sensors.
    pub fn proximity(&self) -> &[Real] {
        &self.proximity_m[..self.proximity_count as usize]
    }

    /// The beacon bearings, one per beacon of the lab.
    pub fn beacons(&self) -> &[Option<Real>] {
        &self.beacons_deg[..self.beacon_count as usize]
    }
}

/// A message of at most [`MAX_MESSAGE_BYTES`] bytes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Message {
    len: u8,
    bytes: [u8; MAX_MESSAGE_BYTES],
}

impl std::fmt::Debug for Message {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Message({:?})", String::from_utf8_lossy(self.as_bytes()))
    }
}

/// A message longer than [`MAX_MESSAGE_BYTES`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[error("message of {len} bytes refused: at most {max} bytes may be sent per tick", max = MAX_MESSAGE_BYTES)]
pub struct MessageTooLong {
    /// Length given.
    pub len: usize,
}

impl Message {
    /// A message, refused when longer than [`MAX_MESSAGE_BYTES`].
    pub fn new(bytes: &[u8]) -> Result<Self, MessageTooLong> {
        if bytes.len() > MAX_MESSAGE_BYTES {
            return Err(MessageTooLong { len: bytes.len() });
        }
        let mut m = Self { len: bytes.len() as u8, bytes: [0; MAX_MESSAGE_BYTES] };
        m.bytes[..bytes.len()].copy_from_slice(bytes);
        Ok(m)
    }

    /// The bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len as usize]
    }

    /// Length in bytes.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether it is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// A message heard this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Heard {
    /// Who said it.
    pub from: RobotHandle,
    /// What was said.
    pub message: Message,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_over_a_hundred_bytes_are_refused() {
        assert!(Message::new(&[b'a'; 100]).is_ok());
        assert_eq!(Message::new(&[b'a'; 101]), Err(MessageTooLong { len: 101 }));
        assert_eq!(Message::new(b"hi").expect("short").as_bytes(), b"hi");
    }
}
