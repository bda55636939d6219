//! Untrusted text on the user's terminal: a string read from a file (a manifest's command, a
//! lock's holder, Blender's error reply) is printed with its control characters escaped, so
//! that escape sequences cannot colour, hide or rewrite what the user reads, set the window
//! title or write the clipboard (docs/security.md).

use std::borrow::Cow;
use std::fmt::Write as _;

/// Unicode's bidirectional formatting characters: embeddings and overrides (U+202A..U+202E),
/// isolates (U+2066..U+2069) and the marks (U+200E, U+200F, U+061C). They are not control
/// characters to Rust, but on a terminal they reorder what follows them, so that a name or
/// command reads other than it is ("Trojan Source", CVE-2021-42574).
fn is_bidi_format(c: char) -> bool {
    matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{200e}' | '\u{200f}' | '\u{61c}')
}

/// `text` with every control character (C0, DEL, C1: ESC, CR, BEL, ...) and bidirectional
/// formatting character (U+202E, ...) written as `\u{..}`; with `lines`, newlines and tabs are
/// kept (a traceback stays readable).
fn escaped(text: &str, lines: bool) -> Cow<'_, str> {
    let bad =
        |c: char| (c.is_control() || is_bidi_format(c)) && !(lines && (c == '\n' || c == '\t'));
    if !text.chars().any(bad) {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        if bad(c) {
            let _ = write!(out, "\\u{{{:x}}}", c as u32);
        } else {
            out.push(c);
        }
    }
    Cow::Owned(out)
}

/// One line of untrusted text, safe to print: every control and bidirectional formatting
/// character escaped (newlines too).
pub fn printable(text: &str) -> Cow<'_, str> {
    escaped(text, false)
}

/// Untrusted text of several lines, safe to print: control and bidirectional formatting
/// characters escaped except newlines and tabs.
pub fn printable_lines(text: &str) -> Cow<'_, str> {
    escaped(text, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_reach_the_terminal_as_text() {
        assert!(matches!(printable("clevrtex generate"), Cow::Borrowed(_)));
        let hostile = "\u{1b}[2K\rclevrtex generate\u{7}\u{1b}]52;c;ZXZpbA==\u{7}\u{9b}31m\nx";
        let p = printable(hostile);
        assert!(!p.chars().any(char::is_control), "{p}");
        assert_eq!(
            p,
            "\\u{1b}[2K\\u{d}clevrtex generate\\u{7}\\u{1b}]52;c;ZXZpbA==\\u{7}\\u{9b}31m\\u{a}x"
        );
        // Issue 34: a right-to-left override reached the terminal and reordered the line.
        assert_eq!(
            printable("seed 1\u{202e}0 dees\u{2066}x\u{2069}\u{200f}"),
            "seed 1\\u{202e}0 dees\\u{2066}x\\u{2069}\\u{200f}"
        );
        let l = printable_lines("Traceback:\n\tline 1\u{1b}[31m");
        assert_eq!(l, "Traceback:\n\tline 1\\u{1b}[31m");
    }
}
