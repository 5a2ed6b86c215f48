//! A small typed document — headings, paragraphs, lists, key/value lists, tables, figures and
//! warnings — built once and rendered three ways: terminal text ([`Document::to_text`]), Markdown
//! ([`Document::to_markdown`]) and HTML ([`Document::to_html`]). The diagnosis is such a document
//! (`crate::report::diagnosis`), so that what `robocal diagnose` prints, `summary.md` and
//! `index.html` carry the same content without one rendering being parsed back into another.

mod html;
mod markdown;
mod text;

/// A piece of running text.
#[derive(Clone, Debug, PartialEq)]
pub enum Span {
    /// Plain text.
    Text(String),
    /// Emphasised text (a cause named in a finding).
    Strong(String),
    /// A word of the command line or a file (`calibrate --model auto`).
    Code(String),
}

impl Span {
    /// The span's text, without markup.
    pub fn plain(&self) -> &str {
        match self {
            Span::Text(s) | Span::Strong(s) | Span::Code(s) => s,
        }
    }
}

/// Plain text as one span.
pub fn text(s: impl Into<String>) -> Vec<Span> {
    vec![Span::Text(s.into())]
}

/// How a table column's cells are aligned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Align {
    /// Left (words).
    Left,
    /// Right (numbers).
    Right,
}

/// A table: a header row and rows of cells (plain text), one alignment per column.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Column headers.
    pub header: Vec<String>,
    /// Alignment per column (as many as `header`).
    pub align: Vec<Align>,
    /// Rows, each with as many cells as `header`.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// A table with `header`; the first column left-aligned, the others right-aligned.
    pub fn new(header: &[&str]) -> Table {
        let align = (0..header.len())
            .map(|i| if i == 0 { Align::Left } else { Align::Right })
            .collect();
        Table {
            header: header.iter().map(|h| h.to_string()).collect(),
            align,
            rows: Vec::new(),
        }
    }

    /// The same table with column `i` left-aligned.
    pub fn left(mut self, i: usize) -> Table {
        self.align[i] = Align::Left;
        self
    }

    /// Adds a row (as many cells as the header).
    pub fn row(&mut self, cells: Vec<String>) {
        debug_assert_eq!(cells.len(), self.header.len());
        self.rows.push(cells);
    }
}

/// One block of a document.
#[derive(Clone, Debug, PartialEq)]
pub enum Block {
    /// A heading of level 1 (the title) or 2 (a section).
    Heading(u8, String),
    /// A paragraph.
    Paragraph(Vec<Span>),
    /// A bulleted list, one item per entry.
    List(Vec<Vec<Span>>),
    /// Key/value pairs (`key: value`).
    KeyValues(Vec<(String, String)>),
    /// A table.
    Table(Table),
    /// A figure: an image file beside the document (SVG) and its caption.
    Figure {
        /// File name, relative to the document.
        file: String,
        /// Caption (also the image's alternative text).
        caption: String,
    },
    /// A warning: something the reader must not miss (one line in the terminal).
    Warning(String),
}

/// A document: blocks in reading order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Document {
    /// The blocks.
    pub blocks: Vec<Block>,
}

impl Document {
    /// Appends a block.
    pub fn push(&mut self, block: Block) {
        self.blocks.push(block);
    }

    /// Terminal text (stderr): headings as lines, tables as aligned columns, warnings as
    /// `warning: …` lines.
    pub fn to_text(&self) -> String {
        text::render(self)
    }

    /// Markdown (GitHub-flavoured tables).
    pub fn to_markdown(&self) -> String {
        markdown::render(self)
    }

    /// A standalone HTML page titled `title`, every text escaped.
    pub fn to_html(&self, title: &str) -> String {
        html::render(self, title)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Document {
        let mut t = Table::new(&["model", "test RMS"]);
        t.row(vec!["kinematic".into(), "12.5 µm".into()]);
        t.row(vec!["kinematic+a<b & c|d".into(), "7.0 µm".into()]);
        Document {
            blocks: vec![
                Block::Heading(1, "Title <x>".into()),
                Block::Paragraph(vec![Span::Text("see ".into()), Span::Code("a|b".into())]),
                Block::Table(t),
                Block::List(vec![vec![
                    Span::Strong("cause".into()),
                    Span::Text(": 5 < 6".into()),
                ]]),
                Block::KeyValues(vec![("noise floor".into(), "10 µm".into())]),
                Block::Warning("not tried: x".into()),
                Block::Figure {
                    file: "errors.svg".into(),
                    caption: "Errors \"held out\"".into(),
                },
            ],
        }
    }

    #[test]
    fn html_escapes_text() {
        let html = sample().to_html("t & <u>");
        assert!(html.contains("<title>t &amp; &lt;u&gt;</title>"), "{html}");
        assert!(html.contains("<h1>Title &lt;x&gt;</h1>"), "{html}");
        assert!(
            html.contains("<td>kinematic+a&lt;b &amp; c|d</td>"),
            "{html}"
        );
        assert!(html.contains("<code>a|b</code>"), "{html}");
        assert!(html.contains(": 5 &lt; 6"), "{html}");
        assert!(
            html.contains("alt=\"Errors &quot;held out&quot;\""),
            "{html}"
        );
        assert!(!html.contains("<x>") && !html.contains("a<b"), "{html}");
    }

    #[test]
    fn markdown_escapes_table_pipes_and_tags() {
        let md = sample().to_markdown();
        assert!(md.contains("| kinematic+a\\<b & c\\|d | 7.0 µm |"), "{md}");
        assert!(md.contains("# Title \\<x>"), "{md}");
        assert!(md.contains("|---|---:|"), "{md}");
        assert!(md.contains("![Errors \"held out\"](errors.svg)"), "{md}");
    }

    #[test]
    fn text_aligns_tables_and_prints_warnings_on_one_line() {
        let t = sample().to_text();
        assert!(t.contains("\nwarning: not tried: x\n"), "{t}");
        let rows: Vec<&str> = t.lines().filter(|l| l.contains("µm")).collect();
        assert_eq!(rows.len(), 3, "{t}");
        // Right-aligned numbers end in the same column.
        let ends: Vec<usize> = rows[..2].iter().map(|l| l.chars().count()).collect();
        assert_eq!(ends[0], ends[1], "{t}");
    }
}
