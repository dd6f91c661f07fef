//! PDS3 labels: the Object Description Language (ODL) statements of a detached label (`.LBL`)
//! or of the label at the head of a product (`.IMG`), read into named groups of keyword values.
//!
//! A label is a list of statements `KEYWORD = VALUE`, one per line unless a value's
//! parentheses, braces or quotes stay open, nested in `GROUP = NAME` / `END_GROUP` and
//! `OBJECT = NAME` / `END_OBJECT` blocks, with `/* comments */`, and closed by a line `END`.
//! Values are kept as their text; [`OdlGroup::number`] and [`OdlGroup::numbers`] read numbers
//! and number lists, units in angle brackets (`1.9 <m>`) dropped.

/// The bytes read at most when looking for a label's `END` (labels are a few tens of kB).
pub const MAX_LABEL_BYTES: usize = 1 << 20;

/// One group or object of a label (the label's top level is the group `ROOT`), its keywords
/// in order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OdlGroup {
    /// `GROUP = NAME` or `OBJECT = NAME` (quotes removed); `ROOT` for the top level.
    pub name: String,
    /// `(keyword, value text, line)`: the value as written (continuation lines joined by a
    /// space), the line 1-based.
    pub entries: Vec<(String, String, usize)>,
}

/// A parsed PDS3 label: its groups and objects in the order they open, nested ones flattened.
#[derive(Clone, Debug, PartialEq)]
pub struct OdlLabel {
    /// `groups[0]` is `ROOT`.
    pub groups: Vec<OdlGroup>,
}

/// Whether `bytes` start a PDS3 label (`PDS_VERSION_ID` or `ODL_VERSION_ID` after white space).
pub fn looks_like_pds3_label(bytes: &[u8]) -> bool {
    let start = bytes.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(bytes.len());
    let rest = &bytes[start..];
    rest.starts_with(b"PDS_VERSION_ID") || rest.starts_with(b"ODL_VERSION_ID")
}

/// The start of the file `path`: its label (up to [`MAX_LABEL_BYTES`]) when it starts with one
/// ([`looks_like_pds3_label`]), else its first 64 bytes (enough to tell a format by).
pub fn read_head(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let mut head = Vec::new();
    (&mut file).take(64).read_to_end(&mut head)?;
    if looks_like_pds3_label(&head) {
        file.take(MAX_LABEL_BYTES as u64 - head.len() as u64).read_to_end(&mut head)?;
    }
    Ok(head)
}

impl OdlLabel {
    /// Parses the label at the start of `bytes` (Latin-1; what follows its `END` line, such
    /// as an attached image, is not read). `Err` names the line at fault.
    pub fn parse(bytes: &[u8]) -> Result<Self, String> {
        let bytes = &bytes[..bytes.len().min(MAX_LABEL_BYTES)];
        let mut groups = vec![OdlGroup { name: "ROOT".into(), ..Default::default() }];
        let mut open: Vec<(usize, String, usize)> = Vec::new(); // (group index, kind, line)
        let mut statement = String::new();
        let mut first_line = 0;
        let mut in_comment = false;
        for (k, raw) in bytes.split(|&b| b == b'\n').enumerate() {
            let line_no = k + 1;
            let line = strip_comments(&latin1(raw), &mut in_comment);
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            if statement.is_empty() {
                first_line = line_no;
            } else {
                statement.push(' ');
            }
            statement.push_str(line);
            if !balanced(&statement) {
                continue;
            }
            let st = std::mem::take(&mut statement);
            if st == "END" {
                if let Some((_, kind, at)) = open.last() {
                    return Err(format!("line {line_no}: END while {kind} of line {at} is open"));
                }
                return Ok(OdlLabel { groups });
            }
            let bare_end = (st == "END_GROUP" || st == "END_OBJECT").then_some((st.as_str(), ""));
            let Some((key, value)) = bare_end.or_else(|| st.split_once('=')) else {
                return Err(format!("line {first_line}: {:?} is not KEYWORD = VALUE", clip(&st)));
            };
            let (key, value) = (key.trim(), value.trim());
            if key.is_empty() || key.contains(char::is_whitespace) {
                return Err(format!("line {first_line}: bad keyword {:?}", clip(key)));
            }
            match key {
                "GROUP" | "OBJECT" => {
                    groups.push(OdlGroup { name: value.trim_matches('"').to_string(), ..Default::default() });
                    open.push((groups.len() - 1, key.to_string(), first_line));
                }
                "END_GROUP" | "END_OBJECT" => {
                    let Some((at, kind, opened)) = open.pop() else {
                        return Err(format!("line {first_line}: {key} without an open {}", &key[4..]));
                    };
                    if kind != key[4..] {
                        return Err(format!("line {first_line}: {key} closes the {kind} of line {opened}"));
                    }
                    let name = value.trim_matches('"');
                    if !name.is_empty() && name != groups[at].name {
                        return Err(format!("line {first_line}: {key} = {name} closes {kind} {} (line {opened})", groups[at].name));
                    }
                }
                _ => {
                    let at = open.last().map_or(0, |o| o.0);
                    groups[at].entries.push((key.to_string(), value.to_string(), first_line));
                }
            }
        }
        if !statement.is_empty() {
            return Err(format!("line {first_line}: a value whose quotes or brackets are never closed"));
        }
        Err("no END line: the label is cut short".to_string())
    }

