//! Editing a URDF as text: the `<origin>` of named joints is rewritten in place and a comment block is
//! added after the `<robot>` start tag. Every other byte of the file is kept: elements robocal never
//! reads (visuals, collisions, meshes, `<transmission>`, `<gazebo>`, `<ros2_control>`), comments,
//! attribute order and quoting, whitespace and line breaks. A diff of the result against the input
//! shows the changed `xyz` / `rpy` values and the comment, nothing else.
//!
//! Only `<joint>` elements that are children of `<robot>` are joints: the `<joint>` elements inside
//! `<transmission>` or `<ros2_control>` blocks are references to them and are never touched.

use crate::error::{Result, SimError};
use std::collections::HashMap;
use std::ops::Range;

/// The attributes (name, unescaped value) of every `<name>` element that is a child of `<robot>`, in
/// document order, read with the scanner of [`edit_joint_origins`]: comments, CDATA and elements
/// nested deeper are not children. `source_name` names the text in errors.
///
/// # Errors
/// [`SimError::Parse`] when the markup is unterminated or an end tag closes another element.
pub fn robot_children(
    text: &str,
    source_name: &str,
    name: &str,
) -> Result<Vec<Vec<(String, String)>>> {
    let err = |message: String| SimError::Parse {
        source_name: source_name.to_string(),
        message,
    };
    let mut stack: Vec<&str> = Vec::new();
    let mut out = Vec::new();
    for item in Scanner::new(text) {
        let item =
            item.map_err(|(pos, what)| err(format!("{what} at line {}", line_of(text, pos))))?;
        match item {
            Item::Open(tag) => {
                if stack.len() == 1 && stack[0] == "robot" && tag.name(text) == name {
                    out.push(
                        tag.attrs
                            .iter()
                            .map(|a| {
                                (
                                    text[a.name.clone()].to_string(),
                                    unescape(&text[a.value.clone()]),
                                )
                            })
                            .collect(),
                    );
                }
                if !tag.self_closing {
                    stack.push(tag.name(text));
                }
            }
            Item::Close(span, closed) => {
                if stack.pop() != Some(closed) {
                    return Err(err(format!(
                        "</{closed}> does not close the open element at line {}",
                        line_of(text, span.start)
                    )));
                }
            }
            Item::Comment(_) => {}
        }
    }
    Ok(out)
}

