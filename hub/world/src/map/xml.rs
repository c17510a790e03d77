//! Reading the Ciber-Rato lab, grid and parameters XML files.
//!
//! This is the only module that talks to quick-xml. It reads a file in two passes: first into
//! a small element tree that remembers where each element starts (line and column), checking
//! the XML itself (tags closed and nested, attributes unique); then it interprets that tree as
//! a [`Lab`], a [`Grid`] or [`Params`], checking the values. Every problem becomes a
//! [`MapLoadError`] that says where it is and what was expected; no input makes it panic.
//!
//! Like Ciber-Rato, the reader ignores elements it does not know and stray text around the
//! elements, so every Ciber-Rato lab, grid and parameters file loads. Unlike Ciber-Rato, it
//! refuses what would silently lose part of a map: a lab without its size, a `<Row>` pattern
//! character that means nothing, text with no element at all, a DTD.
//!
//! ```
//! use world::map::xml::parse_lab;
//!
//! let lab = parse_lab(r#"<Lab Name="box" Width="4" Height="3">
//!     <Wall><Corner X="1" Y="1"/><Corner X="2" Y="1"/><Corner X="2" Y="2"/></Wall>
//! </Lab>"#).expect("valid lab");
//! assert_eq!(lab.walls.len(), 1);
//!
//! let err = parse_lab(r#"<Lab Width="4" Height="3"><Beacon X="1" Y="NaN"/></Lab>"#).unwrap_err();
//! assert_eq!(
//!     err.to_string(),
//!     "1:27: <Beacon> attribute Y=\"NaN\" is not a number: expected a finite decimal number such as 2.5"
//! );
//! ```

use std::fmt;
use std::path::{Path, PathBuf};

use nalgebra::Point2;
use quick_xml::XmlVersion;
use quick_xml::escape::EscapeError;
use quick_xml::events::attributes::AttrError;
use quick_xml::events::{BytesStart, Event};
use quick_xml::reader::Reader;

use super::{Beacon, DEFAULT_WALL_HEIGHT_M, Grid, Lab, Params, StartPose, Target, Wall, pattern};

/// A place in a text: 1-based line, and 1-based column counted in characters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TextPos {
    /// Line, from 1.
    pub line: u32,
    /// Column in characters (not bytes), from 1.
    pub column: u32,
}

impl TextPos {
    /// The position at `line`, `column` (both 1-based).
    pub const fn new(line: u32, column: u32) -> Self {
        Self { line, column }
    }
}

impl fmt::Display for TextPos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// Why a lab, grid or parameters file could not be loaded.
///
/// Variants with a position print it first, as `line:column: `, then say what is wrong and what
/// was expected.
#[derive(Debug, thiserror::Error)]
pub enum MapLoadError {
    /// An element is still open at the end of the file.
    #[error("{pos}: <{tag}> is never closed: expected </{tag}> before the end of the file")]
    UnclosedTag {
        /// Where the unclosed element's opening tag starts (its `<`); the innermost one if
        /// several are open.
        pos: TextPos,
        /// Its name.
        tag: String,
    },
    /// A closing tag does not match the element that is open.
    #[error("{pos}: </{found}> does not close the open <{expected}>: expected </{expected}> here")]
    MismatchedEndTag {
        /// Where the closing tag starts (its `<`).
        pos: TextPos,
        /// Name of the element that is open.
        expected: String,
        /// Name in the closing tag.
        found: String,
    },
    /// The XML is malformed in some other way (a tag without `>`, an unquoted attribute value,
    /// a closing tag with nothing open, a second root element, an unknown `&entity;`…).
    #[error("{pos}: malformed XML: {message}")]
    Syntax {
        /// Where the problem is.
        pos: TextPos,
        /// What is wrong, in a sentence.
        message: String,
    },
    /// An element has the same attribute twice.
    #[error("{pos}: <{element}> has the attribute {attr} twice: expected each attribute once")]
    DuplicateAttribute {
        /// Where the second occurrence of the attribute starts.
        pos: TextPos,
        /// Element name.
        element: String,
        /// Attribute name.
        attr: String,
    },
    /// The root element is not the kind of file that was asked for.
    #[error("{pos}: the root element is <{found}>: expected a {expected} file")]
    UnknownRoot {
        /// Where the root element starts.
        pos: TextPos,
        /// Its name.
        found: String,
        /// What would have been accepted, e.g. "Lab" or "Lab, Grid or Parameters".
        expected: &'static str,
    },
    /// The file holds no element at all (it is empty, or only whitespace and comments).
    #[error("the file holds no root element: expected <Lab>, <Grid> or <Parameters>")]
    Empty,
    /// The file holds text but no element: it is not XML at all.
    #[error("{pos}: text where the root element belongs: expected <Lab>, <Grid> or <Parameters>")]
    NoRootElement {
        /// Where the text starts (its first character that is not whitespace).
        pos: TextPos,
    },
    /// The file is not UTF-8 text.
    #[error("{pos}: the file is not UTF-8 text: expected UTF-8 (or plain ASCII) from this byte on")]
    NotUtf8 {
        /// Where the first byte that is not UTF-8 is (its column counts the characters before it).
        pos: TextPos,
    },
    /// The file is larger than [`MAX_FILE_BYTES`].
    #[error("{} is larger than {max} bytes: expected a lab, grid or parameters file of at most {max} bytes", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The limit, [`MAX_FILE_BYTES`].
        max: u64,
    },
    /// A `<!DOCTYPE>` declares a DTD (its internal subset, in `[...]`): iwsim does not read
    /// DTDs, so the entities it declares would be unknown.
    #[error(
        "{pos}: DTDs and entity declarations are not supported: expected no <!DOCTYPE [...]> \
         (write the characters themselves, UTF-8 encoded)"
    )]
    DtdNotSupported {
        /// Where the `<!DOCTYPE` starts.
        pos: TextPos,
    },
    /// An `&name;` reference that is not one of XML's five predefined entities.
    #[error(
        "{pos}: &{name}; is not an entity iwsim knows (DTDs and entity declarations are not \
         supported): expected &amp; &lt; &gt; &quot; &apos;, a character reference such as \
         &#233;, or the character itself"
    )]
    UnknownEntity {
        /// Where the `&` is.
        pos: TextPos,
        /// The entity's name.
        name: String,
    },
    /// A `<Row Pattern>` holds a character that draws nothing in Ciber-Rato and is not one of
    /// the characters its labs use, most likely a typo that would silently lose a wall.
    #[error(
        "{pos}: <Row> Pattern holds {found:?}, which means nothing in a pattern: expected only \
         space | - + / \\ . · T H X"
    )]
    BadPatternCharacter {
        /// Where the character is (the attribute value's start when it was written with
        /// entities, so that its column cannot be told).
        pos: TextPos,
        /// The character.
        found: char,
    },
    /// A required attribute is absent.
    #[error("{pos}: <{element}> has no {attr} attribute: expected {attr}=\"...\"")]
    MissingAttribute {
        /// Where the element starts.
        pos: TextPos,
        /// Element name.
        element: String,
        /// Name of the missing attribute.
        attr: String,
    },
    /// A numeric attribute is not a finite number (this includes `NaN` and `inf`).
    #[error("{pos}: <{element}> attribute {attr}=\"{value}\" is not a number: expected {expected}")]
    NotANumber {
        /// Where the element starts.
        pos: TextPos,
        /// Element name.
        element: String,
        /// Attribute name.
        attr: String,
        /// The attribute's text.
        value: String,
        /// What kind of number belongs there, with an example that would be accepted.
        expected: &'static str,
    },
    /// An attribute is readable but its value is not allowed (a zero width, a negative height
    /// or noise, a beacon outside the lab, a switch that is neither On nor Off…).
    #[error("{pos}: <{element}> attribute {attr}=\"{value}\" is out of range: expected {expected}")]
    OutOfRange {
        /// Where the element starts.
        pos: TextPos,
        /// Element name.
        element: String,
        /// Attribute name.
        attr: String,
        /// The attribute's text.
        value: String,
        /// What is allowed, in words.
        expected: &'static str,
    },
    /// A wall has fewer than three corners.
    #[error("{pos}: this <Wall> has {count} <Corner> element(s): expected at least 3")]
    TooFewCorners {
        /// Where the `<Wall>` starts.
        pos: TextPos,
        /// How many corners it has.
        count: usize,
    },
    /// A corner (of a wall, or of a wall made from a `<Row>`) lies outside the lab's rectangle.
    /// Corners on the border are fine.
    #[error(
        "{pos}: corner ({x}, {y}) lies outside the lab: expected 0 <= X <= {width} and \
         0 <= Y <= {height}"
    )]
    CornerOutsideLab {
        /// Where the `<Corner>` (or the `<Row>`) starts.
        pos: TextPos,
        /// Corner x, metres.
        x: f64,
        /// Corner y, metres.
        y: f64,
        /// Lab width, metres.
        width: f64,
        /// Lab height, metres.
        height: f64,
    },
    /// A wall's corners do not trace a simple polygon: it has zero area, or its edges cross or
    /// touch each other.
    #[error(
        "{pos}: this <Wall> has zero area or edges that cross: expected corners that trace \
         the wall's outline once, without crossing"
    )]
    DegenerateWall {
        /// Where the `<Wall>` starts.
        pos: TextPos,
    },
    /// A `builtin:NAME` spec names no built-in map.
    #[error("there is no built-in map named \"{name}\": expected one of {known}")]
    UnknownBuiltin {
        /// The name asked for.
        name: String,
        /// The built-in names, comma-separated.
        known: String,
    },
    /// The file could not be read.
    #[error("cannot read {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Any of the three kinds of file, as told by its root element.
#[derive(Debug, Clone, PartialEq)]
pub enum MapFile {
    /// A `<Lab>` file.
    Lab(Lab),
    /// A `<Grid>` file.
    Grid(Grid),
    /// A `<Parameters>` file.
    Params(Params),
}

/// The largest lab, grid or parameters file read, in bytes (16 MiB).
///
/// Ciber-Rato's largest shipped lab is a few kilobytes and iwsim's largest benchmark lab well
/// under a megabyte; the cap only stops a wrong path (`/dev/zero`, a disk image) from being read
/// until memory runs out.
pub const MAX_FILE_BYTES: u64 = places::files::MAX_TEXT_FILE_BYTES;

