//! A report as one list of blocks, rendered to Markdown and to HTML from that same list: the
//! two files cannot drift apart, and each format escapes text in one place.

use base64::Engine;

/// The report: a title and its blocks, in order.
pub(crate) struct Document {
    pub title: String,
    /// The HTML page's extra style rules (tables, figures).
    pub style: &'static str,
    pub blocks: Vec<Block>,
}

pub(crate) enum Block {
    /// A section heading (level 2).
    Heading(String),
    Paragraph(String),
    /// A paragraph in bold: a verdict, or a warning about the whole report.
    Strong(String),
    Table(Table),
    List(Vec<String>),
    /// A picture: `file` relative to the report; its PNG bytes embedded in the HTML page when
    /// given (the page then stands alone), else linked.
    Figure {
        caption: String,
        file: String,
        png: Option<Vec<u8>>,
    },
    Code {
        language: &'static str,
        text: String,
    },
}

/// A table; an empty `head` (all columns blank) is a table of key-value rows.
pub(crate) struct Table {
    pub head: Vec<String>,
    pub rows: Vec<Vec<Cell>>,
}

/// One table cell: text, and in HTML a colour swatch before it (a class's colour).
pub(crate) struct Cell {
    pub text: String,
    pub swatch: Option<[u8; 3]>,
}

impl From<String> for Cell {
    fn from(text: String) -> Self {
        Self { text, swatch: None }
    }
}

impl From<&str> for Cell {
    fn from(text: &str) -> Self {
        text.to_owned().into()
    }
}

impl Table {
    pub fn new(head: &[&str]) -> Self {
        Self {
            head: head.iter().map(|&h| h.to_owned()).collect(),
            rows: Vec::new(),
        }
    }

    pub fn row(&mut self, cells: impl IntoIterator<Item = Cell>) {
        self.rows.push(cells.into_iter().collect());
    }
}

impl Document {
    pub fn new(title: String, style: &'static str) -> Self {
        Self {
            title,
            style,
            blocks: Vec::new(),
        }
    }

    pub fn push(&mut self, block: Block) {
        self.blocks.push(block);
    }

    pub fn markdown(&self) -> String {
        let mut md = format!("# {}\n", self.title);
        for block in &self.blocks {
            md.push('\n');
            match block {
                Block::Heading(text) => md += &format!("## {text}\n"),
                Block::Paragraph(text) => md += &format!("{text}\n"),
                Block::Strong(text) => md += &format!("**{text}**\n"),
                Block::Table(table) => {
                    let line = |cells: Vec<String>| format!("| {} |\n", cells.join(" | "));
                    md += &line(table.head.iter().map(|h| cell_md(h)).collect());
                    md += &format!("|{}\n", "---|".repeat(table.head.len()));
                    for row in &table.rows {
                        md += &line(row.iter().map(|c| cell_md(&c.text)).collect());
                    }
                }
                Block::List(items) => {
                    for item in items {
                        md += &format!("- {item}\n");
                    }
                }
                Block::Figure { caption, file, .. } => md += &format!("![{caption}]({file})\n"),
                Block::Code { language, text } => {
                    md += &format!("```{language}\n{}\n```\n", text.trim_end_matches('\n'))
                }
            }
        }
        md
    }

    pub fn html(&self) -> String {
        let title = escape(&self.title);
        let mut html = format!(
            "<!doctype html><meta charset=utf-8><title>{title}</title>\
             <style>body{{font-family:sans-serif}}{}</style><h1>{title}</h1>",
            self.style
        );
        for block in &self.blocks {
            match block {
                Block::Heading(text) => html += &format!("<h2>{}</h2>", escape(text)),
                Block::Paragraph(text) => html += &format!("<p>{}</p>", escape(text)),
                Block::Strong(text) => html += &format!("<p><b>{}</b></p>", escape(text)),
                Block::Table(table) => {
                    html += "<table>";
                    if table.head.iter().any(|h| !h.is_empty()) {
                        html += "<tr>";
                        for h in &table.head {
                            html += &format!("<th>{}", escape(h));
                        }
                        html += "</tr>";
                    }
                    for row in &table.rows {
                        html += "<tr>";
                        for c in row {
                            html += "<td>";
                            if let Some([r, g, b]) = c.swatch {
                                html += &format!(
                                    "<span style=\"background:rgb({r},{g},{b})\">\
                                     &nbsp;&nbsp;&nbsp;</span> "
                                );
                            }
                            html += &escape(&c.text);
                        }
                        html += "</tr>";
                    }
                    html += "</table>";
                }
                Block::List(items) => {
                    html += "<ul>";
                    for item in items {
                        html += &format!("<li>{}</li>", escape(item));
                    }
                    html += "</ul>";
                }
                Block::Figure { caption, file, png } => {
                    let src = match png {
                        Some(png) => format!(
                            "data:image/png;base64,{}",
                            base64::engine::general_purpose::STANDARD.encode(png)
                        ),
                        None => escape(file),
                    };
                    let caption = escape(caption);
                    html += &format!(
                        "<figure><img src=\"{src}\" alt=\"{caption}\">\
                         <figcaption>{caption}</figcaption></figure>"
                    );
                }
                Block::Code { text, .. } => html += &format!("<pre>{}</pre>", escape(text)),
            }
        }
        html
    }
}

/// A table cell's text in Markdown: a `|` would end the cell.
fn cell_md(text: &str) -> String {
    text.replace('|', "\\|")
}

/// Text safe inside HTML (element content and quoted attributes).
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Document {
        let mut doc = Document::new("a <report>".into(), "");
        doc.push(Block::Strong("stopped early".into()));
        let mut table = Table::new(&["id", "class"]);
        table.row([
            Cell::from("1"),
            Cell {
                text: "a|b & <c>".into(),
                swatch: Some([1, 2, 3]),
            },
        ]);
        doc.push(Block::Table(table));
        doc.push(Block::Heading("Warnings".into()));
        doc.push(Block::List(vec!["x < y".into()]));
        doc.push(Block::Code {
            language: "toml",
            text: "a = \"<b>\"\n".into(),
        });
        doc
    }

    #[test]
    fn markdown_keeps_each_table_row_to_its_cells() {
        let md = sample().markdown();
        assert!(
            md.starts_with("# a <report>\n\n**stopped early**\n"),
            "{md}"
        );
        assert!(
            md.contains("| id | class |\n|---|---|\n| 1 | a\\|b & <c> |\n"),
            "{md}"
        );
        assert!(md.contains("\n## Warnings\n\n- x < y\n"), "{md}");
        assert!(md.contains("```toml\na = \"<b>\"\n```\n"), "{md}");
    }

    #[test]
    fn html_escapes_every_text_once() {
        let html = sample().html();
        assert!(html.contains("<h1>a &lt;report&gt;</h1>"), "{html}");
        assert!(html.contains("<tr><th>id<th>class</tr>"), "{html}");
        assert!(
            html.contains("background:rgb(1,2,3)") && html.contains("a|b &amp; &lt;c&gt;"),
            "{html}"
        );
        assert!(html.contains("<li>x &lt; y</li>"), "{html}");
        assert!(
            html.contains("<pre>a = &quot;&lt;b&gt;&quot;\n</pre>"),
            "{html}"
        );
        // Only the markup's own tags are left: none from the text.
        assert!(!html.contains("<report>") && !html.contains("<c>") && !html.contains("<b>\""));
    }
}
