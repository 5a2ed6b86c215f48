//! Markdown: `summary.md` of a diagnose report.

use super::{Align, Block, Document, Span};

/// Running text: `<` escaped, so that `<inertial>` in a message is shown, not taken for HTML.
fn plain(t: &str) -> String {
    t.replace('<', "\\<")
}

/// A table cell: running text with `|` escaped and line breaks as spaces.
fn cell(c: &str) -> String {
    plain(c).replace('|', "\\|").replace(['\n', '\r'], " ")
}

fn spans(s: &[Span]) -> String {
    s.iter()
        .map(|s| match s {
            Span::Text(t) => plain(t),
            Span::Strong(t) => format!("**{}**", plain(t)),
            Span::Code(t) => format!("`{t}`"),
        })
        .collect()
}

/// Renders `doc` as Markdown, blocks separated by blank lines.
pub(super) fn render(doc: &Document) -> String {
    let mut parts = Vec::new();
    for b in &doc.blocks {
        parts.push(match b {
            Block::Heading(level, h) => {
                format!(
                    "{} {}\n",
                    "#".repeat(usize::from((*level).max(1))),
                    plain(h)
                )
            }
            Block::Paragraph(p) => format!("{}\n", spans(p)),
            Block::List(items) => items.iter().map(|i| format!("- {}\n", spans(i))).collect(),
            Block::KeyValues(kv) => kv.iter().map(|(k, v)| format!("- {k}: {v}\n")).collect(),
            Block::Table(t) => {
                let row = |cells: &[String]| {
                    let c: Vec<String> = cells.iter().map(|c| cell(c)).collect();
                    format!("| {} |\n", c.join(" | "))
                };
                let rule: Vec<&str> = t
                    .align
                    .iter()
                    .map(|a| match a {
                        Align::Left => "---",
                        Align::Right => "---:",
                    })
                    .collect();
                let mut s = row(&t.header);
                s.push_str(&format!("|{}|\n", rule.join("|")));
                for r in &t.rows {
                    s.push_str(&row(r));
                }
                s
            }
            Block::Figure { file, caption } => format!("![{}]({file})\n", plain(caption)),
            Block::Warning(w) => format!("> **Warning:** {}\n", plain(w)),
        });
    }
    parts.join("\n")
}
