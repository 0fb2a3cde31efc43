//! The labelled table a [`CsMat`] prints as (used by `ndds echo`).

use std::fmt;

use super::{CsMat, Field};

/// Columns are separated by this.
const GAP: &str = "  ";

impl fmt::Display for CsMat {
    /// A table: a header line of column labels, then one line per row starting with the row's
    /// label. A label is the field name followed by ` [unit]` when the unit is not empty, or
    /// the index when the axis has no fields (or the name is empty). Numbers are right-aligned;
    /// a precision (`{:.3}`) fixes their decimals, otherwise they are shown with up to 6
    /// decimals, trailing zeros dropped, or in exponent form when very large or small. An
    /// empty matrix prints as `(empty)`. The name is not printed.
    ///
    /// ```
    /// use ndds_runtime::CsMat;
    ///
    /// let x = CsMat::from_row_slice("x", 2, 1, &[1.5, -2.0])?
    ///     .with_row_fields([("q1", "rad"), ("q2", "rad")])?
    ///     .with_col_fields([("pos", "")])?;
    /// assert_eq!(x.to_string(), "          pos\nq1 [rad]  1.5\nq2 [rad]   -2");
    /// # Ok::<(), ndds_runtime::MatError>(())
    /// ```
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_empty() {
            return f.write_str("(empty)");
        }
        let precision = f.precision();
        let row_labels: Vec<String> = (0..self.rows())
            .map(|i| label(&self.row_fields, i))
            .collect();
        let col_labels: Vec<String> = (0..self.cols())
            .map(|j| label(&self.col_fields, j))
            .collect();
        let cells: Vec<Vec<String>> = self
            .m
            .row_iter()
            .map(|row| row.iter().map(|&v| number(v, precision)).collect())
            .collect();
        let label_width = width(row_labels.iter());
        let widths: Vec<usize> = col_labels
            .iter()
            .enumerate()
            .map(|(j, head)| width(cells.iter().filter_map(|row| row.get(j)).chain([head])))
            .collect();
        write!(f, "{:label_width$}", "")?;
        for (head, w) in col_labels.iter().zip(&widths) {
            write!(f, "{GAP}{head:>w$}")?;
        }
        for (row_label, row) in row_labels.iter().zip(&cells) {
            write!(f, "\n{row_label:<label_width$}")?;
            for (cell, w) in row.iter().zip(&widths) {
                write!(f, "{GAP}{cell:>w$}")?;
            }
        }
        Ok(())
    }
}

fn label(fields: &[Field], index: usize) -> String {
    match fields.get(index) {
        Some(field) if !field.name.is_empty() && !field.unit.is_empty() => {
            format!("{} [{}]", field.name, field.unit)
        }
        Some(field) if !field.name.is_empty() => field.name.clone(),
        Some(field) if !field.unit.is_empty() => format!("{index} [{}]", field.unit),
        _ => index.to_string(),
    }
}

fn width<'a>(texts: impl Iterator<Item = &'a String>) -> usize {
    texts.map(|t| t.chars().count()).max().unwrap_or(0)
}

fn number(value: f64, precision: Option<usize>) -> String {
    if let Some(p) = precision {
        return format!("{value:.p$}");
    }
    let magnitude = value.abs();
    if !value.is_finite() || value == 0.0 {
        // `0` for both zeros; NaN, inf and -inf as Rust prints them.
        return if value == 0.0 {
            "0".to_owned()
        } else {
            value.to_string()
        };
    }
    if (1e-3..1e9).contains(&magnitude) {
        let text = format!("{value:.6}");
        let trimmed = text.trim_end_matches('0').trim_end_matches('.');
        trimmed.to_owned()
    } else {
        format!("{value:.4e}")
    }
}
