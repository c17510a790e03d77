//! The chair emulator's furniture: boxes only its room has (the simulator's map need not), some
//! of them dark. A scenario writes them as `[[chair.room]]` tables and the runner hands them to
//! the emulator as `--box NAME,X0,Y0,X1,Y1[,dark]`: one type for both forms, with one check,
//! so what a scenario may hold is what the emulator takes.

use std::fmt;

use serde::Deserialize;

/// The command-line form of a box, as errors name it.
const BOX_FORM: &str = "a box NAME,X0,Y0,X1,Y1[,dark]";

/// A piece of furniture: an axis-aligned box in the emulator's room, solid to the chair and to
/// sonars.
///
/// On the command line `NAME,X0,Y0,X1,Y1[,dark]` (metres), which is also what
/// [`Display`](fmt::Display) writes; in a scenario a table with those keys (`dark` optional).
///
/// ```
/// use places::RoomBox;
/// let b = RoomBox::parse("table,17,6.1,17.6,6.4,dark")?;
/// assert!(b.dark);
/// assert_eq!(b.to_string(), "table,17,6.1,17.6,6.4,dark");
/// assert!(RoomBox::parse("t,3,2,1,4").is_err());
/// # Ok::<(), String>(())
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "RoomBoxTable")]
pub struct RoomBox {
    /// Label, for messages (no commas, not a number: the command-line form starts with it).
    pub name: String,
    /// Lower-left x, metres.
    pub x0: f64,
    /// Lower-left y, metres.
    pub y0: f64,
    /// Upper-right x, metres.
    pub x1: f64,
    /// Upper-right y, metres.
    pub y1: f64,
    /// A dark or soft surface: IR beams that meet it first get no echo (the thesis: real IR and
    /// sonar sensors miss black or rough surfaces). Sonars still see it.
    pub dark: bool,
}

impl RoomBox {
    /// Parses `NAME,X0,Y0,X1,Y1[,dark]`; the box must not be empty or upside down.
    pub fn parse(spec: &str) -> Result<RoomBox, String> {
        let parts: Vec<&str> = spec.split(',').map(str::trim).collect();
        let (dark, numbers) = match parts.as_slice() {
            [_, rest @ .., "dark"] => (true, rest),
            [_, rest @ ..] => (false, rest),
            [] => (false, &[][..]),
        };
        let name = parts.first().copied().unwrap_or_default();
        if name.is_empty() || name.parse::<f64>().is_ok() {
            return Err(format!("{spec:?}: {BOX_FORM} starts with a name"));
        }
        if numbers.len() != 4 {
            return Err(format!("{spec:?}: {BOX_FORM} has 4 numbers, got {}", numbers.len()));
        }
        let mut v = [0.0; 4];
        for (slot, text) in v.iter_mut().zip(numbers) {
            *slot = text
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{spec:?}: {text:?} is not a finite number ({BOX_FORM})"))?;
        }
        let [x0, y0, x1, y1] = v;
        RoomBox { name: name.to_owned(), x0, y0, x1, y1, dark }.checked().map_err(|e| format!("{spec:?}: {e}"))
    }

    /// Itself, if it has a name the command-line form can carry and is a box: every number
    /// finite, X0 < X1 and Y0 < Y1.
    pub fn checked(self) -> Result<Self, String> {
        if self.name.is_empty() || self.name.contains(',') || self.name.parse::<f64>().is_ok() {
            return Err(format!(
                "{BOX_FORM} starts with a name, without commas and not a number (got {:?})",
                self.name
            ));
        }
        let finite = [self.x0, self.y0, self.x1, self.y1].iter().all(|v| v.is_finite());
        if !(finite && self.x0 < self.x1 && self.y0 < self.y1) {
            return Err(format!(
                "room box {}: want X0 < X1 and Y0 < Y1, every number finite; got {},{},{},{}",
                self.name, self.x0, self.y0, self.x1, self.y1
            ));
        }
        Ok(self)
    }
}

/// The command-line form, `NAME,X0,Y0,X1,Y1[,dark]`.
impl fmt::Display for RoomBox {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{},{}", self.name, self.x0, self.y0, self.x1, self.y1)?;
        if self.dark { write!(f, ",dark") } else { Ok(()) }
    }
}

/// A room box's table in a scenario file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RoomBoxTable {
    name: String,
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    #[serde(default)]
    dark: bool,
}

impl TryFrom<RoomBoxTable> for RoomBox {
    type Error = String;
    fn try_from(t: RoomBoxTable) -> Result<Self, String> {
        RoomBox { name: t.name, x0: t.x0, y0: t.y0, x1: t.x1, y1: t.y1, dark: t.dark }.checked()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_read_with_and_without_dark_and_junk_is_named() {
        let b = RoomBox::parse("A, 17, 6.1, 17.6, 6.4").expect("valid");
        assert_eq!(b, RoomBox { name: "A".into(), x0: 17.0, y0: 6.1, x1: 17.6, y1: 6.4, dark: false });
        assert!(RoomBox::parse("B,1,2,3,4,dark").expect("valid").dark);
        for (bad, says) in [
            ("1,2,3,4", "starts with a name"),
            ("A,1,2,3", "has 4 numbers, got 3"),
            ("A,1,2,3,4,5", "has 4 numbers, got 5"),
            ("A,1,x,3,4", "\"x\" is not a finite number"),
            ("A,1,2,3,inf", "\"inf\" is not a finite number"),
            ("A,3,2,1,4", "want X0 < X1"),
            ("", "starts with a name"),
        ] {
            let e = RoomBox::parse(bad).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn both_forms_take_the_same_boxes_and_refuse_the_same_ones() {
        let table = |s: &str| serde_json::from_str::<RoomBox>(s).map_err(|e| e.to_string());
        let b = RoomBox::parse("desk, 9.5,5.5,10.5,6.5").expect("valid");
        assert_eq!(table(r#"{"name":"desk","x0":9.5,"y0":5.5,"x1":10.5,"y1":6.5}"#), Ok(b.clone()));
        assert_eq!(RoomBox::parse(&b.to_string()), Ok(b));
        for (spec, json, why) in [
            ("1,2,3,4", r#"{"name":"","x0":1,"y0":2,"x1":3,"y1":4}"#, "starts with a name"),
            ("7,1,2,3,4", r#"{"name":"7","x0":1,"y0":2,"x1":3,"y1":4}"#, "starts with a name"),
            ("t,3,2,1,4", r#"{"name":"t","x0":3,"y0":2,"x1":1,"y1":4}"#, "want X0 < X1"),
        ] {
            let cli = RoomBox::parse(spec).expect_err(spec);
            assert!(cli.contains(why) && cli.starts_with(&format!("{spec:?}")), "{spec}: {cli}");
            let file = table(json).expect_err(json);
            assert!(file.contains(why), "{json}: {file}");
        }
        assert!(table(r#"{"name":"a,b","x0":1,"y0":2,"x1":3,"y1":4}"#).expect_err("comma").contains("without commas"));
    }
}