/// Reads a whole file as text: at most [`MAX_FILE_BYTES`], and UTF-8 (a byte-order mark is
/// kept; the parsers skip it).
///
/// This is the world crate's one file-reading function, and it reads through the one capped
/// reader of the files users write, `places::files::read_text` (regular files only: a FIFO
/// with no writer would block the open for ever, a device be read until the cap).
pub fn read_text(path: &Path) -> Result<String, MapLoadError> {
    use places::files::TextReadError;
    places::files::read_text(path).map_err(|e| match e {
        TextReadError::Io(source) => MapLoadError::Io { path: path.to_owned(), source },
        TextReadError::TooLarge { max } => MapLoadError::TooLarge { path: path.to_owned(), max },
        TextReadError::NotUtf8 { line, column } => {
            MapLoadError::NotUtf8 { pos: TextPos { line: saturate(line), column: saturate(column) } }
        }
    })
}

impl MapLoadError {
    /// Where in the file the problem is, for errors that know.
    pub fn pos(&self) -> Option<TextPos> {
        match self {
            Self::UnclosedTag { pos, .. }
            | Self::MismatchedEndTag { pos, .. }
            | Self::Syntax { pos, .. }
            | Self::DuplicateAttribute { pos, .. }
            | Self::UnknownRoot { pos, .. }
            | Self::NoRootElement { pos }
            | Self::NotUtf8 { pos }
            | Self::DtdNotSupported { pos }
            | Self::UnknownEntity { pos, .. }
            | Self::BadPatternCharacter { pos, .. }
            | Self::MissingAttribute { pos, .. }
            | Self::NotANumber { pos, .. }
            | Self::OutOfRange { pos, .. }
            | Self::TooFewCorners { pos, .. }
            | Self::CornerOutsideLab { pos, .. }
            | Self::DegenerateWall { pos } => Some(*pos),
            Self::Empty | Self::UnknownBuiltin { .. } | Self::Io { .. } | Self::TooLarge { .. } => None,
        }
    }

    /// The error as a user reads it about the file `file`: `file:line:column: what` when it
    /// has a place, `file: what` when not, and just `what` when it names the file itself
    /// (cannot read it, too large).
    ///
    /// ```
    /// use world::map::xml::parse_lab;
    ///
    /// let err = parse_lab("<Lab Width=\"x\"/>").unwrap_err();
    /// assert!(err.in_file("lab.xml").to_string().starts_with("lab.xml:1:1: <Lab> attribute Width"));
    /// let err = parse_lab("").unwrap_err();
    /// assert!(err.in_file("lab.xml").to_string().starts_with("lab.xml: the file holds no root element"));
    /// ```
    pub fn in_file<'a>(&'a self, file: &'a str) -> InFile<'a> {
        InFile { err: self, file }
    }
}

/// A [`MapLoadError`] shown with its file's name; see [`MapLoadError::in_file`].
#[derive(Debug, Clone, Copy)]
pub struct InFile<'a> {
    err: &'a MapLoadError,
    file: &'a str,
}

impl fmt::Display for InFile<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.err {
            MapLoadError::Io { .. } | MapLoadError::TooLarge { .. } => write!(f, "{}", self.err),
            // A positioned error prints `line:column: ` first, so the name joins it with `:`.
            err if err.pos().is_some() => write!(f, "{}:{err}", self.file),
            err => write!(f, "{}: {err}", self.file),
        }
    }
}

/// Parses a Ciber-Rato lab: `<Lab Name Width Height>` with `<Beacon>`, `<Target>`, `<Wall>`
/// and `<Row>` children.
pub fn parse_lab(text: &str) -> Result<Lab, MapLoadError> {
    let doc = Document::parse(text)?;
    lab_from(doc.root()?, &doc, "Lab")
}

/// Parses a Ciber-Rato start grid: `<Grid>` with `<Position X Y Dir/>` children. Without its
/// lab a position can be anywhere; [`parse_grid_for`] checks them against the lab.
pub fn parse_grid(text: &str) -> Result<Grid, MapLoadError> {
    let doc = Document::parse(text)?;
    grid_from(doc.root()?, &doc, "Grid", None)
}

/// [`parse_grid`] for `lab`: a position outside the lab's rectangle is an error at its line
/// and column (a robot started there would drive outside the border wall for good).
pub fn parse_grid_for(text: &str, lab: &Lab) -> Result<Grid, MapLoadError> {
    let doc = Document::parse(text)?;
    grid_from(doc.root()?, &doc, "Grid", Some(lab))
}

/// Parses a Ciber-Rato parameters file (root `<Parameters .../>`), starting from
/// [`Params::default`]. Attributes iwsim has no use for (scoring, file names…) are ignored.
pub fn parse_params(text: &str) -> Result<Params, MapLoadError> {
    let doc = Document::parse(text)?;
    params_from(doc.root()?, "Parameters")
}

/// Parses a lab, grid or parameters file, whichever its root element says it is.
pub fn parse_any(text: &str) -> Result<MapFile, MapLoadError> {
    const EXPECTED: &str = "Lab, Grid or Parameters";
    let doc = Document::parse(text)?;
    let root = doc.root()?;
    match root.name.as_str() {
        "Lab" => lab_from(root, &doc, EXPECTED).map(MapFile::Lab),
        "Grid" => grid_from(root, &doc, EXPECTED, None).map(MapFile::Grid),
        "Parameters" => params_from(root, EXPECTED).map(MapFile::Params),
        _ => Err(unknown_root(root, EXPECTED)),
    }
}

// ---------------------------------------------------------------------------------------------
// Pass 1: XML text to an element tree with positions.
// ---------------------------------------------------------------------------------------------

/// One element of the file.
#[derive(Debug)]
struct Element {
    name: String,
    pos: TextPos,
    /// Attributes in file order, values unescaped; names are unique.
    attrs: Vec<Attr>,
    /// Indices into [`Document::elements`], in file order.
    children: Vec<usize>,
}

/// One attribute of an element.
#[derive(Debug)]
struct Attr {
    name: String,
    /// The value, entities and whitespace normalised.
    value: String,
    /// Where the value's first character is (just after the opening quote).
    value_pos: TextPos,
    /// Whether the value is character for character as written on one line (no entity, no
    /// line break), so that its n-th character sits n columns after `value_pos`.
    verbatim: bool,
}

impl Element {
    fn attr(&self, name: &str) -> Option<&str> {
        self.attrs.iter().find(|a| a.name == name).map(|a| a.value.as_str())
    }

    /// Where the `index`-th character (0-based) of the attribute's value is written: exact
    /// when the value was written verbatim, else the value's start.
    fn char_pos(&self, name: &str, index: usize) -> TextPos {
        match self.attrs.iter().find(|a| a.name == name) {
            Some(a) if a.verbatim => {
                TextPos { line: a.value_pos.line, column: a.value_pos.column.saturating_add(saturate(index)) }
            }
            Some(a) => a.value_pos,
            None => self.pos,
        }
    }
}

/// A parsed file: its elements, the root being the first.
#[derive(Debug)]
struct Document {
    elements: Vec<Element>,
}

/// Turns byte offsets into lines and columns.
struct LineIndex<'a> {
    text: &'a str,
    /// Byte offset at which each line starts.
    line_starts: Vec<usize>,
}

impl<'a> LineIndex<'a> {
    fn new(text: &'a str) -> Self {
        let line_starts = std::iter::once(0)
            .chain(text.bytes().enumerate().filter(|(_, b)| *b == b'\n').map(|(i, _)| i + 1))
            .collect();
        Self { text, line_starts }
    }

    fn pos(&self, offset: usize) -> TextPos {
        let offset = offset.min(self.text.len());
        // The first line starts at 0 <= offset, so `line >= 1`.
        let line = self.line_starts.partition_point(|&start| start <= offset);
        let start = self.line_starts.get(line.wrapping_sub(1)).copied().unwrap_or(0);
        let before = self.text.as_bytes().get(start..offset).unwrap_or_default();
        // Count characters, not bytes: skip UTF-8 continuation bytes.
        let chars = before.iter().filter(|b| (**b & 0xC0) != 0x80).count();
        TextPos { line: saturate(line), column: saturate(chars + 1) }
    }
}

fn saturate(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl Document {
    fn parse(text: &str) -> Result<Document, MapLoadError> {
        // quick-xml skips a byte-order mark without counting it; so do we.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let index = LineIndex::new(text);
        let mut reader = Reader::from_str(text);
        {
            // Nesting is checked below against our own stack, which knows where each element
            // opened; Ciber-Rato-style stray text (even with a lone `&`) is ignored.
            let config = reader.config_mut();
            config.check_end_names = false;
            config.allow_unmatched_ends = true;
            config.allow_dangling_amp = true;
            config.expand_empty_elements = false;
        }
        let mut elements: Vec<Element> = Vec::new();
        let mut open: Vec<usize> = Vec::new();
        // Where the first stray text is, to report a file of text without any element.
        let mut first_text: Option<TextPos> = None;
        loop {
            let before = usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX);
            let event = match reader.read_event() {
                Ok(event) => event,
                Err(err) => {
                    let at = usize::try_from(reader.error_position()).unwrap_or(usize::MAX);
                    return Err(MapLoadError::Syntax { pos: index.pos(at), message: describe_xml_error(&err) });
                }
            };
            // Markup starts at its `<`; text events in between are reported separately, so the
            // `<` is the first one from where the previous event ended.
            let tag_start = text.get(before..).and_then(|rest| rest.find('<')).map_or(before, |i| before + i);
            match event {
                Event::Start(tag) => {
                    let id = add_element(&mut elements, &open, &tag, tag_start, &index)?;
                    open.push(id);
                }
                Event::Empty(tag) => {
                    add_element(&mut elements, &open, &tag, tag_start, &index)?;
                }
                Event::End(tag) => {
                    let found = tag.name().as_ref().to_owned();
                    let pos = index.pos(tag_start);
                    let Some(id) = open.pop() else {
                        return Err(MapLoadError::Syntax {
                            pos,
                            message: format!(
                                "</{found}> closes an element that was never opened: \
                                 expected no closing tag here"
                            ),
                        });
                    };
                    let expected = elements.get(id).map(|e| e.name.as_str()).unwrap_or_default();
                    if expected != found {
                        return Err(MapLoadError::MismatchedEndTag { pos, expected: expected.to_owned(), found });
                    }
                }
                Event::Text(content) => {
                    let content: &str = &content;
                    if !content.trim().is_empty() {
                        let lead = content.len() - content.trim_start().len();
                        first_text.get_or_insert_with(|| index.pos(before.saturating_add(lead)));
                        tracing::debug!(
                            at = %index.pos(before),
                            "ignoring stray text {:?}",
                            content.trim()
                        );
                    }
                }
                Event::CData(_) | Event::GeneralRef(_) => {
                    tracing::debug!(at = %index.pos(before), "ignoring stray character data");
                }
                // An internal subset can declare entities, which this reader never expands:
                // refuse it here, where it is written, rather than at the first use.
                Event::DocType(doctype) if doctype.contains('[') => {
                    return Err(MapLoadError::DtdNotSupported { pos: index.pos(tag_start) });
                }
                Event::Comment(_) | Event::Decl(_) | Event::PI(_) | Event::DocType(_) => {}
                Event::Eof => break,
            }
        }
        if let Some(element) = open.last().and_then(|&id| elements.get(id)) {
            return Err(MapLoadError::UnclosedTag { pos: element.pos, tag: element.name.clone() });
        }
        if elements.is_empty() {
            return Err(match first_text {
                Some(pos) => MapLoadError::NoRootElement { pos },
                None => MapLoadError::Empty,
            });
        }
        Ok(Document { elements })
    }

    /// The root element (the first one); a parsed document always has one.
    fn root(&self) -> Result<&Element, MapLoadError> {
        self.elements.first().ok_or(MapLoadError::Empty)
    }

    fn children<'d>(&'d self, parent: &'d Element) -> impl Iterator<Item = &'d Element> + 'd {
        parent.children.iter().filter_map(|&id| self.elements.get(id))
    }
}

