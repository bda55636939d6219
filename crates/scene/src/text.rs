//! Untrusted text on the user's terminal: a string read from a file (a manifest's command, a
//! lock's holder, Blender's error reply) is printed with its control characters escaped, so
//! that escape sequences cannot colour, hide or rewrite what the user reads, set the window
//! title or write the clipboard (docs/security.md).

use std::borrow::Cow;
use std::fmt::Write as _;

/// `text` with every control character (C0, DEL, C1: ESC, CR, BEL, ...) written as `\u{..}`;
/// with `lines`, newlines and tabs are kept (a traceback stays readable).
fn escaped(text: &str, lines: bool) -> Cow<'_, str> {
    let bad = |c: char| c.is_control() && !(lines && (c == '\n' || c == '\t'));
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

/// One line of untrusted text, safe to print: every control character escaped (newlines too).
pub fn printable(text: &str) -> Cow<'_, str> {
    escaped(text, false)
}

/// Untrusted text of several lines, safe to print: control characters escaped except newlines
/// and tabs.
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
        let l = printable_lines("Traceback:\n\tline 1\u{1b}[31m");
        assert_eq!(l, "Traceback:\n\tline 1\\u{1b}[31m");
    }
}
