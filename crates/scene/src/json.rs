//! Human-friendly JSON: fields in declaration order one per line, and every array that holds
//! only numbers, strings, booleans or nulls on one line (so a 4x4 matrix takes four short
//! lines, not twenty-one).

use serde::Serialize;

/// Serialise `value` as indented JSON with flat arrays kept on one line, ending in a newline.
pub fn to_pretty_json<T: Serialize>(value: &T) -> Result<String, serde_json::Error> {
    let pretty = serde_json::to_string_pretty(value)?;
    let mut out = String::with_capacity(pretty.len());
    // Per open array: where it starts in `out`, and whether it holds only scalars so far.
    let mut arrays: Vec<(usize, bool)> = Vec::new();
    // Per open container: `true` for an array.
    let mut open: Vec<bool> = Vec::new();
    let mut in_string = false;
    let mut escaped = false;
    for c in pretty.chars() {
        out.push(c);
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => in_string = true,
            '[' | '{' => {
                if open.last() == Some(&true) {
                    if let Some(parent) = arrays.last_mut() {
                        parent.1 = false;
                    }
                }
                open.push(c == '[');
                if c == '[' {
                    arrays.push((out.len() - 1, true));
                }
            }
            '}' => {
                open.pop();
            }
            ']' => {
                open.pop();
                if let Some((start, true)) = arrays.pop() {
                    let collapsed = collapse(&out[start..]);
                    out.truncate(start);
                    out.push_str(&collapsed);
                }
            }
            _ => {}
        }
    }
    out.push('\n');
    Ok(out)
}

/// Join the lines of a flat array: a line break after a comma becomes one space, any other
/// line break (after `[`, before `]`) disappears. JSON strings never hold a raw line break,
/// so every line break here is layout.
fn collapse(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\n' {
            while chars.peek() == Some(&' ') {
                chars.next();
            }
            if out.ends_with(',') {
                out.push(' ');
            }
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct T {
        z: Vec<f64>,
        m: [[i32; 2]; 3],
        o: Vec<serde_json::Value>,
        s: &'static str,
        e: Vec<u8>,
    }

    #[test]
    fn round_trips_keeps_field_order_and_flat_arrays_inline() {
        let t = T {
            z: vec![1.5, 2.0],
            m: [[1, 0], [0, 1], [2, 2]],
            o: vec![serde_json::json!({"x": "q\"[,\n"})],
            s: "a]b[",
            e: vec![],
        };
        let text = to_pretty_json(&t).unwrap();
        let back: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(back, serde_json::to_value(&t).unwrap());
        assert!(
            text.starts_with("{\n  \"z\": [1.5, 2.0],\n  \"m\": [\n    [1, 0],\n    [0, 1],\n"),
            "{text}"
        );
        assert!(text.contains("\"o\": [\n    {\n      \"x\""), "{text}");
        assert!(text.contains("\"e\": []"), "{text}");
        assert!(text.ends_with("}\n"));
    }
}
