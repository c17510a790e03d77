//! Reading the small text files a user writes (scenarios, agent configs): the whole file, at
//! most [`MAX_TEXT_FILE_BYTES`], as UTF-8.
//!
//! ```
//! let err = places::files::read_text(std::path::Path::new("/dev/zero")).unwrap_err();
//! assert!(err.to_string().contains("not a regular file"), "{err}");
//! ```

use std::io::Read;
use std::path::Path;

/// The largest file read, in bytes (16 MiB): the same cap as a lab file's. A scenario or a
/// config is a few kilobytes; the cap only stops a wrong path (`/dev/zero`, a disk image) from
/// being read until memory runs out.
pub const MAX_TEXT_FILE_BYTES: u64 = 16 * 1024 * 1024;

/// Why a text file could not be read. The variants do not name the file: callers say which
/// file it was, as they did for the I/O error alone.
#[derive(Debug, thiserror::Error)]
pub enum TextReadError {
    /// The file could not be opened or read.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The file is larger than [`MAX_TEXT_FILE_BYTES`].
    #[error("the file is larger than {max} bytes: expected a text file of at most {max} bytes")]
    TooLarge {
        /// The limit.
        max: u64,
    },
    /// The file is not UTF-8 text.
    #[error("{line}:{column}: the file is not UTF-8 text: expected UTF-8 (or plain ASCII) from this byte on")]
    NotUtf8 {
        /// Line of the first byte that is not UTF-8, from 1.
        line: usize,
        /// Its column, counting the characters before it, from 1.
        column: usize,
    },
}

/// Opens `path` for reading if it is a regular file (or a link to one). A device (`/dev/zero`
/// would be read until memory runs out), a pipe (opening a FIFO with no writer blocks for
/// ever) or a directory is refused with an error of kind `InvalidInput` that says what it is.
pub fn open_regular(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::FileTypeExt as _;
    let kind = std::fs::metadata(path)?.file_type();
    let what = if kind.is_file() {
        return std::fs::File::open(path);
    } else if kind.is_dir() {
        "a directory"
    } else if kind.is_fifo() {
        "a pipe (FIFO)"
    } else if kind.is_socket() {
        "a socket"
    } else if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else {
        "not a file"
    };
    Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("not a regular file but {what}: give a file")))
}

/// Reads a whole text file, refusing one larger than [`MAX_TEXT_FILE_BYTES`] or not UTF-8.
pub fn read_text(path: &Path) -> Result<String, TextReadError> {
    let mut bytes = Vec::new();
    // One byte past the cap tells "exactly the cap" from "larger".
    open_regular(path)?.take(MAX_TEXT_FILE_BYTES + 1).read_to_end(&mut bytes)?;
    if u64::try_from(bytes.len()).unwrap_or(u64::MAX) > MAX_TEXT_FILE_BYTES {
        return Err(TextReadError::TooLarge { max: MAX_TEXT_FILE_BYTES });
    }
    String::from_utf8(bytes).map_err(|err| {
        let good = err.utf8_error().valid_up_to();
        // Everything before `good` is valid UTF-8, so this never falls back.
        let before = std::str::from_utf8(err.as_bytes().get(..good).unwrap_or_default()).unwrap_or_default();
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().unwrap_or_default().chars().count() + 1;
        TextReadError::NotUtf8 { line, column }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let path = std::env::temp_dir().join(format!("records-files-{}-{name}", std::process::id()));
        std::fs::write(&path, bytes).expect("temp file");
        path
    }

    #[test]
    fn a_text_file_reads_whole() {
        let path = temp("ok.toml", "seconds = 5\nname = \"é\"\n".as_bytes());
        let text = read_text(&path);
        std::fs::remove_file(&path).expect("clean up");
        assert_eq!(text.expect("reads"), "seconds = 5\nname = \"é\"\n");
    }

    #[test]
    fn a_file_over_the_cap_stops_at_the_cap() {
        let path = std::env::temp_dir().join(format!("iwsim-records-big-{}.toml", std::process::id()));
        std::fs::File::create(&path).and_then(|f| f.set_len(MAX_TEXT_FILE_BYTES + 1)).expect("a sparse file");
        let err = read_text(&path).expect_err("too large");
        std::fs::remove_file(&path).expect("clean up");
        assert!(matches!(err, TextReadError::TooLarge { max: MAX_TEXT_FILE_BYTES }), "{err:?}");
    }

    #[test]
    fn a_device_a_pipe_or_a_directory_is_refused_at_once() {
        let fifo = std::env::temp_dir().join(format!("iwsim-records-fifo-{}", std::process::id()));
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs").success());
        // A FIFO with no writer: opening it would block for ever.
        let pipe = read_text(&fifo).expect_err("a pipe");
        std::fs::remove_file(&fifo).expect("clean up");
        for (err, what) in [
            (read_text(Path::new("/dev/zero")).expect_err("a device"), "a device"),
            (pipe, "a pipe (FIFO)"),
            (read_text(&std::env::temp_dir()).expect_err("a directory"), "a directory"),
        ] {
            assert!(err.to_string().contains(&format!("not a regular file but {what}")), "{err}");
        }
    }

    #[test]
    fn invalid_utf8_is_refused_at_its_first_bad_byte() {
        let path = temp("latin1.toml", b"a = 1\nname = \"caf\xe9\"\n");
        let err = read_text(&path).expect_err("latin-1");
        std::fs::remove_file(&path).expect("clean up");
        assert!(matches!(err, TextReadError::NotUtf8 { line: 2, column: 12 }), "{err:?}");
    }

    #[test]
    fn a_missing_file_is_the_io_error_itself() {
        let err = read_text(Path::new("/nonexistent/iwsim/x.toml")).expect_err("missing");
        assert!(matches!(&err, TextReadError::Io(e) if e.kind() == std::io::ErrorKind::NotFound), "{err:?}");
    }
}