    /// The first group or object named `name`.
    pub fn group(&self, name: &str) -> Option<&OdlGroup> {
        self.groups.iter().find(|g| g.name == name)
    }

    /// The top-level keywords.
    pub fn root(&self) -> &OdlGroup {
        &self.groups[0]
    }
}

impl OdlGroup {
    /// The value text of `key` and its line.
    pub fn get(&self, key: &str) -> Option<(&str, usize)> {
        self.entries.iter().find(|e| e.0 == key).map(|e| (e.1.as_str(), e.2))
    }

    /// The value of `key` as text, quotes removed.
    pub fn text(&self, key: &str) -> Option<&str> {
        self.get(key).map(|(v, _)| v.trim().trim_matches('"').trim())
    }

    /// The value of `key` as one number (a unit in angle brackets dropped); `Err` names the key
    /// and line.
    pub fn number(&self, key: &str) -> Result<f64, String> {
        let (v, line) = self.get(key).ok_or_else(|| format!("no {key} in {}", self.name))?;
        parse_number(v).ok_or_else(|| format!("line {line}: {key} = {:?} is not a finite number", clip(v)))
    }

    /// The value of `key` as a list of `n` numbers `(a, b, ...)`; `Err` names the key and line.
    pub fn numbers(&self, key: &str, n: usize) -> Result<Vec<f64>, String> {
        let (v, line) = self.get(key).ok_or_else(|| format!("no {key} in {}", self.name))?;
        let bad = || format!("line {line}: {key} = {:?} is not a list of {n} finite numbers", clip(v));
        // A unit may follow the list: `(1, 2, 3) <m>`.
        let list = v.trim();
        let list = match (list.ends_with('>'), list.rfind('<')) {
            (true, Some(u)) => list[..u].trim_end(),
            _ => list,
        };
        let inner = list.strip_prefix('(').and_then(|s| s.strip_suffix(')')).ok_or_else(bad)?;
        let out: Vec<f64> = inner.split(',').map(parse_number).collect::<Option<_>>().ok_or_else(bad)?;
        if out.len() != n {
            return Err(bad());
        }
        Ok(out)
    }
}

/// A finite number, its unit (`<m>`) and quotes dropped.
fn parse_number(v: &str) -> Option<f64> {
    let v = v.split('<').next()?.trim().trim_matches('"').trim();
    v.parse::<f64>().ok().filter(|x| x.is_finite())
}

fn latin1(raw: &[u8]) -> String {
    raw.iter().map(|&b| b as char).collect()
}

/// `line` without its `/* ... */` comments (which may run over lines: `in_comment` carries it).
fn strip_comments(line: &str, in_comment: &mut bool) -> String {
    let mut out = String::with_capacity(line.len());
    let mut rest = line;
    loop {
        if *in_comment {
            match rest.find("*/") {
                Some(e) => {
                    rest = &rest[e + 2..];
                    *in_comment = false;
                }
                None => return out,
            }
        }
        // A comment opens only outside quotes.
        let mut quoted = false;
        let open = rest.char_indices().find(|&(i, c)| {
            if c == '"' {
                quoted = !quoted;
            }
            !quoted && rest[i..].starts_with("/*")
        });
        match open {
            Some((s, _)) => {
                out.push_str(&rest[..s]);
                rest = &rest[s + 2..];
                *in_comment = true;
            }
            None => {
                out.push_str(rest);
                return out;
            }
        }
    }
}