/// Records a new element under the innermost open one (or as the root) and returns its index.
fn add_element(
    elements: &mut Vec<Element>,
    open: &[usize],
    tag: &BytesStart<'_>,
    start: usize,
    index: &LineIndex<'_>,
) -> Result<usize, MapLoadError> {
    let name = tag.name().as_ref().to_owned();
    let pos = index.pos(start);
    let parent = open.last().copied();
    if parent.is_none() && !elements.is_empty() {
        return Err(MapLoadError::Syntax {
            pos,
            message: format!("<{name}> is a second root element: expected everything inside the first one"),
        });
    }
    let raw: &str = tag;
    let mut attrs = Vec::new();
    for attr in tag.attributes() {
        // Attribute errors count bytes from just after the tag's `<`.
        let at = |offset: usize| index.pos(start.saturating_add(1).saturating_add(offset));
        match attr {
            Ok(attr) => {
                let key = attr.key.as_ref().to_owned();
                // The reader borrows from the text, so the value's address gives its offset.
                let value_at = (attr.value.as_ptr() as usize).checked_sub(index.text.as_ptr() as usize);
                let value_at = value_at.filter(|&at| at <= index.text.len()).unwrap_or(start);
                let value = attr.normalized_value(XmlVersion::Implicit1_0).map_err(|err| match err {
                    quick_xml::Error::Escape(EscapeError::UnrecognizedEntity(range, entity)) => {
                        // The range covers the name; the `&` is just before it.
                        let amp = value_at.saturating_add(range.start).saturating_sub(1);
                        MapLoadError::UnknownEntity { pos: index.pos(amp), name: entity }
                    }
                    err => MapLoadError::Syntax { pos, message: format!("<{name}> attribute {key}: {err}") },
                })?;
                let verbatim = *value == *attr.value;
                attrs.push(Attr { name: key, value: value.into_owned(), value_pos: index.pos(value_at), verbatim });
            }
            Err(AttrError::Duplicated(offset, _)) => {
                let attr = raw
                    .get(offset..)
                    .and_then(|rest| rest.split(|c: char| c == '=' || c.is_whitespace()).next())
                    .unwrap_or_default()
                    .to_owned();
                return Err(MapLoadError::DuplicateAttribute { pos: at(offset), element: name, attr });
            }
            Err(err) => {
                let (offset, message) = describe_attr_error(&err);
                return Err(MapLoadError::Syntax { pos: at(offset), message: format!("in <{name}>, {message}") });
            }
        }
    }
    let id = elements.len();
    elements.push(Element { name, pos, attrs, children: Vec::new() });
    if let Some(parent) = parent.and_then(|p| elements.get_mut(p)) {
        parent.children.push(id);
    }
    Ok(id)
}

fn describe_attr_error(err: &AttrError) -> (usize, String) {
    match err {
        AttrError::ExpectedEq(at) => (*at, "an attribute name must be followed by `=` and a quoted value".to_owned()),
        AttrError::ExpectedValue(at) => (*at, "`=` must be followed by a quoted value".to_owned()),
        AttrError::UnquotedValue(at) => (*at, "an attribute value must be enclosed in \" or '".to_owned()),
        AttrError::ExpectedQuote(at, quote) => {
            (*at, format!("an attribute value is not closed with {}", char::from(*quote)))
        }
        AttrError::Duplicated(at, _) => (*at, "an attribute appears twice".to_owned()),
    }
}

fn describe_xml_error(err: &quick_xml::Error) -> String {
    use quick_xml::errors::{Error, SyntaxError};
    match err {
        Error::Syntax(SyntaxError::UnclosedTag) => {
            "a tag opened here is never ended with `>`: expected `>` or `/>`".to_owned()
        }
        Error::Syntax(SyntaxError::UnclosedComment) => {
            "a comment opened here is never closed: expected `-->`".to_owned()
        }
        Error::Syntax(SyntaxError::UnclosedSingleQuotedAttributeValue)
        | Error::Syntax(SyntaxError::UnclosedDoubleQuotedAttributeValue) => {
            "an attribute value opened in this tag is never closed: expected a closing quote".to_owned()
        }
        other => other.to_string(),
    }
}

// ---------------------------------------------------------------------------------------------
// Pass 2: element tree to labs, grids and parameters.
// ---------------------------------------------------------------------------------------------

/// Corners this close outside the lab still count as on its border.
const BORDER_TOLERANCE_M: f64 = 1e-9;

const DEFAULT_LAB_NAME: &str = "NO NAMED LAB";
const DEFAULT_TARGET_RADIUS_M: f64 = 2.0;

/// The characters a `<Row Pattern>` may hold: those Ciber-Rato's shipped labs use. Only `|` and
/// `-` draw walls (see [`pattern`]); the others are drawn by hand as junctions, diagonals or
/// marks, and carry no wall in Ciber-Rato either.
pub const PATTERN_CHARACTERS: &str = " |-+/\\.·THX";

fn unknown_root(root: &Element, expected: &'static str) -> MapLoadError {
    MapLoadError::UnknownRoot { pos: root.pos, found: root.name.clone(), expected }
}

fn ignore(child: &Element, parent: &str) {
    tracing::debug!(at = %child.pos, "ignoring unknown element <{}> in <{}>", child.name, parent);
}

/// The hint a [`MapLoadError::NotANumber`] gives for a decimal attribute.
const DECIMAL: &str = "a finite decimal number such as 2.5";
/// The hint a [`MapLoadError::NotANumber`] gives for a whole-number attribute (a `<Row Pos>`,
/// a count, a latency), which refuses "2.5".
const WHOLE_EXAMPLE: &str = "a whole number of 0 or more, such as 12";

/// The attribute as a finite number, or `None` when absent.
fn number(element: &Element, attr: &str) -> Result<Option<f64>, MapLoadError> {
    number_as(element, attr, DECIMAL)
}

/// [`number`], with `expected` as the hint when the text is not a number.
fn number_as(element: &Element, attr: &str, expected: &'static str) -> Result<Option<f64>, MapLoadError> {
    let Some(raw) = element.attr(attr) else {
        return Ok(None);
    };
    match raw.trim().parse::<f64>() {
        Ok(value) if value.is_finite() => Ok(Some(value)),
        _ => Err(MapLoadError::NotANumber {
            pos: element.pos,
            element: element.name.clone(),
            attr: attr.to_owned(),
            value: raw.to_owned(),
            expected,
        }),
    }
}

fn required(element: &Element, attr: &str) -> Result<f64, MapLoadError> {
    required_as(element, attr, DECIMAL)
}

fn required_as(element: &Element, attr: &str, expected: &'static str) -> Result<f64, MapLoadError> {
    number_as(element, attr, expected)?.ok_or_else(|| MapLoadError::MissingAttribute {
        pos: element.pos,
        element: element.name.clone(),
        attr: attr.to_owned(),
    })
}

fn out_of_range(element: &Element, attr: &str, expected: &'static str) -> MapLoadError {
    MapLoadError::OutOfRange {
        pos: element.pos,
        element: element.name.clone(),
        attr: attr.to_owned(),
        value: element.attr(attr).unwrap_or_default().to_owned(),
        expected,
    }
}

/// `value` if `ok(value)`, else an out-of-range error for `attr`.
fn check(
    element: &Element,
    attr: &str,
    value: f64,
    ok: impl Fn(f64) -> bool,
    expected: &'static str,
) -> Result<f64, MapLoadError> {
    if ok(value) { Ok(value) } else { Err(out_of_range(element, attr, expected)) }
}

const POSITIVE: &str = "a number greater than 0";
const NOT_NEGATIVE: &str = "a number of 0 or more";
const WHOLE: &str = "a whole number of 0 or more";

