//! Terminal text: what `robocal diagnose` prints on stderr.

use super::{Align, Block, Document, Span, Table};

/// Spans without markup, except that code keeps its backquotes.
fn spans(s: &[Span]) -> String {
    s.iter()
        .map(|s| match s {
            Span::Code(c) => format!("`{c}`"),
            other => other.plain().to_string(),
        })
        .collect()
}

/// A table as aligned columns, indented by two spaces, columns two spaces apart.
fn table(t: &Table) -> String {
    let width = |i: usize| {
        t.rows
            .iter()
            .map(|r| r[i].chars().count())
            .chain([t.header[i].chars().count()])
            .max()
            .unwrap_or(0)
    };
    let widths: Vec<usize> = (0..t.header.len()).map(width).collect();
    let line = |cells: &[String]| {
        let parts: Vec<String> = cells
            .iter()
            .zip(&widths)
            .zip(&t.align)
            .map(|((c, &w), a)| match a {
                Align::Left => format!("{c:<w$}"),
                Align::Right => format!("{c:>w$}"),
            })
            .collect();
        format!("  {}\n", parts.join("  ").trim_end())
    };
    let mut s = line(&t.header);
    for r in &t.rows {
        s.push_str(&line(r));
    }
    s
}

/// Renders `doc` as terminal text.
pub(super) fn render(doc: &Document) -> String {
    let mut s = String::new();
    for (k, b) in doc.blocks.iter().enumerate() {
        match b {
            Block::Heading(1, h) => s.push_str(&format!("{h}\n")),
            Block::Heading(_, h) => {
                if k > 0 {
                    s.push('\n');
                }
                s.push_str(&format!("{}:\n", h.to_lowercase()));
            }
            Block::Paragraph(p) => s.push_str(&format!("{}\n", spans(p))),
            Block::List(items) => {
                for i in items {
                    s.push_str(&format!("  - {}\n", spans(i)));
                }
            }
            Block::KeyValues(kv) => {
                for (key, v) in kv {
                    s.push_str(&format!("  {key}: {v}\n"));
                }
            }
            Block::Table(t) => {
                // Set off from running text above it.
                if k > 0 && !matches!(doc.blocks[k - 1], Block::Heading(..)) {
                    s.push('\n');
                }
                s.push_str(&table(t));
            }
            Block::Figure { file, caption } => {
                s.push_str(&format!("  figure: {caption} ({file})\n"));
            }
            Block::Warning(w) => s.push_str(&format!("warning: {w}\n")),
        }
    }
    s
}