/// `urdf` without its `<inertial>` elements (and every other byte kept): the robot as a vendor's
/// kinematics file or a DH table describes it, with no masses. What a study of calibration without
/// masses starts from (joint compliance then identifies lumped products; see
/// `calib::model::extensions::lumped_gravity`). An unterminated `<inertial>` is left as it is.
pub fn without_inertials(urdf: &str) -> String {
    let mut out = String::with_capacity(urdf.len());
    let mut rest = urdf;
    while let Some(a) = find_tag(rest, "inertial") {
        let open_end = match rest[a..].find('>') {
            Some(e) => a + e,
            None => break,
        };
        let end = if rest[..open_end].ends_with('/') {
            Some(open_end + 1)
        } else {
            rest[open_end..]
                .find("</inertial>")
                .map(|e| open_end + e + "</inertial>".len())
        };
        let Some(end) = end else { break };
        out.push_str(&rest[..a]);
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// The byte offset of the first start tag `<name` (followed by `>`, `/` or white space) in `text`.
fn find_tag(text: &str, name: &str) -> Option<usize> {
    let open = format!("<{name}");
    let mut from = 0;
    while let Some(k) = text[from..].find(&open) {
        let at = from + k;
        match text[at + open.len()..].chars().next() {
            Some(c) if c == '>' || c == '/' || c.is_whitespace() => return Some(at),
            _ => from = at + open.len(),
        }
    }
    None
}

/// A new origin for one joint: `xyz` (m) and `rpy` (rad, URDF roll-pitch-yaw).
#[derive(Clone, Debug, PartialEq)]
pub struct OriginEdit {
    /// URDF joint name.
    pub joint: String,
    /// Translation (m).
    pub xyz: [f64; 3],
    /// Roll, pitch, yaw (rad): `R = Rz(yaw) Ry(pitch) Rx(roll)`.
    pub rpy: [f64; 3],
}

/// The comment block to add after the `<robot>` start tag.
#[derive(Clone, Debug)]
pub struct CommentBlock<'a> {
    /// The first word of the comment. A comment of the input (a child of `<robot>`) that starts with
    /// it is removed, so that a file edited twice carries one block, the current one.
    pub marker: &'a str,
    /// Lines after the marker, without indentation. `--` (not allowed in an XML comment) is written
    /// as `- -`.
    pub lines: &'a [String],
}

/// `text` with the origins of the joints in `edits` rewritten and `comment` added; `source_name` names
/// the text in errors. A joint that has an `<origin>` keeps its position, attribute order and quotes
/// (a missing `rpy` attribute is added after `xyz`, only when not zero); a joint without one gets
/// `<origin xyz=".." rpy=".."/>` as its first child, indented like its next child.
///
/// # Errors
/// [`SimError::Parse`] when the markup is unterminated, the root element is not `<robot>`, a joint
/// named in `edits` is not a child of `<robot>` or has two `<origin>` children.
pub fn edit_joint_origins(
    text: &str,
    source_name: &str,
    edits: &[OriginEdit],
    comment: &CommentBlock,
) -> Result<String> {
    let err = |message: String| SimError::Parse {
        source_name: source_name.to_string(),
        message,
    };
    let wanted: HashMap<&str, usize> = edits
        .iter()
        .enumerate()
        .map(|(i, e)| (e.joint.as_str(), i))
        .collect();
    let mut done = vec![false; edits.len()];
    // (range to replace, new text), applied from the back.
    let mut patches: Vec<(Range<usize>, String)> = Vec::new();
    let mut stack: Vec<&str> = Vec::new();
    let mut robot_end: Option<usize> = None;
    // The joint being read: (edit index, its start tag, its <origin> tag if seen).
    let mut current: Option<(usize, Tag, Option<Tag>)> = None;
    for item in Scanner::new(text) {
        let item =
            item.map_err(|(pos, what)| err(format!("{what} at line {}", line_of(text, pos))))?;
        match item {
            Item::Open(tag) => {
                let depth = stack.len();
                if depth == 0 {
                    if tag.name(text) != "robot" {
                        return Err(err(format!(
                            "the root element is <{}>, not <robot>",
                            tag.name(text)
                        )));
                    }
                    robot_end = Some(tag.span.end);
                } else if depth == 1 && tag.name(text) == "joint" {
                    if let Some(&i) = tag.attr(text, "name").and_then(|v| wanted.get(v.as_str())) {
                        if done[i] {
                            return Err(err(format!(
                                "joint '{}' is defined twice",
                                edits[i].joint
                            )));
                        }
                        if tag.self_closing {
                            return Err(err(format!("joint '{}' has no children", edits[i].joint)));
                        }
                        current = Some((i, tag.clone(), None));
                    }
                } else if depth == 2
                    && tag.name(text) == "origin"
                    && let Some((i, _, origin)) = &mut current
                {
                    if origin.is_some() {
                        return Err(err(format!(
                            "joint '{}' has two <origin> elements",
                            edits[*i].joint
                        )));
                    }
                    *origin = Some(tag.clone());
                }
                if !tag.self_closing {
                    stack.push(tag.name(text));
                }
            }
            Item::Close(span, name) => {
                if stack.pop() != Some(name) {
                    return Err(err(format!(
                        "</{name}> does not close the open element at line {}",
                        line_of(text, span.start)
                    )));
                }
                if stack.len() == 1
                    && name == "joint"
                    && let Some((i, joint, origin)) = current.take()
                {
                    patches.extend(origin_patches(text, &edits[i], &joint, origin.as_ref()));
                    done[i] = true;
                }
            }
            Item::Comment(span) => {
                let body = text[span.start + 4..span.end - 3].trim_start();
                if stack.len() == 1 && body.starts_with(comment.marker) {
                    patches.push((whole_lines(text, span), String::new()));
                }
            }
        }
    }
    if !stack.is_empty() {
        return Err(err(format!("<{}> is not closed", stack[stack.len() - 1])));
    }
    let Some(robot_end) = robot_end else {
        return Err(err("no <robot> element".into()));
    };
    if let Some(i) = done.iter().position(|d| !d) {
        return Err(err(format!(
            "joint '{}' is not a <joint> element of <robot>",
            edits[i].joint
        )));
    }
    patches.push((robot_end..robot_end, comment_text(text, robot_end, comment)));
    patches.sort_by_key(|(r, _)| (r.start, r.end));
    let mut out = text.to_string();
    for (range, new) in patches.into_iter().rev() {
        out.replace_range(range, &new);
    }
    Ok(out)
}

/// A number as URDF text: the shortest decimal that reads back to the same `f64` (`0` for ±0).
pub fn number(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let s = format!("{x:?}");
    s.strip_suffix(".0").map_or(s.clone(), str::to_string)
}

fn triple(v: &[f64; 3]) -> String {
    format!("{} {} {}", number(v[0]), number(v[1]), number(v[2]))
}

/// The replacements that give `joint` the origin of `edit`.
fn origin_patches(
    text: &str,
    edit: &OriginEdit,
    joint: &Tag,
    origin: Option<&Tag>,
) -> Vec<(Range<usize>, String)> {
    let rpy_zero = edit.rpy.iter().all(|v| *v == 0.0);
    let Some(o) = origin else {
        // A first child, indented like the joint's next child.
        let rest = &text[joint.span.end..];
        let ws = &rest[..rest.len() - rest.trim_start().len()];
        let lead = match ws.rfind('\n') {
            Some(k) if k > 0 && ws.as_bytes()[k - 1] == b'\r' => &ws[k - 1..],
            Some(k) => &ws[k..],
            None => "",
        };
        let new = format!(
            "{lead}<origin xyz=\"{}\" rpy=\"{}\"/>",
            triple(&edit.xyz),
            triple(&edit.rpy)
        );
        return vec![(joint.span.end..joint.span.end, new)];
    };
    let mut out = Vec::new();
    let xyz = o.attrs.iter().find(|a| &text[a.name.clone()] == "xyz");
    let rpy = o.attrs.iter().find(|a| &text[a.name.clone()] == "rpy");
    let mut missing = String::new();
    match xyz {
        Some(a) => out.push((a.value.clone(), triple(&edit.xyz))),
        None => missing.push_str(&format!(" xyz=\"{}\"", triple(&edit.xyz))),
    }
    match rpy {
        Some(a) => out.push((a.value.clone(), triple(&edit.rpy))),
        None if !rpy_zero => missing.push_str(&format!(" rpy=\"{}\"", triple(&edit.rpy))),
        None => {}
    }
    if !missing.is_empty() {
        // After the last attribute (its closing quote), or after the element name.
        let at = o
            .attrs
            .iter()
            .map(|a| a.value.end + 1)
            .max()
            .unwrap_or(o.name_range.end);
        out.push((at..at, missing));
    }
    out
}

/// The comment block, placed after the `<robot>` start tag that ends at `at` and indented like the
/// element after it.
fn comment_text(text: &str, at: usize, c: &CommentBlock) -> String {
    let rest = &text[at..];
    let ws = &rest[..rest.len() - rest.trim_start().len()];
    let indent = match ws.rfind('\n') {
        Some(k) => ws[k + 1..].to_string(),
        None => String::new(),
    };
    // The file's own line break (CRLF files stay CRLF).
    let nl = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let clean = |s: &str| {
        let mut s = s.to_string();
        while s.contains("--") {
            s = s.replace("--", "- -");
        }
        s
    };
    let mut out = format!("{nl}{indent}<!-- {}", clean(c.marker));
    for l in c.lines {
        out.push_str(nl);
        if !l.is_empty() {
            out.push_str(&format!("{indent}     {}", clean(l.trim_end_matches('-'))));
        }
    }
    out.push_str(&format!("{nl}{indent}-->"));
    out
}

/// `span` widened to whole lines when only whitespace shares its first and last line.
fn whole_lines(text: &str, span: Range<usize>) -> Range<usize> {
    let line_start = text[..span.start].rfind('\n').map_or(0, |k| k + 1);
    let line_end = text[span.end..]
        .find('\n')
        .map_or(text.len(), |k| span.end + k + 1);
    if text[line_start..span.start].trim().is_empty() && text[span.end..line_end].trim().is_empty()
    {
        line_start..line_end
    } else {
        span
    }
}

fn line_of(text: &str, pos: usize) -> usize {
    1 + text.as_bytes()[..pos.min(text.len())]
        .iter()
        .filter(|&&c| c == b'\n')
        .count()
}

/// A start tag: byte ranges into the text.
#[derive(Clone, Debug)]
struct Tag {
    span: Range<usize>,
    name_range: Range<usize>,
    attrs: Vec<Attr>,
    self_closing: bool,
}

#[derive(Clone, Debug)]
struct Attr {
    name: Range<usize>,
    /// Inside the quotes.
    value: Range<usize>,
}

impl Tag {
    fn name<'t>(&self, text: &'t str) -> &'t str {
        &text[self.name_range.clone()]
    }

    fn attr(&self, text: &str, name: &str) -> Option<String> {
        self.attrs
            .iter()
            .find(|a| &text[a.name.clone()] == name)
            .map(|a| unescape(&text[a.value.clone()]))
    }
}