/// Whether a statement is whole: its quotes, parentheses and braces closed, and a value after
/// its `=`.
fn balanced(s: &str) -> bool {
    let (mut depth, mut quoted) = (0i64, false);
    for c in s.chars() {
        match c {
            '"' => quoted = !quoted,
            '(' | '{' if !quoted => depth += 1,
            ')' | '}' if !quoted => depth -= 1,
            _ => {}
        }
    }
    // `KEYWORD =` at a line's end: the value is on the next line.
    !quoted && depth <= 0 && !s.ends_with('=')
}

fn clip(s: &str) -> String {
    s.chars().take(60).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const LABEL: &str = "PDS_VERSION_ID = PDS3\n/* a comment */\nPRODUCT_ID = \"NLA_1\"\nPLANET_DAY_NUMBER = 38\n\
GROUP = GEOMETRIC_CAMERA_MODEL_PARMS\n  MODEL_TYPE =\n    CAHVOR /* trailing */\n  MODEL_COMPONENT_1 = (0.8,\n    0.3,-1.95) <m>\n\
  DESCRIPTION = \"an = sign (and a paren\"\nEND_GROUP = GEOMETRIC_CAMERA_MODEL_PARMS\nOBJECT = IMAGE\n  LINES = 1024\nEND_OBJECT = IMAGE\nEND\n\0\x01binary";

    #[test]
    fn groups_keywords_lists_units_and_comments_are_read() {
        let l = OdlLabel::parse(LABEL.as_bytes()).unwrap();
        assert!(looks_like_pds3_label(LABEL.as_bytes()));
        assert_eq!(l.root().text("PRODUCT_ID"), Some("NLA_1"));
        assert_eq!(l.root().number("PLANET_DAY_NUMBER"), Ok(38.0));
        let cm = l.group("GEOMETRIC_CAMERA_MODEL_PARMS").unwrap();
        assert_eq!(cm.text("MODEL_TYPE"), Some("CAHVOR"));
        assert_eq!(cm.numbers("MODEL_COMPONENT_1", 3), Ok(vec![0.8, 0.3, -1.95]));
        assert_eq!(cm.get("MODEL_COMPONENT_1").unwrap().1, 8, "a value over two lines keeps its first line");
        assert_eq!(cm.text("DESCRIPTION"), Some("an = sign (and a paren"));
        assert_eq!(l.group("IMAGE").unwrap().number("LINES"), Ok(1024.0));
        let err = cm.numbers("MODEL_COMPONENT_1", 4).unwrap_err();
        assert!(err.contains("line 8") && err.contains("MODEL_COMPONENT_1"), "{err}");
        assert!(cm.number("NOPE").unwrap_err().contains("no NOPE in GEOMETRIC_CAMERA_MODEL_PARMS"));
    }

    #[test]
    fn broken_labels_are_refused_with_the_line() {
        let cases = [
            ("PDS_VERSION_ID = PDS3\nGROUP = A\nX = 1\nEND\n", "END while GROUP of line 2"),
            ("PDS_VERSION_ID = PDS3\nGROUP = A\nEND_OBJECT = A\nEND\n", "line 3: END_OBJECT closes the GROUP of line 2"),
            ("PDS_VERSION_ID = PDS3\nGROUP = A\nEND_GROUP = B\nEND\n", "closes GROUP A"),
            ("PDS_VERSION_ID = PDS3\nEND_GROUP = B\nEND\n", "line 2: END_GROUP without an open GROUP"),
            ("PDS_VERSION_ID = PDS3\nOBJECT = A\nEND_GROUP\nEND\n", "line 3: END_GROUP closes the OBJECT of line 2"),
            ("PDS_VERSION_ID = PDS3\nJUST WORDS\nEND\n", "line 2"),
            ("PDS_VERSION_ID = PDS3\nX = (1, 2\n", "never closed"),
            ("PDS_VERSION_ID = PDS3\nX = 1\n", "no END line"),
        ];
        for (text, want) in cases {
            let err = OdlLabel::parse(text.as_bytes()).unwrap_err();
            assert!(err.contains(want), "{text:?}: {err}");
        }
        // Every prefix of a valid label is refused or parsed, never a panic.
        for cut in 0..LABEL.len() {
            let _ = OdlLabel::parse(&LABEL.as_bytes()[..cut]);
        }
    }
}
