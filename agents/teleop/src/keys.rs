//! Keyboard bytes → driving commands.
//!
//! Terminals send arrow keys as escape sequences: `ESC [ A` normally, `ESC O A` when the
//! application has (or a multiplexer like tmux has) switched the terminal to application cursor
//! mode, and `ESC [ 1 ; 5 A` with a modifier held. A read may end in the middle of a sequence,
//! so the parser keeps its state between calls; anything it does not know is dropped without
//! disturbing what follows.

/// A driving command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Key {
    /// Up arrow or `w`: one step more forward speed.
    Faster,
    /// Down arrow or `s`: one step less speed (reverse below zero).
    Slower,
    /// Left arrow or `a`: one step more turn to the left.
    Left,
    /// Right arrow or `d`: one step more turn to the right.
    Right,
    /// Space: speed and turn to zero.
    Stop,
    /// `+` (or `=`): a larger step.
    StepUp,
    /// `-` (or `_`): a smaller step.
    StepDown,
    /// `r`: ask the hub to resume a physical chair after a latched stop.
    Resume,
    /// `q`, Ctrl-C or Ctrl-D: leave.
    Quit,
}

/// Where the parser is inside an escape sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
enum State {
    /// Between keys.
    #[default]
    Ground,
    /// After `ESC`.
    Escape,
    /// After `ESC [`, with this many parameter/intermediate bytes so far.
    Csi(u8),
    /// After `ESC O`.
    Ss3,
}

/// Longest run of parameter bytes accepted inside `ESC [ … final`; longer is junk.
const MAX_CSI_PARAMS: u8 = 16;

/// Turns a stream of bytes from the terminal into [`Key`]s; keeps partial escape sequences
/// between calls.
#[derive(Debug, Clone, Default)]
pub struct KeyParser {
    state: State,
}

impl KeyParser {
    /// A parser between keys.
    pub fn new() -> Self {
        Self::default()
    }

    /// Parses `bytes`, appending the keys found to `keys`.
    pub fn feed(&mut self, bytes: &[u8], keys: &mut Vec<Key>) {
        for &b in bytes {
            if let Some(k) = self.byte(b) {
                keys.push(k);
            }
        }
    }

    /// Whether a sequence has begun and not ended.
    pub fn pending(&self) -> bool {
        self.state != State::Ground
    }

    /// Abandons a sequence left unfinished (a lone `ESC` with nothing after it for a while).
    pub fn reset(&mut self) {
        self.state = State::Ground;
    }

    fn byte(&mut self, b: u8) -> Option<Key> {
        match self.state {
            State::Ground => self.ground(b),
            State::Escape => match b {
                b'[' => {
                    self.state = State::Csi(0);
                    None
                }
                b'O' => {
                    self.state = State::Ss3;
                    None
                }
                // ESC ESC: the first was a lone ESC; the second may begin a sequence.
                0x1b => None,
                // A lone ESC followed by an ordinary key (or Alt+key): drop the ESC, keep the key.
                _ => {
                    self.state = State::Ground;
                    self.ground(b)
                }
            },
            State::Csi(n) => match b {
                // Parameter and intermediate bytes (`1;5` of Ctrl+Up).
                0x20..=0x3f if n < MAX_CSI_PARAMS => {
                    self.state = State::Csi(n + 1);
                    None
                }
                // The final byte ends the sequence; modifiers are ignored.
                0x40..=0x7e => {
                    self.state = State::Ground;
                    arrow(b)
                }
                // Not a sequence after all: start again with this byte.
                _ => {
                    self.state = State::Ground;
                    self.ground(b)
                }
            },
            State::Ss3 => {
                self.state = State::Ground;
                match b {
                    0x40..=0x7e => arrow(b),
                    _ => self.ground(b),
                }
            }
        }
    }

    fn ground(&mut self, b: u8) -> Option<Key> {
        match b {
            0x1b => {
                self.state = State::Escape;
                None
            }
            b'w' | b'W' => Some(Key::Faster),
            b's' | b'S' => Some(Key::Slower),
            b'a' | b'A' => Some(Key::Left),
            b'd' | b'D' => Some(Key::Right),
            b' ' => Some(Key::Stop),
            b'+' | b'=' => Some(Key::StepUp),
            b'-' | b'_' => Some(Key::StepDown),
            b'r' | b'R' => Some(Key::Resume),
            b'q' | b'Q' | 0x03 | 0x04 => Some(Key::Quit),
            _ => None,
        }
    }
}