/// XML's five named entities and numeric character references.
fn unescape(s: &str) -> String {
    if !s.contains('&') {
        return s.to_string();
    }
    let mut out = String::new();
    let mut rest = s;
    while let Some(k) = rest.find('&') {
        out.push_str(&rest[..k]);
        rest = &rest[k..];
        let Some(end) = rest.find(';') else { break };
        let ent = &rest[1..end];
        let ch = match ent {
            "amp" => Some('&'),
            "lt" => Some('<'),
            "gt" => Some('>'),
            "quot" => Some('"'),
            "apos" => Some('\''),
            _ => ent
                .strip_prefix("#x")
                .map(|h| u32::from_str_radix(h, 16).ok())
                .unwrap_or_else(|| ent.strip_prefix('#').and_then(|d| d.parse().ok()))
                .and_then(char::from_u32),
        };
        match ch {
            Some(c) => {
                out.push(c);
                rest = &rest[end + 1..];
            }
            None => {
                out.push('&');
                rest = &rest[1..];
            }
        }
    }
    out.push_str(rest);
    out
}

enum Item<'t> {
    Open(Tag),
    Close(Range<usize>, &'t str),
    Comment(Range<usize>),
}

/// The markup of a document in order: start tags, end tags and comments (CDATA, processing
/// instructions and declarations are skipped; text is not reported).
struct Scanner<'t> {
    text: &'t str,
    pos: usize,
}

