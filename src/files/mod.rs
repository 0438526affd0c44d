//! Files in and out, for every layer that touches the file system.
//!
//! Contract:
//! - [`read_input`] reads only regular files (following symlinks): a FIFO, a device such as
//!   `/dev/zero`, a socket or a directory is refused with an error naming the path and what it
//!   is, before a byte is read, so no input can block forever or stream without end. The read is
//!   bounded by the size the file had when it was opened and by a caller's limit.
//! - [`Outputs`] writes a set of outputs all or nothing: every output gets an exclusively
//!   created temporary with a random name in its own directory (it can neither follow nor reuse
//!   an existing path, so a planted symlink redirects nothing), and the temporaries are renamed
//!   over their targets only after every one was written. Dropping an unfinished set deletes its
//!   temporaries.
//! - Before any work, an output that is the same file as an input or as another output is
//!   refused with both names. Files are compared by identity (device and inode of what the path
//!   resolves to), not by spelling: `./a.png`, symlinks and hard links are all caught.
//! - [`excerpt`] is the one way an error message quotes input: at most a short, escaped
//!   excerpt, so no message carries terminal escapes or megabytes of a hostile file.

mod input;
pub mod memory;
mod output;

pub use input::{FileId, read_head, read_input};
pub use output::{Outputs, check_not_input, remove_temporaries, write_output};

use std::path::PathBuf;

/// Everything reading or writing a file can fail with; each names the path.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Memory { path: PathBuf, message: String },
    #[error("{path}: expected a regular file, found {found}")]
    NotRegular { path: PathBuf, found: &'static str },
    #[error("{path}: the file holds {size} bytes, more than the {limit} bytes this input may have")]
    TooLarge {
        path: PathBuf,
        size: u64,
        limit: u64,
    },
    #[error(
        "{first} ({first_role}) and {second} ({second_role}) are the same file: refusing to \
         overwrite {what}"
    )]
    SameFile {
        first: PathBuf,
        first_role: String,
        second: PathBuf,
        second_role: String,
        what: &'static str,
    },
    #[error("{path} ({role}): expected a file name in an existing directory, found {found}")]
    BadTarget {
        path: PathBuf,
        role: String,
        found: String,
    },
}

/// Longest excerpt of input an error message quotes, in characters before escaping.
pub const EXCERPT_CHARS: usize = 40;

/// Quotes input for an error message: the first [`EXCERPT_CHARS`] characters (lossy UTF-8),
/// with control characters, quotes and non-printing characters escaped, in single quotes, and
/// `...` when it was cut.
pub fn excerpt(bytes: &[u8]) -> String {
    let text = String::from_utf8_lossy(&bytes[..bytes.len().min(4 * EXCERPT_CHARS)]);
    let cut = bytes.len() > 4 * EXCERPT_CHARS;
    let (head, more) = excerpt_parts(&text, EXCERPT_CHARS);
    format!("'{head}'{}", if more || cut { "..." } else { "" })
}

/// [`excerpt`] without the quotes, for names quoted by the message around them: at most
/// `max` characters, escaped, with `...` when cut.
pub fn excerpt_text(text: &str, max: usize) -> String {
    let (head, more) = excerpt_parts(text, max);
    format!("{head}{}", if more { "..." } else { "" })
}

/// `text` safe for a terminal: control and text-direction characters escaped (nothing else,
/// so text escaped before stays as it was), cut to `max` characters with `...`.
pub fn printable(text: &str, max: usize) -> String {
    let mut chars = text.chars();
    let mut out: String = chars
        .by_ref()
        .take(max)
        .map(|c| {
            let bidi = matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}');
            if c.is_control() || bidi {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect();
    if chars.next().is_some() {
        out.push_str("...");
    }
    out
}

/// The first `max` characters of `text`, escaped, and whether anything was left out.
fn excerpt_parts(text: &str, max: usize) -> (String, bool) {
    let mut chars = text.chars();
    let head: String = chars.by_ref().take(max).collect();
    let escaped = head
        .chars()
        .map(|c| match c {
            '\'' | '"' => c.to_string(),
            c => c.escape_debug().to_string(),
        })
        .collect();
    (escaped, chars.next().is_some())
}

#[cfg(test)]
mod tests {
    use super::{excerpt, excerpt_text, printable};

    #[test]
    fn excerpts_are_short_and_escaped() {
        assert_eq!(excerpt(b"abc"), "'abc'");
        let hostile = [b"\x1b[31mred\x07".as_slice(), &[b'x'; 5_000_000]].concat();
        let e = excerpt(&hostile);
        assert!(e.len() < 80, "{e}");
        assert!(!e.chars().any(char::is_control), "{e:?}");
        assert!(
            e.starts_with("'\\u{1b}[31mred\\u{7}") && e.ends_with("..."),
            "{e}"
        );
        // A multi-byte character cut by the byte window is replaced, never split.
        assert_eq!(excerpt_text("a\nb", 2), "a\\n...");
        assert_eq!(
            printable("x\\u{1b} \x1b[2J\u{202e}", 100),
            "x\\u{1b} \\u{1b}[2J\\u{202e}"
        );
        assert_eq!(printable(&"y".repeat(50), 10), "yyyyyyyyyy...");
        let e = excerpt("é".repeat(200).as_bytes());
        assert!(e.ends_with("...") && e.chars().filter(|&c| c == 'é').count() == 40);
    }
}