/// The key a sequence's final byte names, if it is an arrow.
fn arrow(b: u8) -> Option<Key> {
    match b {
        b'A' => Some(Key::Faster),
        b'B' => Some(Key::Slower),
        b'C' => Some(Key::Right),
        b'D' => Some(Key::Left),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(chunks: &[&[u8]]) -> Vec<Key> {
        let mut p = KeyParser::new();
        let mut keys = Vec::new();
        for c in chunks {
            p.feed(c, &mut keys);
        }
        keys
    }

    #[test]
    fn every_letter_key_maps_to_its_command() {
        use Key::*;
        assert_eq!(parse(&[b"wsad +-q"]), [Faster, Slower, Left, Right, Stop, StepUp, StepDown, Quit]);
        assert_eq!(parse(&[b"WSADQ=_"]), [Faster, Slower, Left, Right, Quit, StepUp, StepDown]);
    }

    #[test]
    fn ctrl_c_and_ctrl_d_quit() {
        assert_eq!(parse(&[b"\x03"]), [Key::Quit]);
        assert_eq!(parse(&[b"\x04"]), [Key::Quit]);
    }

    #[test]
    fn arrows_parse_in_normal_cursor_mode() {
        use Key::*;
        assert_eq!(parse(&[b"\x1b[A\x1b[B\x1b[C\x1b[D"]), [Faster, Slower, Right, Left]);
    }

    #[test]
    fn arrows_parse_in_application_cursor_mode() {
        use Key::*;
        assert_eq!(parse(&[b"\x1bOA\x1bOB\x1bOC\x1bOD"]), [Faster, Slower, Right, Left]);
    }

    #[test]
    fn arrows_with_modifiers_still_count() {
        assert_eq!(parse(&[b"\x1b[1;5A\x1b[1;2D"]), [Key::Faster, Key::Left]);
    }

    #[test]
    fn a_sequence_split_across_reads_at_every_point_parses_once() {
        for seq in [&b"\x1b[D"[..], b"\x1bOC", b"\x1b[1;5A"] {
            for cut in 0..=seq.len() {
                let keys = parse(&[b"w", &seq[..cut], &seq[cut..], b"s"]);
                assert_eq!(keys.len(), 3, "{seq:?} cut at {cut}: {keys:?}");
                assert_eq!((keys[0], keys[2]), (Key::Faster, Key::Slower));
            }
        }
        // One byte per read.
        let bytes = b"\x1b[A\x1bOD";
        let chunks: Vec<&[u8]> = bytes.chunks(1).collect();
        assert_eq!(parse(&chunks), [Key::Faster, Key::Left]);
    }

    #[test]
    fn a_lone_escape_does_not_swallow_the_next_key() {
        assert_eq!(parse(&[b"\x1b", b"w"]), [Key::Faster]);
        assert_eq!(parse(&[b"\x1b\x1b[A"]), [Key::Faster]);
        assert_eq!(parse(&[b"\x1b q"]), [Key::Stop, Key::Quit]);
    }

    #[test]
    fn reset_abandons_a_pending_escape() {
        let mut p = KeyParser::new();
        let mut keys = Vec::new();
        p.feed(b"\x1b", &mut keys);
        assert!(p.pending());
        p.reset();
        assert!(!p.pending());
        // Without the reset, "[A" would have finished an Up arrow.
        p.feed(b"[A", &mut keys);
        assert_eq!(keys, [Key::Left]);
    }

    #[test]
    fn junk_and_unknown_sequences_are_dropped_without_breaking_what_follows() {
        use Key::*;
        // Home/End/F1/PageUp/other letters/control bytes/high bytes/UTF-8.
        let junk: &[u8] = b"\x1b[H\x1b[F\x1bOP\x1b[5~xyz\r\n\t\x00\x7f\xff\xc3\xa9";
        assert_eq!(parse(&[junk, b"w\x1b[D"]), [Faster, Left]);
        // A broken sequence: a control byte inside CSI ends it and counts as itself.
        assert_eq!(parse(&[b"\x1b[1\x03"]), [Quit]);
        // An overlong parameter run is junk, and parsing recovers.
        let mut long = b"\x1b[".to_vec();
        long.extend(std::iter::repeat_n(b'1', 40));
        long.extend(b"w\x1b[A");
        assert_eq!(parse(&[&long]), [Faster, Faster]);
        // An SS3 followed by a control byte.
        assert_eq!(parse(&[b"\x1bO\x03"]), [Quit]);
    }
}