impl<'t> Scanner<'t> {
    fn new(text: &'t str) -> Self {
        Scanner { text, pos: 0 }
    }

    fn find_from(&self, from: usize, pat: &str) -> Option<usize> {
        self.text[from..].find(pat).map(|k| from + k)
    }

    fn is_name_char(c: u8) -> bool {
        !(c.is_ascii_whitespace() || matches!(c, b'/' | b'>' | b'=' | b'"' | b'\'' | b'<'))
    }

    fn start_tag(&self, start: usize) -> std::result::Result<Tag, (usize, &'static str)> {
        let b = self.text.as_bytes();
        let mut i = start + 1;
        let name_start = i;
        while i < b.len() && Self::is_name_char(b[i]) {
            i += 1;
        }
        if i == name_start {
            return Err((start, "a '<' that starts no element"));
        }
        let name_range = name_start..i;
        let mut attrs = Vec::new();
        loop {
            while i < b.len() && b[i].is_ascii_whitespace() {
                i += 1;
            }
            match b.get(i) {
                None => return Err((start, "an unterminated start tag")),
                Some(b'>') => {
                    return Ok(Tag {
                        span: start..i + 1,
                        name_range,
                        attrs,
                        self_closing: false,
                    });
                }
                Some(b'/') if b.get(i + 1) == Some(&b'>') => {
                    return Ok(Tag {
                        span: start..i + 2,
                        name_range,
                        attrs,
                        self_closing: true,
                    });
                }
                Some(_) => {}
            }
            let an = i;
            while i < b.len() && Self::is_name_char(b[i]) {
                i += 1;
            }
            if i == an {
                return Err((start, "a malformed attribute"));
            }
            let name = an..i;
            while i < b.len() && b[i].is_ascii_whitespace() {
                i += 1;
            }
            if b.get(i) != Some(&b'=') {
                return Err((start, "an attribute without a value"));
            }
            i += 1;
            while i < b.len() && b[i].is_ascii_whitespace() {
                i += 1;
            }
            let q = match b.get(i) {
                Some(&q @ (b'"' | b'\'')) => q,
                _ => return Err((start, "an unquoted attribute value")),
            };
            let vs = i + 1;
            let Some(ve) = b[vs..].iter().position(|&c| c == q).map(|k| vs + k) else {
                return Err((start, "an unterminated attribute value"));
            };
            attrs.push(Attr {
                name,
                value: vs..ve,
            });
            i = ve + 1;
        }
    }
}