fn lab_from(root: &Element, doc: &Document, expected: &'static str) -> Result<Lab, MapLoadError> {
    if root.name != "Lab" {
        return Err(unknown_root(root, expected));
    }
    let name = root.attr("Name").unwrap_or(DEFAULT_LAB_NAME).to_owned();
    // Ciber-Rato falls back to 16 m when a size is missing; a lab that forgot its size is more
    // likely a mistake than a 16 m lab, so the size is required.
    const SIZE: &str = "a number of metres greater than 0 and at most 10000";
    let in_size = |v: f64| v > 0.0 && v <= crate::MAX_LAB_SIZE_M;
    let width = check(root, "Width", required(root, "Width")?, in_size, SIZE)?;
    let height = check(root, "Height", required(root, "Height")?, in_size, SIZE)?;
    let mut lab =
        Lab { name, width_m: width, height_m: height, walls: Vec::new(), beacons: Vec::new(), targets: Vec::new() };
    let inside_x = |v: f64| (-BORDER_TOLERANCE_M..=width + BORDER_TOLERANCE_M).contains(&v);
    let inside_y = |v: f64| (-BORDER_TOLERANCE_M..=height + BORDER_TOLERANCE_M).contains(&v);
    const INSIDE_X: &str = "an x inside the lab, from 0 to its Width";
    const INSIDE_Y: &str = "a y inside the lab, from 0 to its Height";

    for child in doc.children(root) {
        match child.name.as_str() {
            "Beacon" => {
                let x = check(child, "X", required(child, "X")?, inside_x, INSIDE_X)?;
                let y = check(child, "Y", required(child, "Y")?, inside_y, INSIDE_Y)?;
                let h = number(child, "Height")?.unwrap_or(0.0);
                let h = check(child, "Height", h, |v| v >= 0.0, NOT_NEGATIVE)?;
                lab.beacons.push(Beacon { pos: Point2::new(x, y), height_m: h });
            }
            "Target" => {
                let x = check(child, "X", required(child, "X")?, inside_x, INSIDE_X)?;
                let y = check(child, "Y", required(child, "Y")?, inside_y, INSIDE_Y)?;
                let r = number(child, "Radius")?.unwrap_or(DEFAULT_TARGET_RADIUS_M);
                let r = check(child, "Radius", r, |v| v > 0.0, POSITIVE)?;
                lab.targets.push(Target { pos: Point2::new(x, y), radius_m: r });
            }
            "Wall" => lab.walls.push(wall_from(child, doc, width, height)?),
            "Row" => {
                let pos = required_as(child, "Pos", WHOLE_EXAMPLE)?;
                let pos = check(child, "Pos", pos, |v| v >= 0.0 && v.fract() == 0.0 && v <= 1e9, WHOLE)?;
                let Some(pattern) = child.attr("Pattern") else {
                    return Err(MapLoadError::MissingAttribute {
                        pos: child.pos,
                        element: child.name.clone(),
                        attr: "Pattern".to_owned(),
                    });
                };
                if let Some((i, found)) = pattern.chars().enumerate().find(|(_, c)| !PATTERN_CHARACTERS.contains(*c)) {
                    return Err(MapLoadError::BadPatternCharacter { pos: child.char_pos("Pattern", i), found });
                }
                let h = number(child, "Height")?.unwrap_or(DEFAULT_WALL_HEIGHT_M);
                let h = check(child, "Height", h, |v| v >= 0.0, NOT_NEGATIVE)?;
                // `pos` is a whole number below 1e9, so the cast is exact.
                for wall in pattern::expand_row(pos as i64, pattern, h) {
                    for corner in &wall.corners {
                        if !inside_x(corner.x) || !inside_y(corner.y) {
                            return Err(MapLoadError::CornerOutsideLab {
                                pos: child.pos,
                                x: corner.x,
                                y: corner.y,
                                width,
                                height,
                            });
                        }
                    }
                    lab.walls.push(wall);
                }
            }
            _ => ignore(child, "Lab"),
        }
    }
    Ok(lab)
}

fn wall_from(element: &Element, doc: &Document, width: f64, height: f64) -> Result<Wall, MapLoadError> {
    let h = number(element, "Height")?.unwrap_or(DEFAULT_WALL_HEIGHT_M);
    let h = check(element, "Height", h, |v| v >= 0.0, NOT_NEGATIVE)?;
    let corner_elements: Vec<&Element> = doc
        .children(element)
        .filter(|child| {
            let is_corner = child.name == "Corner";
            if !is_corner {
                ignore(child, "Wall");
            }
            is_corner
        })
        .collect();
    if corner_elements.len() < 3 {
        return Err(MapLoadError::TooFewCorners { pos: element.pos, count: corner_elements.len() });
    }
    let mut corners: Vec<Point2<f64>> = Vec::with_capacity(corner_elements.len());
    for corner in corner_elements {
        let x = required(corner, "X")?;
        let y = required(corner, "Y")?;
        let inside = (-BORDER_TOLERANCE_M..=width + BORDER_TOLERANCE_M).contains(&x)
            && (-BORDER_TOLERANCE_M..=height + BORDER_TOLERANCE_M).contains(&y);
        if !inside {
            return Err(MapLoadError::CornerOutsideLab { pos: corner.pos, x, y, width, height });
        }
        // A corner repeated right after itself (or the first one repeated at the end, as some
        // tools close polygons) adds no edge.
        if corners.last() != Some(&Point2::new(x, y)) {
            corners.push(Point2::new(x, y));
        }
    }
    if corners.len() > 1 && corners.first() == corners.last() {
        corners.pop();
    }
    let area = signed_area(&corners);
    if corners.len() < 3 || area == 0.0 || !is_simple(&corners) {
        return Err(MapLoadError::DegenerateWall { pos: element.pos });
    }
    if area < 0.0 {
        // Clockwise: reverse the order, keeping the first corner first.
        if let Some(rest) = corners.get_mut(1..) {
            rest.reverse();
        }
    }
    Ok(Wall { height_m: h, corners })
}

/// The signed area (positive when counter-clockwise), by the shoelace formula.
fn signed_area(corners: &[Point2<f64>]) -> f64 {
    let n = corners.len();
    let twice: f64 =
        corners.iter().zip(corners.iter().cycle().skip(1)).take(n).map(|(a, b)| a.x * b.y - b.x * a.y).sum();
    twice / 2.0
}

/// Cross product of `b - a` and `c - a`: positive when `a, b, c` turn left.
fn orient(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>) -> f64 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// Whether `p` (known collinear with `a`–`b`) lies within the segment's bounding box.
fn within(a: Point2<f64>, b: Point2<f64>, p: Point2<f64>) -> bool {
    a.x.min(b.x) <= p.x && p.x <= a.x.max(b.x) && a.y.min(b.y) <= p.y && p.y <= a.y.max(b.y)
}

/// Whether closed segments `p1`–`p2` and `q1`–`q2` share at least one point.
fn segments_touch(p1: Point2<f64>, p2: Point2<f64>, q1: Point2<f64>, q2: Point2<f64>) -> bool {
    let d1 = orient(q1, q2, p1);
    let d2 = orient(q1, q2, p2);
    let d3 = orient(p1, p2, q1);
    let d4 = orient(p1, p2, q2);
    let opposite = |a: f64, b: f64| (a > 0.0 && b < 0.0) || (a < 0.0 && b > 0.0);
    if opposite(d1, d2) && opposite(d3, d4) {
        return true;
    }
    (d1 == 0.0 && within(q1, q2, p1))
        || (d2 == 0.0 && within(q1, q2, p2))
        || (d3 == 0.0 && within(p1, p2, q1))
        || (d4 == 0.0 && within(p1, p2, q2))
}

/// Whether the closed polygon (no repeated consecutive corners) is simple: no two edges meet
/// except neighbours at their shared corner, and no edge doubles back over its neighbour.
fn is_simple(corners: &[Point2<f64>]) -> bool {
    let n = corners.len();
    let corner = |i: usize| corners.get(i % n).copied().unwrap_or_else(Point2::origin);
    for i in 0..n {
        let (a, b, c) = (corner(i), corner(i + 1), corner(i + 2));
        // Neighbouring edges a-b and b-c: they fold over each other when collinear and
        // pointing back.
        let back = (b - a).dot(&(c - b)) < 0.0;
        if orient(a, b, c) == 0.0 && back {
            return false;
        }
        // Edges that share no corner must not meet at all. Edge i and edge j (j > i + 1),
        // except the last edge against the first.
        for j in (i + 2)..n {
            if i == 0 && j == n - 1 {
                continue;
            }
            if segments_touch(a, b, corner(j), corner(j + 1)) {
                return false;
            }
        }
    }
    true
}

fn grid_from(root: &Element, doc: &Document, expected: &'static str, lab: Option<&Lab>) -> Result<Grid, MapLoadError> {
    if root.name != "Grid" {
        return Err(unknown_root(root, expected));
    }
    let mut grid = Grid::default();
    for child in doc.children(root) {
        if child.name != "Position" {
            ignore(child, "Grid");
            continue;
        }
        let mut x = required(child, "X")?;
        let mut y = required(child, "Y")?;
        if let Some(lab) = lab {
            const INSIDE_X: &str = "an x inside the lab, from 0 to its Width";
            const INSIDE_Y: &str = "a y inside the lab, from 0 to its Height";
            x = check(child, "X", x, |v| (0.0..=lab.width_m).contains(&v), INSIDE_X)?;
            y = check(child, "Y", y, |v| (0.0..=lab.height_m).contains(&v), INSIDE_Y)?;
        }
        let dir = number(child, "Dir")?.unwrap_or(0.0);
        grid.poses.push(StartPose { pos: Point2::new(x, y), heading_deg: dir });
    }
    Ok(grid)
}

