//! Human-friendly JSON: fields in declaration order one per line, and every array that holds
//! only numbers, strings, booleans or nulls on one line (so a 4x4 matrix takes four short
//! lines, not twenty-one).

use serde::Serialize;

/// Serialise `value` as indented JSON with flat arrays kept on one line, ending in a newline.
pub fn to_pretty_json<T: Serialize>(value: &T) -> Result<String, serde_json::Error> {
    let pretty = serde_json::to_vec_pretty(value)?;
    let mut out: Vec<u8> = Vec::with_capacity(pretty.len() + 1);
    // Per open array: where it starts in `out`, and whether it holds only scalars so far.
    let mut arrays: Vec<(usize, bool)> = Vec::new();
    // Per open container: `true` for an array.
    let mut open: Vec<bool> = Vec::new();
    let mut i = 0;
    while i < pretty.len() {
        // Copy the run up to the next byte that matters in one go.
        let run = pretty[i..]
            .iter()
            .position(|c| matches!(c, b'"' | b'[' | b']' | b'{' | b'}'))
            .unwrap_or(pretty.len() - i);
        out.extend_from_slice(&pretty[i..i + run]);
        i += run;
        let Some(&c) = pretty.get(i) else { break };
        i += 1;
        out.push(c);
        match c {
            b'"' => {
                // Copy the string through its closing quote, skipping escaped characters.
                while i < pretty.len() {
                    let s = pretty[i];
                    out.push(s);
                    i += 1;
                    if s == b'\\' {
                        out.push(pretty[i]);
                        i += 1;
                    } else if s == b'"' {
                        break;
                    }
                }
            }
            b'[' | b'{' => {
                if open.last() == Some(&true) {
                    if let Some(parent) = arrays.last_mut() {
                        parent.1 = false;
                    }
                }
                open.push(c == b'[');
                if c == b'[' {
                    arrays.push((out.len() - 1, true));
                }
            }
            b'}' => {
                open.pop();
            }
            _ => {
                open.pop();
                if let Some((start, true)) = arrays.pop() {
                    collapse(&mut out, start);
                }
            }
        }
    }
    out.push(b'\n');
    // Only ASCII layout bytes were removed or replaced, so the text is still UTF-8.
    Ok(String::from_utf8(out).expect("serde_json writes UTF-8"))
}

/// Join the lines of the flat array `out[start..]` in place: a line break after a comma
/// becomes one space, any other line break (after `[`, before `]`) disappears, and the
/// indentation after a line break goes. JSON strings never hold a raw line break, so every
/// line break here is layout.
fn collapse(out: &mut Vec<u8>, start: usize) {
    let mut w = start;
    let mut r = start;
    while r < out.len() {
        let c = out[r];
        r += 1;
        if c == b'\n' {
            while r < out.len() && out[r] == b' ' {
                r += 1;
            }
            if w > start && out[w - 1] == b',' {
                out[w] = b' ';
                w += 1;
            }
        } else {
            out[w] = c;
            w += 1;
        }
    }
    out.truncate(w);
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