impl<'t> Iterator for Scanner<'t> {
    type Item = std::result::Result<Item<'t>, (usize, &'static str)>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let start = self.find_from(self.pos, "<")?;
            let rest = &self.text[start..];
            let skip_past = |s: &Self, pat: &str, what: &'static str| {
                s.find_from(start + 1, pat)
                    .map(|k| k + pat.len())
                    .ok_or((start, what))
            };
            if rest.starts_with("<!--") {
                let end = match self.find_from(start + 4, "-->") {
                    Some(k) => k + 3,
                    None => return Some(Err((start, "an unterminated comment"))),
                };
                self.pos = end;
                return Some(Ok(Item::Comment(start..end)));
            }
            let skipped = if rest.starts_with("<![CDATA[") {
                skip_past(self, "]]>", "an unterminated CDATA section")
            } else if rest.starts_with("<?") {
                skip_past(self, "?>", "an unterminated processing instruction")
            } else if rest.starts_with("<!") {
                // A declaration; a DOCTYPE's internal subset is bracketed.
                match (self.find_from(start, "["), self.find_from(start, ">")) {
                    (Some(o), Some(c)) if o < c => self
                        .find_from(o, "]")
                        .and_then(|k| self.find_from(k, ">"))
                        .map(|k| k + 1)
                        .ok_or((start, "an unterminated declaration")),
                    (_, Some(c)) => Ok(c + 1),
                    _ => Err((start, "an unterminated declaration")),
                }
            } else if rest.starts_with("</") {
                let Some(end) = self.find_from(start, ">") else {
                    return Some(Err((start, "an unterminated end tag")));
                };
                self.pos = end + 1;
                let name = self.text[start + 2..end].trim_end();
                return Some(Ok(Item::Close(start..end + 1, name)));
            } else {
                return Some(self.start_tag(start).map(|tag| {
                    self.pos = tag.span.end;
                    Item::Open(tag)
                }));
            };
            match skipped {
                Ok(end) => self.pos = end,
                Err(e) => return Some(Err(e)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edit(joint: &str, xyz: [f64; 3], rpy: [f64; 3]) -> OriginEdit {
        OriginEdit {
            joint: joint.into(),
            xyz,
            rpy,
        }
    }

    const MARK: &str = "robocal-test";

    /// Inertials go, in every spelling; `<inertia>` inside them with them; everything else stays,
    /// and the built-in robots lose their masses and nothing else.
    #[test]
    fn without_inertials_removes_the_masses_only() {
        let text = "<robot name=\"r\"><link name=\"a\"><inertial>\n<mass value=\"2\"/>\
                    <inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial>\
                    <visual/></link><link name=\"b\"><inertial  /></link><inertials_note/>\
                    <link name=\"c\"><inertial\n><mass value=\"1\"/></inertial></link></robot>";
        assert_eq!(
            without_inertials(text),
            "<robot name=\"r\"><link name=\"a\"><visual/></link><link name=\"b\"></link>\
             <inertials_note/><link name=\"c\"></link></robot>"
        );
        assert_eq!(without_inertials("<inertial><mass/>"), "<inertial><mass/>");
        for (name, urdf) in crate::robots::BUILTIN {
            let full = crate::urdf::load_str(urdf, name, &Default::default()).unwrap();
            let bare =
                crate::urdf::load_str(&without_inertials(urdf), name, &Default::default()).unwrap();
            assert!(full.require_inertials().is_ok() && bare.require_inertials().is_err());
            assert_eq!(bare.massless_links().len(), bare.nq(), "{name}");
            assert_eq!(full.home_flange(), bare.home_flange(), "{name}");
        }
    }

    fn run(text: &str, edits: &[OriginEdit]) -> Result<String> {
        let lines = vec!["line one".to_string(), "a -- b".to_string()];
        let c = CommentBlock {
            marker: MARK,
            lines: &lines,
        };
        edit_joint_origins(text, "t.urdf", edits, &c)
    }

    /// Hand-written expected bytes: only the values change; quotes, attribute order, spacing, the
    /// transmission's own `<joint>` and other joints are kept.
    #[test]
    fn only_the_named_origins_change_and_everything_else_is_kept() {
        let text = "<?xml version=\"1.0\"?>\n<!-- top -->\n<robot name='r'>\n  <link name=\"a\"/>\n  \
                    <joint type=\"revolute\" name=\"j1\">\n    <parent link=\"a\"/>\n    \
                    <origin rpy='0 0 0'   xyz = \"1 2 3\" />\n  </joint>\n  <joint name=\"j2\" type=\"fixed\">\n    \
                    <origin xyz=\"0 0 1\"/>\n  </joint>\n  <transmission name=\"t\"><joint name=\"j1\"><origin xyz=\"9 9 9\"/></joint></transmission>\n</robot>\n";
        let out = run(
            text,
            &[edit(
                "j1",
                [0.5, -0.0, 1e-5],
                [0.0, 0.25, -std::f64::consts::FRAC_PI_2],
            )],
        )
        .unwrap();
        let expected = "<?xml version=\"1.0\"?>\n<!-- top -->\n<robot name='r'>\n  <!-- robocal-test\n       line one\n       a - - b\n  -->\n  <link name=\"a\"/>\n  \
                    <joint type=\"revolute\" name=\"j1\">\n    <parent link=\"a\"/>\n    \
                    <origin rpy='0 0.25 -1.5707963267948966'   xyz = \"0.5 0 1e-5\" />\n  </joint>\n  <joint name=\"j2\" type=\"fixed\">\n    \
                    <origin xyz=\"0 0 1\"/>\n  </joint>\n  <transmission name=\"t\"><joint name=\"j1\"><origin xyz=\"9 9 9\"/></joint></transmission>\n</robot>\n";
        assert_eq!(out, expected);
        // Edited again: one comment block, the new one.
        let again = run(&out, &[edit("j2", [0.0, 0.0, 2.0], [0.0; 3])]).unwrap();
        assert_eq!(again.matches(MARK).count(), 1);
        assert!(again.contains("<origin xyz=\"0 0 2\"/>"));
    }

    #[test]
    fn a_missing_origin_or_rpy_is_added() {
        let text = "<robot name=\"r\">\n  <joint name=\"j\" type=\"fixed\">\n    <parent link=\"a\"/>\n  </joint>\n  \
                    <joint name=\"k\" type=\"fixed\"><origin xyz=\"1 0 0\"/></joint>\n  \
                    <joint name=\"z\" type=\"fixed\"><origin/></joint>\n</robot>";
        let out = run(
            text,
            &[
                edit("j", [1.0, 0.0, 0.0], [0.0; 3]),
                edit("k", [2.0, 0.0, 0.0], [0.5, 0.0, 0.0]),
                edit("z", [0.0; 3], [0.0; 3]),
            ],
        )
        .unwrap();
        assert!(
            out.contains(
                "<joint name=\"j\" type=\"fixed\">\n    <origin xyz=\"1 0 0\" rpy=\"0 0 0\"/>\n    <parent"
            ),
            "{out}"
        );
        assert!(
            out.contains("<origin xyz=\"2 0 0\" rpy=\"0.5 0 0\"/>"),
            "{out}"
        );
        assert!(out.contains("<origin xyz=\"0 0 0\"/>"), "{out}");
    }

    /// A CRLF file stays CRLF: the comment block and an added <origin> use its line break.
    #[test]
    fn crlf_files_keep_their_line_breaks() {
        let text = "<robot name=\"r\">\r\n  <joint name=\"j\" type=\"fixed\">\r\n    <parent link=\"a\"/>\r\n  </joint>\r\n</robot>\r\n";
        let out = run(text, &[edit("j", [1.0, 0.0, 0.0], [0.0; 3])]).unwrap();
        assert!(!out.replace("\r\n", "").contains('\n'), "{out:?}");
        assert!(out.contains(
            "type=\"fixed\">\r\n    <origin xyz=\"1 0 0\" rpy=\"0 0 0\"/>\r\n    <parent"
        ));
        assert!(
            out.starts_with("<robot name=\"r\">\r\n  <!-- robocal-test\r\n       line one\r\n")
        );
    }

    #[test]
    fn names_are_compared_after_unescaping_and_bad_markup_is_an_error() {
        let text = "<robot name=\"r\"><joint name=\"a&amp;b&#33;\"><origin xyz=\"0 0 0\"/></joint></robot>";
        let out = run(text, &[edit("a&b!", [1.0, 0.0, 0.0], [0.0; 3])]).unwrap();
        assert!(out.contains("xyz=\"1 0 0\""));
        let e = |t: &str, j: &str| {
            run(t, &[edit(j, [0.0; 3], [0.0; 3])])
                .unwrap_err()
                .to_string()
        };
        assert!(e(text, "nope").contains("joint 'nope' is not a <joint> element of <robot>"));
        assert!(
            e(
                "<robot><joint name=\"j\"><origin/><origin/></joint></robot>",
                "j"
            )
            .contains("two <origin>")
        );
        assert!(e("<robot>\n<joint name=\"j\" </robot>", "j").contains("line 2"));
        assert!(e("<urdf><joint name=\"j\"/></urdf>", "j").contains("not <robot>"));
        assert!(e("<robot><a></robot>", "j").contains("does not close"));
        assert!(e("<robot>", "j").contains("not closed"));
        // A CDATA section, a DOCTYPE with an internal subset and '>' in a value are skipped over.
        let text = "<!DOCTYPE robot [ <!ENTITY x \"<joint>\"> ]><robot name=\"a>b\"><![CDATA[<joint name=\"j\">]]>\
                    <joint name=\"j\"><origin xyz=\"0 0 0\"/></joint></robot>";
        assert!(
            run(text, &[edit("j", [3.0, 0.0, 0.0], [0.0; 3])])
                .unwrap()
                .contains("xyz=\"3 0 0\"")
        );
    }

    #[test]
    fn numbers_read_back_exactly() {
        for x in [
            0.1,
            -std::f64::consts::FRAC_PI_2,
            1e-17,
            123456.789,
            1.0,
            -0.0,
            2.5e300,
        ] {
            assert_eq!(number(x).parse::<f64>().unwrap(), x);
        }
        assert_eq!(number(-0.0), "0");
        assert_eq!(number(3.0), "3");
    }
}