fn params_from(root: &Element, expected: &'static str) -> Result<Params, MapLoadError> {
    if root.name != "Parameters" {
        return Err(unknown_root(root, expected));
    }
    let mut p = Params::default();
    for Attr { name, value: raw, .. } in &root.attrs {
        let attr = name.as_str();
        let value = || -> Result<f64, MapLoadError> { required(root, attr) };
        let not_negative = || -> Result<f64, MapLoadError> { check(root, attr, value()?, |v| v >= 0.0, NOT_NEGATIVE) };
        let positive = || -> Result<f64, MapLoadError> { check(root, attr, value()?, |v| v > 0.0, POSITIVE) };
        let whole = |max: f64| -> Result<f64, MapLoadError> {
            let v = required_as(root, attr, WHOLE_EXAMPLE)?;
            check(root, attr, v, |v| v >= 0.0 && v.fract() == 0.0 && v <= max, WHOLE)
        };
        let count = || -> Result<u32, MapLoadError> { Ok(whole(f64::from(u32::MAX))? as u32) };
        let switch = || -> Result<bool, MapLoadError> {
            match raw.trim().to_ascii_lowercase().as_str() {
                "on" | "true" | "yes" => Ok(true),
                "off" | "false" | "no" => Ok(false),
                _ => Err(out_of_range(root, attr, "On or Off (or True/False, Yes/No)")),
            }
        };
        match attr {
            // `whole` bounds the values, so the casts are exact.
            "SimTime" => p.sim_time_ticks = whole(9.007_199_254_740_992e15)? as u64,
            "CycleTime" => p.cycle_ms = count()?,
            "CompassNoise" => p.noise.compass_deg = not_negative()?,
            "BeaconNoise" => p.noise.beacon_deg = not_negative()?,
            "ObstacleNoise" => p.noise.proximity_m = not_negative()?,
            "MotorsNoise" => p.noise.motor_frac = not_negative()? / 100.0,
            "GPSLinNoise" => p.noise.gps_pos_m = not_negative()?,
            "GPSDirNoise" => p.noise.gps_heading_deg = not_negative()?,
            "EncoderNoise" => p.noise.encoder_slip_frac = not_negative()? / 100.0,
            "GPS" => p.sensors.gps = switch()?,
            "BeaconSensor" => p.sensors.beacon = switch()?,
            "CompassSensor" => p.sensors.compass = switch()?,
            "NRequestsPerCycle" | "RequestsPerCycle" => p.requests.per_cycle = count()?,
            "ObstacleRequestable" => p.requests.obstacle = switch()?,
            "BeaconRequestable" => p.requests.beacon = switch()?,
            "GroundRequestable" => p.requests.ground = switch()?,
            "CompassRequestable" => p.requests.compass = switch()?,
            "CollisionRequestable" => p.requests.collision = switch()?,
            "ObstacleLatency" => p.latency.proximity = count()?,
            "BeaconLatency" => p.latency.beacon = count()?,
            "GroundLatency" => p.latency.ground = count()?,
            "CompassLatency" => p.latency.compass = count()?,
            "CollisionLatency" | "collisionLatency" => p.latency.collision = count()?,
            "GPSLatency" => p.latency.gps = count()?,
            "BeaconAperture" => p.beacon_aperture_rad = not_negative()?,
            "ObstacleRange" => p.proximity_range_m = Some(positive()?),
            "MessageRange" => p.message_range_m = not_negative()?,
            "EncoderTicks" => {
                p.encoder_ticks_per_rev = count()?;
                if p.encoder_ticks_per_rev == 0 {
                    return Err(out_of_range(root, attr, "a whole number greater than 0"));
                }
            }
            "WheelRadius" => p.wheel_radius_m = positive()?,
            "KeyTime" => p.challenge.key_time_ticks = whole(9.007_199_254_740_992e15)? as u64,
            "ScoreSensor" => p.challenge.score_sensor = switch()?,
            "ReturnTimePenalty" => p.challenge.return_time_penalty = count()?,
            "ArrivalTimePenalty" => p.challenge.arrival_time_penalty = count()?,
            "CollisionWallPenalty" => p.challenge.collision_wall_penalty = count()?,
            "CollisionRobotPenalty" => p.challenge.collision_robot_penalty = count()?,
            "TargetReward" => p.challenge.target_reward = count()?,
            "HomeReward" => p.challenge.home_reward = count()?,
            "Scoring" => {
                p.challenge.scoring = crate::challenge::Scoring::from_number(count()?)
                    .map_err(|_| out_of_range(root, attr, "a scoring mode, 0 to 7"))?
            }
            "LineSensorTrueProb" => {
                let truth = check(root, attr, value()?, |v| (0.0..=1.0).contains(&v), "a probability, from 0 to 1")?;
                p.noise.line_flip_prob = 1.0 - truth;
            }
            _ => tracing::debug!(at = %root.pos, "ignoring parameter {attr}={raw:?}"),
        }
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(line: u32, column: u32) -> TextPos {
        TextPos::new(line, column)
    }

    fn lab_err(text: &str) -> MapLoadError {
        match parse_lab(text) {
            Ok(lab) => panic!("expected an error, got {lab:?}"),
            Err(err) => err,
        }
    }

    fn lab_ok(text: &str) -> Lab {
        match parse_lab(text) {
            Ok(lab) => lab,
            Err(err) => panic!("expected a lab, got: {err}"),
        }
    }

    fn params_ok(text: &str) -> Params {
        match parse_params(text) {
            Ok(params) => params,
            Err(err) => panic!("expected parameters, got: {err}"),
        }
    }

    fn corners(wall: &Wall) -> Vec<(f64, f64)> {
        wall.corners.iter().map(|c| (c.x, c.y)).collect()
    }

    #[test]
    fn an_element_left_open_at_the_end_is_reported_at_its_opening_tag() {
        let err = lab_err("<Lab Width=\"10\" Height=\"10\">\n  <Wall>\n    <Corner X=\"1\" Y=\"1\"/>\n");
        assert!(matches!(&err, MapLoadError::UnclosedTag { pos, tag } if *pos == at(2, 3) && tag == "Wall"), "{err:?}");
        assert!(err.to_string().starts_with("2:3: <Wall> is never closed"), "{err}");
    }

    #[test]
    fn a_lone_open_root_is_an_unclosed_tag() {
        let err = lab_err("\n\n   <Lab Name=\"x\">");
        assert!(matches!(&err, MapLoadError::UnclosedTag { pos, tag } if *pos == at(3, 4) && tag == "Lab"), "{err:?}");
    }

    #[test]
    fn a_wall_with_two_corners_is_too_few() {
        let text = "<Lab Width=\"16\" Height=\"16\">\n<Wall Height=\"1\">\n  <Corner X=\"1\" Y=\"1\"/>\n  <Corner X=\"2\" Y=\"1\"/>\n</Wall>\n</Lab>";
        let err = lab_err(text);
        assert!(matches!(err, MapLoadError::TooFewCorners { pos, count: 2 } if pos == at(2, 1)), "{err:?}");
    }

    #[test]
    fn nan_is_not_a_number() {
        let text = "<Lab Width=\"16\" Height=\"16\">\n  <Wall>\n    <Corner X=\"1\" Y=\"NaN\"/>\n    <Corner X=\"2\" Y=\"1\"/>\n    <Corner X=\"2\" Y=\"2\"/>\n  </Wall>\n</Lab>";
        let err = lab_err(text);
        assert!(
            matches!(&err, MapLoadError::NotANumber { pos, element, attr, value, .. }
                if *pos == at(3, 5) && element == "Corner" && attr == "Y" && value == "NaN"),
            "{err:?}"
        );
        assert!(err.to_string().starts_with("3:5: <Corner> attribute Y=\"NaN\" is not a number"));
    }

    #[test]
    fn infinity_is_not_a_number() {
        let err = lab_err("<Lab Width=\"inf\"/>");
        assert!(
            matches!(&err, MapLoadError::NotANumber { pos, attr, .. } if *pos == at(1, 1) && attr == "Width"),
            "{err:?}"
        );
    }

    #[test]
    fn text_where_a_number_belongs_is_not_a_number() {
        let err = lab_err("<Lab Width=\"16\" Height=\"16\">\r\n\t<Beacon X=\"1,5\" Y=\"2\"/>\r\n</Lab>");
        assert!(
            matches!(&err, MapLoadError::NotANumber { pos, element, attr, value, .. }
                if *pos == at(2, 2) && element == "Beacon" && attr == "X" && value == "1,5"),
            "{err:?}"
        );
    }

    #[test]
    fn columns_count_characters_not_bytes() {
        let err = lab_err("<Lab Name=\"Ção\" Width=\"16\" Height=\"16\"><Beacon X=\"1\" Y=\"é\"/></Lab>");
        assert!(matches!(err, MapLoadError::NotANumber { pos, .. } if pos == at(1, 40)), "{err:?}");
    }

    #[test]
    fn a_corner_outside_the_lab_is_reported_at_the_corner() {
        let text = "<Lab Width=\"10\" Height=\"5\">\n  <Wall>\n    <Corner X=\"1\" Y=\"1\"/>\n    <Corner X=\"10.5\" Y=\"1\"/>\n    <Corner X=\"2\" Y=\"2\"/>\n  </Wall>\n</Lab>";
        let err = lab_err(text);
        assert!(
            matches!(err, MapLoadError::CornerOutsideLab { pos, x, y, width, height }
                if pos == at(4, 5) && x == 10.5 && y == 1.0 && width == 10.0 && height == 5.0),
            "{err:?}"
        );
    }

    #[test]
    fn corners_on_the_border_are_inside_the_lab() {
        let lab = lab_ok(
            "<Lab Width=\"10\" Height=\"5\"><Wall>\
             <Corner X=\"0\" Y=\"0\"/><Corner X=\"10\" Y=\"0\"/><Corner X=\"10.0000000001\" Y=\"5\"/>\
             </Wall></Lab>",
        );
        assert_eq!(lab.walls.len(), 1);
        let err = lab_err(
            "<Lab Width=\"10\" Height=\"5\"><Wall>\
             <Corner X=\"0\" Y=\"0\"/><Corner X=\"10\" Y=\"0\"/><Corner X=\"10\" Y=\"-0.001\"/>\
             </Wall></Lab>",
        );
        assert!(matches!(err, MapLoadError::CornerOutsideLab { .. }), "{err:?}");
    }

    #[test]
    fn a_repeated_attribute_is_reported_at_its_second_occurrence() {
        let err = lab_err("<Lab Width=\"16\" Height=\"16\">\n  <Beacon X=\"1\" Y=\"2\" X=\"3\"/>\n</Lab>");
        assert!(
            matches!(&err, MapLoadError::DuplicateAttribute { pos, element, attr }
                if *pos == at(2, 23) && element == "Beacon" && attr == "X"),
            "{err:?}"
        );
    }

    #[test]
    fn a_grid_given_as_a_lab_has_an_unknown_root() {
        let err = lab_err("<?xml version=\"1.0\"?>\n<Grid>\n</Grid>\n");
        assert!(
            matches!(&err, MapLoadError::UnknownRoot { pos, found, expected: "Lab" }
                if *pos == at(2, 1) && found == "Grid"),
            "{err:?}"
        );
    }

    #[test]
    fn a_closing_tag_for_the_wrong_element_is_mismatched() {
        let err = lab_err("<Lab Width=\"16\" Height=\"16\">\n  <Wall>\n  </Lab>\n");
        assert!(
            matches!(&err, MapLoadError::MismatchedEndTag { pos, expected, found }
                if *pos == at(3, 3) && expected == "Wall" && found == "Lab"),
            "{err:?}"
        );
    }

    #[test]
    fn a_corner_without_y_is_missing_an_attribute() {
        let text = "<Lab Width=\"16\" Height=\"16\">\n <Wall>\n  <Corner X=\"1\" Y=\"1\"/>\n  <Corner X=\"2\"/>\n  <Corner X=\"2\" Y=\"2\"/>\n </Wall>\n</Lab>";
        let err = lab_err(text);
        assert!(
            matches!(&err, MapLoadError::MissingAttribute { pos, element, attr }
                if *pos == at(4, 3) && element == "Corner" && attr == "Y"),
            "{err:?}"
        );
    }

    #[test]
    fn a_bow_tie_wall_is_degenerate() {
        let text = "<Lab Width=\"16\" Height=\"16\">\n<Wall>\n<Corner X=\"0\" Y=\"0\"/><Corner X=\"2\" Y=\"2\"/>\
                    <Corner X=\"2\" Y=\"0\"/><Corner X=\"0\" Y=\"2\"/>\n</Wall>\n</Lab>";
        let err = lab_err(text);
        assert!(matches!(err, MapLoadError::DegenerateWall { pos } if pos == at(2, 1)), "{err:?}");
    }

    #[test]
    fn a_wall_whose_edges_cross_is_degenerate_even_with_area() {
        let text = "<Lab Width=\"16\" Height=\"16\">\n  <Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"6\" Y=\"1\"/><Corner X=\"6\" Y=\"4\"/>\
                    <Corner X=\"2\" Y=\"4\"/><Corner X=\"4\" Y=\"0.5\"/></Wall>\n</Lab>";
        let err = lab_err(text);
        assert!(matches!(err, MapLoadError::DegenerateWall { pos } if pos == at(2, 3)), "{err:?}");
    }

    #[test]
    fn a_wall_with_collinear_corners_is_degenerate() {
        let text = "<Lab Width=\"16\" Height=\"16\"><Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"2\" Y=\"2\"/><Corner X=\"3\" Y=\"3\"/></Wall></Lab>";
        let err = lab_err(text);
        assert!(matches!(err, MapLoadError::DegenerateWall { pos } if pos == at(1, 29)), "{err:?}");
    }

    #[test]
    fn a_wall_that_doubles_back_on_itself_is_degenerate() {
        // A square with a spike: (3,1) -> (4,1) -> (3,1) folds the edge back.
        let text = "<Lab Width=\"16\" Height=\"16\"><Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"3\" Y=\"1\"/><Corner X=\"4\" Y=\"1\"/>\
                    <Corner X=\"3\" Y=\"1.0\"/><Corner X=\"3\" Y=\"3\"/><Corner X=\"1\" Y=\"3\"/></Wall></Lab>";
        let err = lab_err(text);
        assert!(matches!(err, MapLoadError::DegenerateWall { .. }), "{err:?}");
    }

    #[test]
    fn clockwise_walls_come_back_counter_clockwise_from_the_same_first_corner() {
        let lab = lab_ok(
            "<Lab Width=\"16\" Height=\"16\"><Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"1\" Y=\"2\"/>\
             <Corner X=\"2\" Y=\"2\"/><Corner X=\"2\" Y=\"1\"/></Wall></Lab>",
        );
        assert_eq!(corners(&lab.walls[0]), [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)]);
        assert!(signed_area(&lab.walls[0].corners) > 0.0);
    }

    #[test]
    fn counter_clockwise_walls_keep_their_order() {
        let lab = lab_ok(
            "<Lab Width=\"16\" Height=\"16\"><Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"2\" Y=\"1\"/>\
             <Corner X=\"2\" Y=\"2\"/><Corner X=\"1\" Y=\"2\"/></Wall></Lab>",
        );
        assert_eq!(corners(&lab.walls[0]), [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)]);
    }

    #[test]
    fn a_closing_corner_that_repeats_the_first_is_dropped() {
        let lab = lab_ok(
            "<Lab Width=\"16\" Height=\"16\"><Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"2\" Y=\"1\"/><Corner X=\"2\" Y=\"2\"/>\
             <Corner X=\"1\" Y=\"1\"/></Wall></Lab>",
        );
        assert_eq!(corners(&lab.walls[0]), [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)]);
    }

    #[test]
    fn an_empty_lab_gets_ciber_rato_default_name() {
        let lab = lab_ok("<Lab Width=\"16\" Height=\"16\"/>");
        assert_eq!(lab.name, "NO NAMED LAB");
        assert_eq!((lab.width_m, lab.height_m), (16.0, 16.0));
        assert!(lab.walls.is_empty() && lab.beacons.is_empty() && lab.targets.is_empty());
    }

    #[test]
    fn a_lab_without_width_or_height_is_refused_rather_than_given_16_m() {
        for (text, want) in
            [("<Lab Height=\"14\"/>", "Width"), ("\n <Lab Width=\"28\"/>", "Height"), ("<Lab/>", "Width")]
        {
            let err = lab_err(text);
            assert!(
                matches!(&err, MapLoadError::MissingAttribute { element, attr, .. } if element == "Lab" && attr == want),
                "{text}: {err:?}"
            );
        }
        let err = lab_err("\n <Lab Width=\"28\"/>");
        assert_eq!(err.to_string(), "2:2: <Lab> has no Height attribute: expected Height=\"...\"");
    }

    #[test]
    fn a_lab_larger_than_the_limit_is_out_of_range() {
        let err = lab_err("<Lab Width=\"10000000\" Height=\"10000000\"/>");
        assert!(
            matches!(&err, MapLoadError::OutOfRange { attr, pos, .. } if attr == "Width" && *pos == at(1, 1)),
            "{err:?}"
        );
        assert!(err.to_string().contains("at most 10000"), "{err}");
        assert_eq!(crate::MAX_LAB_SIZE_M, 10_000.0, "the message above quotes the limit");
        let lab = lab_ok("<Lab Width=\"10000\" Height=\"0.5\"/>");
        assert_eq!((lab.width_m, lab.height_m), (10_000.0, 0.5));
        let err = lab_err("<Lab Width=\"5\" Height=\"10000.001\"/>");
        assert!(matches!(&err, MapLoadError::OutOfRange { attr, .. } if attr == "Height"), "{err:?}");
    }

    #[test]
    fn beacons_targets_and_walls_get_their_default_heights_and_radius() {
        let lab = lab_ok(
            "<Lab Name=\"A &amp; B\" Width=\"20\" Height=\"10\">\
             <Beacon X=\"1\" Y=\"2\"/><Target X=\"3\" Y=\"4\"/>\
             <Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"2\" Y=\"1\"/><Corner X=\"2\" Y=\"2\"/></Wall>\
             </Lab>",
        );
        assert_eq!(lab.name, "A & B");
        assert_eq!(lab.beacons, [Beacon { pos: Point2::new(1.0, 2.0), height_m: 0.0 }]);
        assert_eq!(lab.targets, [Target { pos: Point2::new(3.0, 4.0), radius_m: 2.0 }]);
        assert_eq!(lab.walls[0].height_m, DEFAULT_WALL_HEIGHT_M);
    }

    #[test]
    fn unknown_elements_comments_and_stray_text_are_ignored() {
        let lab = lab_ok(
            "<?xml version=\"1.0\"?>\n<!-- a lab -->\n<Lab Width=\"5\" Height=\"5\">\n  stray & text\n\
             <Light X=\"1\"><Deeper/></Light>\n\
             <Wall><Corner X=\"1\" Y=\"1\"/><Paint/><Corner X=\"2\" Y=\"1\"/><Corner X=\"2\" Y=\"2\"/></Wall>\n\
             <![CDATA[ more ]]>\n</Lab>\n\"\n",
        );
        assert_eq!(lab.walls.len(), 1);
        assert_eq!(lab.walls[0].corners.len(), 3);
    }

    #[test]
    fn a_row_pattern_becomes_walls_inside_the_lab() {
        let lab = lab_ok(
            "<Lab Width=\"28\" Height=\"14\">\n\
             <Row Pos=\"12\" Pattern=\"           |                             \"/>\n\
             <Row Pos=\"11\" Pattern=\"--+--\" Height=\"1.5\"/>\n</Lab>",
        );
        assert_eq!(lab.walls.len(), 2);
        assert_eq!(corners(&lab.walls[0]), [(7.9, 12.0), (8.1, 12.0), (8.1, 14.0), (7.9, 14.0)]);
        assert_eq!(lab.walls[0].height_m, DEFAULT_WALL_HEIGHT_M);
        assert_eq!(corners(&lab.walls[1]), [(0.0, 11.9), (4.0, 11.9), (4.0, 12.1), (0.0, 12.1)]);
        assert_eq!(lab.walls[1].height_m, 1.5);
    }

    #[test]
    fn a_row_reaching_past_the_lab_is_reported_at_the_row() {
        let err = lab_err("<Lab Width=\"4\" Height=\"14\">\n  <Row Pos=\"12\" Pattern=\"     |\"/>\n</Lab>");
        assert!(matches!(err, MapLoadError::CornerOutsideLab { pos, .. } if pos == at(2, 3)), "{err:?}");
    }

    #[test]
    fn a_row_needs_a_whole_non_negative_pos_and_a_pattern() {
        let err = lab_err("<Lab Width=\"16\" Height=\"16\"><Row Pos=\"1.5\" Pattern=\"--\"/></Lab>");
        assert!(matches!(&err, MapLoadError::OutOfRange { attr, .. } if attr == "Pos"), "{err:?}");
        let err = lab_err("<Lab Width=\"16\" Height=\"16\"><Row Pos=\"-2\" Pattern=\"--\"/></Lab>");
        assert!(matches!(&err, MapLoadError::OutOfRange { attr, .. } if attr == "Pos"), "{err:?}");
        let err = lab_err("<Lab Width=\"16\" Height=\"16\"><Row Pos=\"2\"/></Lab>");
        assert!(
            matches!(&err, MapLoadError::MissingAttribute { attr, pos, .. } if attr == "Pattern" && *pos == at(1, 29)),
            "{err:?}"
        );
    }

    #[test]
    fn impossible_sizes_and_heights_are_out_of_range() {
        let cases = [
            ("<Lab Width=\"0\" Height=\"5\"/>", "Lab", "Width"),
            ("<Lab Width=\"5\" Height=\"-3\"/>", "Lab", "Height"),
            ("<Lab Width=\"16\" Height=\"16\"><Target X=\"1\" Y=\"1\" Radius=\"0\"/></Lab>", "Target", "Radius"),
            ("<Lab Width=\"16\" Height=\"16\"><Beacon X=\"1\" Y=\"1\" Height=\"-1\"/></Lab>", "Beacon", "Height"),
            ("<Lab Width=\"5\" Height=\"5\"><Beacon X=\"6\" Y=\"1\"/></Lab>", "Beacon", "X"),
            ("<Lab Width=\"5\" Height=\"5\"><Target X=\"1\" Y=\"-1\"/></Lab>", "Target", "Y"),
            (
                "<Lab Width=\"16\" Height=\"16\"><Wall Height=\"-1\"><Corner X=\"1\" Y=\"1\"/><Corner X=\"2\" Y=\"1\"/>\
                 <Corner X=\"2\" Y=\"2\"/></Wall></Lab>",
                "Wall",
                "Height",
            ),
        ];
        for (text, want_element, want_attr) in cases {
            let err = lab_err(text);
            assert!(
                matches!(&err, MapLoadError::OutOfRange { element, attr, .. }
                    if element == want_element && attr == want_attr),
                "{text}: {err:?}"
            );
        }
    }

    #[test]
    fn malformed_xml_is_a_syntax_error_with_its_position() {
        let cases = [
            ("<Lab Width=\"16\" Height=\"16\">\n  <Wall Height=\"1\"", at(2, 3)),
            ("<Lab Width=10/>", at(1, 12)),
            ("<Lab/>\n<Lab/>", at(2, 1)),
            ("<Lab Width=\"16\" Height=\"16\">\n</Lab>\n</Lab>", at(3, 1)),
        ];
        for (text, want) in cases {
            let err = lab_err(text);
            assert!(matches!(&err, MapLoadError::Syntax { pos, .. } if *pos == want), "{text:?}: {err:?}");
            assert!(err.to_string().starts_with(&format!("{want}: malformed XML: ")), "{err}");
        }
    }

    #[test]
    fn a_file_without_elements_is_empty() {
        for text in ["", "   \n", "<?xml version=\"1.0\"?><!-- nothing -->"] {
            assert!(matches!(parse_lab(text), Err(MapLoadError::Empty)), "{text:?}");
        }
    }

    #[test]
    fn plain_text_without_an_element_is_refused_at_its_first_character() {
        let err = lab_err("\n  just some text\nand more\n");
        assert!(matches!(err, MapLoadError::NoRootElement { pos } if pos == at(2, 3)), "{err:?}");
        assert!(err.to_string().starts_with("2:3: text where the root element belongs"), "{err}");
        assert!(matches!(parse_any("garbage"), Err(MapLoadError::NoRootElement { pos }) if pos == at(1, 1)));
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        assert_eq!(lab_ok("\u{feff}<Lab Name=\"bom\" Width=\"1\" Height=\"1\"/>").name, "bom");
        let err = lab_err("\u{feff}<Lab Width=\"x\"/>");
        assert!(matches!(err, MapLoadError::NotANumber { pos, .. } if pos == at(1, 1)), "{err:?}");
    }

    #[test]
    fn a_grid_reads_positions_in_order_with_dir_defaulting_to_zero() {
        let grid =
            match parse_grid("<Grid>\n<Position X=\"9\" Y=\"3\" Dir=\"90\"/>\n<Position X=\"5\" Y=\"7\"/>\n</Grid>") {
                Ok(grid) => grid,
                Err(err) => panic!("{err}"),
            };
        assert_eq!(
            grid.poses,
            [
                StartPose { pos: Point2::new(9.0, 3.0), heading_deg: 90.0 },
                StartPose { pos: Point2::new(5.0, 7.0), heading_deg: 0.0 },
            ]
        );
    }

    #[test]
    fn a_grid_with_stray_text_loads_like_ciber_ratos_c1_grid() {
        let text = "<Grid>\n    <Position X=\"1.0\" Y=\"7.0\" Dir=\"0.0\"/>\\n\"\n    <Position X=\"1.0\" Y=\"5.0\" Dir=\"0.0\"/>\nsome words\n</Grid>\n\\n\"";
        match parse_grid(text) {
            Ok(grid) => assert_eq!(grid.poses.len(), 2),
            Err(err) => panic!("{err}"),
        }
    }

    #[test]
    fn a_grid_position_without_x_is_missing_an_attribute() {
        let err = parse_grid("<Grid>\n  <Position Y=\"1\"/>\n</Grid>").expect_err("no X");
        assert!(
            matches!(&err, MapLoadError::MissingAttribute { pos, attr, .. } if *pos == at(2, 3) && attr == "X"),
            "{err:?}"
        );
    }

    #[test]
    fn params_read_motor_noise_in_percent_and_both_collision_latency_spellings() {
        let p = params_ok("<Parameters MotorsNoise=\"1.5\" CollisionLatency=\"3\"/>");
        assert!((p.noise.motor_frac - 0.015).abs() < 1e-15);
        assert_eq!(p.latency.collision, 3);
        let p = params_ok("<Parameters collisionLatency=\"2\"/>");
        assert_eq!(p.latency.collision, 2);
    }

    #[test]
    fn params_read_every_ciber_rato_and_iwsim_attribute() {
        let p = params_ok(
            "<Parameters SimTime=\"1800\" CycleTime=\"50\" CompassNoise=\"1\" BeaconNoise=\"3\"
                ObstacleNoise=\"0.2\" MotorsNoise=\"0\" GPS=\"On\" GPSLinNoise=\"0.4\" GPSDirNoise=\"4\"
                BeaconSensor=\"yes\" CompassSensor=\"OFF\" RequestsPerCycle=\"4\"
                ObstacleRequestable=\"On\" BeaconRequestable=\"True\" GroundRequestable=\"on\"
                CompassRequestable=\"Off\" CollisionRequestable=\"On\" ObstacleLatency=\"1\"
                BeaconLatency=\"2\" GroundLatency=\"3\" CompassLatency=\"4\" GPSLatency=\"5\"
                BeaconAperture=\"1.25\" ObstacleRange=\"2.5\" MessageRange=\"6\"
                EncoderTicks=\"2048\" WheelRadius=\"0.2\" EncoderNoise=\"2\"
                KeyTime=\"4000\" Lab=\"lab.xml\" ShowActions=\"On\" NBeacons=\"1\" ScoreSensor=\"On\"
                ReturnTimePenalty=\"1\" ArrivalTimePenalty=\"2\" CollisionWallPenalty=\"5\"
                CollisionRobotPenalty=\"0\" TargetReward=\"3\" HomeReward=\"4\" LineSensorTrueProb=\"0.99\"
                Scoring=\"1\"/>",
        );
        assert_eq!(p.sim_time_ticks, 1800);
        assert_eq!(p.cycle_ms, 50);
        assert_eq!(p.noise.compass_deg, 1.0);
        assert_eq!(p.noise.beacon_deg, 3.0);
        assert_eq!(p.noise.proximity_m, 0.2);
        assert_eq!(p.noise.motor_frac, 0.0);
        assert_eq!(p.noise.gps_pos_m, 0.4);
        assert_eq!(p.noise.gps_heading_deg, 4.0);
        assert_eq!(p.noise.encoder_slip_frac, 0.02);
        assert_eq!(p.sensors, crate::map::SensorSwitches { gps: true, beacon: true, compass: false });
        assert_eq!(
            p.requests,
            crate::map::RequestParams {
                per_cycle: 4,
                obstacle: true,
                beacon: true,
                ground: true,
                compass: false,
                collision: true
            }
        );
        assert_eq!(
            p.latency,
            crate::map::LatencyParams { proximity: 1, beacon: 2, ground: 3, compass: 4, collision: 0, gps: 5 }
        );
        assert_eq!(p.beacon_aperture_rad, 1.25);
        assert_eq!(p.proximity_range_m, Some(2.5));
        assert_eq!(p.message_range_m, 6.0);
        assert_eq!(p.encoder_ticks_per_rev, 2048);
        assert_eq!(p.wheel_radius_m, 0.2);
        assert_eq!(
            p.challenge,
            crate::map::ChallengeParams {
                key_time_ticks: 4000,
                score_sensor: true,
                return_time_penalty: 1,
                arrival_time_penalty: 2,
                collision_wall_penalty: 5,
                collision_robot_penalty: 0,
                target_reward: 3,
                home_reward: 4,
                scoring: crate::challenge::Scoring::Control,
            }
        );
        assert!((p.noise.line_flip_prob - 0.01).abs() < 1e-12);
    }

    #[test]
    fn the_example_params_file_spells_out_the_defaults() {
        assert_eq!(params_ok(include_str!("../../maps/params-example.xml")), Params::default());
    }

    #[test]
    fn bad_parameter_values_are_out_of_range_or_not_numbers() {
        let cases = [
            ("<Parameters GPS=\"maybe\"/>", "GPS"),
            ("<Parameters CompassNoise=\"-1\"/>", "CompassNoise"),
            ("<Parameters CycleTime=\"12.5\"/>", "CycleTime"),
            ("<Parameters SimTime=\"-1\"/>", "SimTime"),
            ("<Parameters EncoderTicks=\"0\"/>", "EncoderTicks"),
            ("<Parameters WheelRadius=\"0\"/>", "WheelRadius"),
            ("<Parameters LineSensorTrueProb=\"1.5\"/>", "LineSensorTrueProb"),
            ("<Parameters CollisionWallPenalty=\"-2\"/>", "CollisionWallPenalty"),
            ("<Parameters ObstacleLatency=\"99999999999\"/>", "ObstacleLatency"),
        ];
        for (text, want_attr) in cases {
            let err = parse_params(text).expect_err(text);
            assert!(
                matches!(&err, MapLoadError::OutOfRange { attr, pos, .. } if attr == want_attr && *pos == at(1, 1)),
                "{text}: {err:?}"
            );
        }
        let err = parse_params("<Parameters\n  BeaconNoise=\"lots\"/>").expect_err("not a number");
        assert!(matches!(&err, MapLoadError::NotANumber { attr, .. } if attr == "BeaconNoise"), "{err:?}");
    }

    #[test]
    fn parse_any_dispatches_on_the_root_element() {
        assert!(matches!(parse_any("<Lab Width=\"1\" Height=\"1\"/>"), Ok(MapFile::Lab(_))));
        assert!(matches!(parse_any("<Grid/>"), Ok(MapFile::Grid(_))));
        assert!(matches!(parse_any("<Parameters GPS=\"On\"/>"), Ok(MapFile::Params(p)) if p.sensors.gps));
        let err = parse_any("\n <Robot Name=\"r\"/>").expect_err("not a map file");
        assert!(
            matches!(&err, MapLoadError::UnknownRoot { pos, found, expected: "Lab, Grid or Parameters" }
                if *pos == at(2, 2) && found == "Robot"),
            "{err:?}"
        );
        // Errors inside a dispatched file are the file's own.
        assert!(matches!(parse_any("<Grid><Position X=\"a\" Y=\"1\"/></Grid>"), Err(MapLoadError::NotANumber { .. })));
    }

    #[test]
    fn reading_a_missing_file_is_an_io_error() {
        let err = read_text(Path::new("/nonexistent/iwsim/lab.xml")).expect_err("missing");
        assert!(matches!(&err, MapLoadError::Io { path, .. } if path == Path::new("/nonexistent/iwsim/lab.xml")));
        assert!(std::error::Error::source(&err).is_some());
    }

    #[test]
    fn every_pattern_character_of_ciber_ratos_labs_loads() {
        // One row per character Ciber-Rato's 89 shipped labs use.
        let lab = lab_ok("<Lab Width=\"28\" Height=\"14\">\n<Row Pos=\"1\" Pattern=\"--+--| /\\ . · T H X\"/>\n</Lab>");
        assert_eq!(lab.walls.len(), 4, "the bar, the two diagonals and the run of dashes");
    }

    #[test]
    fn a_pattern_character_that_means_nothing_is_refused_at_its_column() {
        for bad in ['#', '=', '*', '@', '{', '}', 'x'] {
            let text = format!("<Lab Width=\"28\" Height=\"14\">\n  <Row Pos=\"3\" Pattern=\"--+-{bad}+\"/>\n</Lab>");
            let err = lab_err(&text);
            // `  <Row Pos="3" Pattern="` is 24 characters; the bad one is the 5th of the value.
            assert!(
                matches!(err, MapLoadError::BadPatternCharacter { pos, found } if pos == at(2, 29) && found == bad),
                "{bad}: {err:?}"
            );
        }
        let err = lab_err("<Lab Width=\"28\" Height=\"14\"><Row Pos=\"3\" Pattern=\"·#\"/></Lab>");
        assert!(err.to_string().contains("'#'") && err.to_string().contains("expected only space"), "{err}");
    }

    #[test]
    fn a_pattern_written_with_entities_is_refused_at_the_value() {
        let err = lab_err("<Lab Width=\"28\" Height=\"14\">\n<Row Pos=\"3\" Pattern=\"&amp;-#\"/></Lab>");
        assert!(matches!(err, MapLoadError::BadPatternCharacter { pos, found: '&' } if pos == at(2, 23)), "{err:?}");
    }

    #[test]
    fn a_row_pos_that_is_not_a_number_hints_at_a_whole_number() {
        let err = lab_err("<Lab Width=\"28\" Height=\"14\"><Row Pos=\"two\" Pattern=\"--\"/></Lab>");
        assert!(matches!(&err, MapLoadError::NotANumber { attr, .. } if attr == "Pos"), "{err:?}");
        let message = err.to_string();
        assert!(message.contains("expected a whole number") && !message.contains("2.5"), "{message}");
        let err = parse_params("<Parameters CycleTime=\"fast\"/>").expect_err("not a number");
        assert!(!err.to_string().contains("2.5"), "{err}");
    }

    #[test]
    fn a_dtd_is_refused_as_unsupported_where_it_is_declared() {
        let text = "<?xml version=\"1.0\"?>\n<!DOCTYPE Lab [ <!ENTITY e9 \"é\"> ]>\n<Lab Name=\"&e9;\" Width=\"1\" Height=\"1\"/>";
        let err = lab_err(text);
        assert!(matches!(err, MapLoadError::DtdNotSupported { pos } if pos == at(2, 1)), "{err:?}");
        assert!(err.to_string().contains("DTDs and entity declarations are not supported"), "{err}");
        // A DOCTYPE that declares nothing is harmless.
        assert_eq!(lab_ok("<!DOCTYPE Lab>\n<Lab Name=\"x\" Width=\"1\" Height=\"1\"/>").name, "x");
    }

    #[test]
    fn an_unknown_entity_says_entities_are_not_supported_and_where() {
        let err = lab_err("<Lab Width=\"1\" Height=\"1\"\n  Name=\"caf&e9;\"/>");
        assert!(
            matches!(&err, MapLoadError::UnknownEntity { pos, name } if *pos == at(2, 12) && name == "e9"),
            "{err:?}"
        );
        assert!(err.to_string().contains("not supported"), "{err}");
        assert_eq!(lab_ok("<Lab Name=\"caf&#233; &amp; co\" Width=\"1\" Height=\"1\"/>").name, "café & co");
    }

    #[test]
    fn invalid_utf8_is_refused_at_its_first_bad_byte() {
        let path = std::env::temp_dir().join(format!("iwsim-latin1-lab-{}.xml", std::process::id()));
        std::fs::write(&path, b"<Lab Width=\"1\" Height=\"1\">\n  <!-- caf\xe9 -->\n</Lab>").expect("written");
        let err = read_text(&path).expect_err("latin-1 is not UTF-8");
        assert!(matches!(err, MapLoadError::NotUtf8 { pos } if pos == at(2, 11)), "{err:?}");
        assert!(err.to_string().starts_with("2:11: the file is not UTF-8 text"), "{err}");
        std::fs::write(&path, "é\nok").expect("written");
        assert_eq!(read_text(&path).expect("UTF-8"), "é\nok");
        let _ = std::fs::remove_file(path);
    }

    #[test]
    fn a_file_larger_than_the_cap_is_refused_without_reading_it_all() {
        // A sparse file: 16 MiB and a little of nothing, made at once.
        let path = std::env::temp_dir().join(format!("iwsim-big-lab-{}.xml", std::process::id()));
        std::fs::File::create(&path).and_then(|f| f.set_len(MAX_FILE_BYTES + 10)).expect("a sparse file");
        let err = read_text(&path).expect_err("too large");
        let _ = std::fs::remove_file(&path);
        assert!(matches!(err, MapLoadError::TooLarge { max: MAX_FILE_BYTES, .. }), "{err:?}");
        assert!(err.to_string().contains("is larger than 16777216 bytes"), "{err}");
    }

    #[test]
    fn a_device_or_a_pipe_is_refused_at_once_not_read_for_ever() {
        // /dev/zero never ends; a FIFO with no writer blocked the open for ever (issue 27).
        let err = read_text(Path::new("/dev/zero")).expect_err("a device");
        assert!(err.to_string().contains("not a regular file but a device"), "{err}");
        let fifo = std::env::temp_dir().join(format!("iwsim-fifo-lab-{}.xml", std::process::id()));
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
        assert!(made.success());
        let err = read_text(&fifo).expect_err("a pipe");
        let _ = std::fs::remove_file(&fifo);
        assert!(err.to_string().contains("not a regular file but a pipe (FIFO)"), "{err}");
    }

    #[test]
    fn errors_name_their_file_once_with_a_colon_or_a_space() {
        let err = lab_err("<Lab Width=\"1\" Height=\"1\"><Beacon X=\"9\" Y=\"0\"/></Lab>");
        assert!(err.in_file("lab.xml").to_string().starts_with("lab.xml:1:27: <Beacon>"), "{err}");
        assert_eq!(
            MapLoadError::Empty.in_file("lab.xml").to_string(),
            "lab.xml: the file holds no root element: expected <Lab>, <Grid> or <Parameters>"
        );
        let err = read_text(Path::new("/nonexistent/iwsim/lab.xml")).expect_err("missing");
        let shown = err.in_file("/nonexistent/iwsim/lab.xml").to_string();
        assert_eq!(shown.matches("/nonexistent/iwsim/lab.xml").count(), 1, "{shown}");
    }

    #[test]
    fn grid_positions_outside_their_lab_are_refused_at_the_position() {
        let lab = lab_ok("<Lab Width=\"40\" Height=\"14\"/>");
        let text = "<Grid>\n  <Position X=\"3\" Y=\"3\"/>\n  <Position X=\"200\" Y=\"3\"/>\n</Grid>";
        let err = parse_grid_for(text, &lab).expect_err("x = 200 on a 40 m lab");
        assert!(
            matches!(&err, MapLoadError::OutOfRange { attr, pos, .. } if attr == "X" && *pos == at(3, 3)),
            "{err:?}"
        );
        let err = parse_grid_for("<Grid><Position X=\"3\" Y=\"-1\"/></Grid>", &lab).expect_err("y < 0");
        assert!(matches!(&err, MapLoadError::OutOfRange { attr, .. } if attr == "Y"), "{err:?}");
        assert_eq!(
            parse_grid_for("<Grid><Position X=\"40\" Y=\"0\"/></Grid>", &lab).expect("on the border").poses.len(),
            1
        );
        // Without a lab there is nothing to check against.
        assert_eq!(parse_grid(text).expect("no lab").poses.len(), 2);
    }

    #[test]
    fn text_positions_print_as_line_colon_column() {
        assert_eq!(at(12, 7).to_string(), "12:7");
    }

    mod never_panics {
        use super::*;
        use proptest::prelude::*;

        const LIACC: &str = include_str!("../../maps/liacc-lab.xml");
        const MAZE: &str = include_str!("../../maps/maze-lab.xml");

        /// Applies byte-level edits (replace, delete, insert) and keeps the result if it is
        /// still UTF-8 — the loader only ever sees `&str`.
        fn mutate(base: &str, edits: &[(usize, u8, u8)]) -> String {
            let mut bytes = base.as_bytes().to_vec();
            for &(at, kind, byte) in edits {
                if bytes.is_empty() {
                    break;
                }
                let at = at % bytes.len();
                match kind % 3 {
                    0 => bytes[at] = byte,
                    1 => {
                        bytes.remove(at);
                    }
                    _ => bytes.insert(at, byte),
                }
            }
            String::from_utf8_lossy(&bytes).into_owned()
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            #[test]
            fn parse_lab_never_panics_on_arbitrary_text(text in any::<String>()) {
                let _ = parse_lab(&text);
                let _ = parse_any(&text);
            }

            #[test]
            fn parse_lab_never_panics_on_xml_like_text(text in "[<>/=\" a-zA-Z0-9.\\-\n&;!?|]{0,200}") {
                let _ = parse_lab(&text);
                let _ = parse_any(&text);
            }

            #[test]
            fn parse_lab_never_panics_on_mutated_builtin_labs(
                edits in proptest::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..8),
                maze in any::<bool>(),
            ) {
                let text = mutate(if maze { MAZE } else { LIACC }, &edits);
                if let Err(err) = parse_lab(&text) {
                    // Every error still renders; positioned ones point inside the text.
                    let message = err.to_string();
                    prop_assert!(!message.is_empty());
                    let lines = u32::try_from(text.lines().count() + 1).unwrap_or(u32::MAX);
                    if let Some(Ok(line)) = message.split_once(':').map(|(line, _)| line.parse::<u32>()) {
                        prop_assert!(line >= 1 && line <= lines, "{message}");
                    }
                }
            }
        }
    }
}
