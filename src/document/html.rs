//! HTML: `index.html` of a diagnose report, a standalone page with every text escaped.

use super::{Align, Block, Document, Span};

/// `&`, `<`, `>` and `"` as entities: safe in text and in quoted attributes.
pub(super) fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn spans(s: &[Span]) -> String {
    s.iter()
        .map(|s| match s {
            Span::Text(t) => escape(t),
            Span::Strong(t) => format!("<strong>{}</strong>", escape(t)),
            Span::Code(t) => format!("<code>{}</code>", escape(t)),
        })
        .collect()
}

const STYLE: &str = "body{font-family:sans-serif;max-width:980px;margin:2em auto;line-height:1.4}\
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px}\
.r{text-align:right}img{max-width:100%}\
.warning{background:#fff4e5;border-left:4px solid #e69500;padding:6px 10px}";

/// Renders `doc` as an HTML page titled `title`.
pub(super) fn render(doc: &Document, title: &str) -> String {
    let mut h = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\
         <style>{STYLE}</style></head><body>\n",
        escape(title)
    );
    for b in &doc.blocks {
        match b {
            Block::Heading(level, t) => {
                let l = (*level).clamp(1, 6);
                h.push_str(&format!("<h{l}>{}</h{l}>\n", escape(t)));
            }
            Block::Paragraph(p) => h.push_str(&format!("<p>{}</p>\n", spans(p))),
            Block::List(items) => {
                h.push_str("<ul>\n");
                for i in items {
                    h.push_str(&format!("<li>{}</li>\n", spans(i)));
                }
                h.push_str("</ul>\n");
            }
            Block::KeyValues(kv) => {
                h.push_str("<dl>\n");
                for (k, v) in kv {
                    h.push_str(&format!("<dt>{}</dt><dd>{}</dd>\n", escape(k), escape(v)));
                }
                h.push_str("</dl>\n");
            }
            Block::Table(t) => {
                let class = |a: &Align| match a {
                    Align::Left => "",
                    Align::Right => " class=\"r\"",
                };
                h.push_str("<table>\n<tr>");
                for c in &t.header {
                    h.push_str(&format!("<th>{}</th>", escape(c)));
                }
                h.push_str("</tr>\n");
                for r in &t.rows {
                    h.push_str("<tr>");
                    for (c, a) in r.iter().zip(&t.align) {
                        h.push_str(&format!("<td{}>{}</td>", class(a), escape(c)));
                    }
                    h.push_str("</tr>\n");
                }
                h.push_str("</table>\n");
            }
            Block::Figure { file, caption } => h.push_str(&format!(
                "<figure><img src=\"{}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>\n",
                escape(file),
                c = escape(caption)
            )),
            Block::Warning(w) => h.push_str(&format!(
                "<p class=\"warning\"><strong>Warning:</strong> {}</p>\n",
                escape(w)
            )),
        }
    }
    h.push_str("</body></html>\n");
    h
}
