//! One table, two renderings: a paper table is built once as plain cells and written as
//! Markdown (inside a report's text) and as a LaTeX `tabular` (for the paper), so the two can
//! never disagree. Cells are plain text; `±`, `†`, `−`-style symbols and LaTeX's special
//! characters are translated by the LaTeX writer.

/// A table: a header row and body rows, the first column the rows' labels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    /// A line saying what the table is; LaTeX writes it as a comment above the `tabular`
    /// (Markdown reports give their own title).
    pub caption: Option<String>,
    pub header: Vec<String>,
    pub rows: Vec<TableRow>,
}

/// One body row.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TableRow {
    pub cells: Vec<String>,
    /// Set in italics (the paper's reference rows beside ours).
    pub emphasis: bool,
}

impl TableRow {
    pub fn new(cells: Vec<String>) -> TableRow {
        TableRow {
            cells,
            emphasis: false,
        }
    }

    pub fn emphasized(cells: Vec<String>) -> TableRow {
        TableRow {
            cells,
            emphasis: true,
        }
    }
}

impl Table {
    pub fn new(header: Vec<String>) -> Table {
        Table {
            caption: None,
            header,
            rows: Vec::new(),
        }
    }

    /// A table with the header `names`.
    pub fn labelled(names: &[&str]) -> Table {
        Table::new(names.iter().map(|n| n.to_string()).collect())
    }

    pub fn push(&mut self, row: TableRow) {
        self.rows.push(row);
    }

    /// A GitHub-flavoured Markdown table (`| a | b |`, an empty cell as `| |`), italics as
    /// `*...*` around each non-empty cell of an emphasized row.
    pub fn markdown(&self) -> String {
        fn line(cells: &[String], emphasis: bool) -> String {
            let mut out = String::from("|");
            for c in cells {
                match (c.is_empty(), emphasis) {
                    (true, _) => out.push_str(" |"),
                    (false, true) => out.push_str(&format!(" *{c}* |")),
                    (false, false) => out.push_str(&format!(" {c} |")),
                }
            }
            out.push('\n');
            out
        }
        let mut out = line(&self.header, false);
        out.push('|');
        out.push_str(&"---|".repeat(self.header.len()));
        out.push('\n');
        for r in &self.rows {
            out.push_str(&line(&r.cells, r.emphasis));
        }
        out
    }

    /// A LaTeX `tabular`: the label column left-aligned, the others right-aligned, rules
    /// above and below the header and at the end; italics as `\textit{...}`.
    pub fn latex(&self) -> String {
        let mut out = String::new();
        if let Some(c) = &self.caption {
            out.push_str(&format!("% {c}\n"));
        }
        let columns = self.header.len().max(1);
        out.push_str(&format!(
            "\\begin{{tabular}}{{l{}}}\n\\hline\n",
            "r".repeat(columns - 1)
        ));
        let line = |cells: &[String], emphasis: bool| {
            let cells: Vec<String> = cells
                .iter()
                .map(|c| match (c.is_empty(), emphasis) {
                    (false, true) => format!("\\textit{{{}}}", latex_text(c)),
                    _ => latex_text(c),
                })
                .collect();
            format!("{} \\\\\n", cells.join(" & ").trim_end())
        };
        out.push_str(&line(&self.header, false));
        out.push_str("\\hline\n");
        for r in &self.rows {
            out.push_str(&line(&r.cells, r.emphasis));
        }
        out.push_str("\\hline\n\\end{tabular}\n");
        out
    }
}

/// Plain cell text as LaTeX: its special characters escaped, `±` and `†` as math, Markdown's
/// `_` in names kept literal.
fn latex_text(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '\\' => out.push_str("\\textbackslash{}"),
            '&' | '%' | '$' | '#' | '_' | '{' | '}' => {
                out.push('\\');
                out.push(ch);
            }
            '~' => out.push_str("\\textasciitilde{}"),
            '^' => out.push_str("\\textasciicircum{}"),
            '±' => out.push_str("$\\pm$"),
            '†' => out.push_str("$^\\dagger$"),
            _ => out.push(ch),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Table {
        let mut t = Table::new(["", "MSE_Joy", "All"].map(String::from).into());
        t.caption = Some("Table X: a test".into());
        t.push(TableRow::new(
            ["facelab", "1.1e-3 ± 2.0e-4 †", ""]
                .map(String::from)
                .into(),
        ));
        t.push(TableRow::emphasized(
            ["Zeng et al.: 50% & more", "0.191", "0.157"]
                .map(String::from)
                .into(),
        ));
        t
    }

    #[test]
    fn markdown_and_latex_carry_the_same_cells() {
        assert_eq!(
            table().markdown(),
            "| | MSE_Joy | All |\n|---|---|---|\n| facelab | 1.1e-3 ± 2.0e-4 † | |\n\
             | *Zeng et al.: 50% & more* | *0.191* | *0.157* |\n"
        );
        assert_eq!(
            table().latex(),
            "% Table X: a test\n\\begin{tabular}{lrr}\n\\hline\n & MSE\\_Joy & All \\\\\n\\hline\n\
             facelab & 1.1e-3 $\\pm$ 2.0e-4 $^\\dagger$ & \\\\\n\
             \\textit{Zeng et al.: 50\\% \\& more} & \\textit{0.191} & \\textit{0.157} \\\\\n\
             \\hline\n\\end{tabular}\n"
        );
    }
}
