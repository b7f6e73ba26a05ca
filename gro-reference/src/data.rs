//! # Reading the workspace's reference CSV files
//!
//! All files under `data/` share one format (data/README.md): `#` comment lines, one header
//! line, then comma-separated rows with no quoting and no missing fields (`v_mag` may be
//! empty in a regenerated Hipparcos file). This reader keeps the cells as text and converts on
//! access, naming the file, row and column in every error.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};

/// The Hipparcos subset (`data/hipparcos_mag6p5.csv`), embedded so that a run does not
/// depend on the working directory.
pub const HIPPARCOS_CSV: &str = include_str!("../../data/hipparcos_mag6p5.csv");

/// The workspace `data/` directory (next to this crate).
#[must_use]
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("data")
}

/// A parsed CSV file: header and text cells.
#[derive(Clone, Debug)]
pub struct CsvTable {
    source: String,
    columns: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl CsvTable {
    /// Parse CSV text; `source` names it in errors.
    ///
    /// # Errors
    /// No header, or a row whose field count differs from the header's.
    pub fn parse(text: &str, source: &str) -> anyhow::Result<Self> {
        let mut lines = text
            .lines()
            .map(str::trim_end)
            .filter(|l| !l.is_empty() && !l.starts_with('#'));
        let header = lines
            .next()
            .ok_or_else(|| anyhow!("{source}: no header line"))?;
        let columns: Vec<String> = header.split(',').map(|c| c.trim().to_owned()).collect();
        let mut rows = Vec::new();
        for (i, line) in lines.enumerate() {
            let cells: Vec<String> = line.split(',').map(|c| c.trim().to_owned()).collect();
            if cells.len() != columns.len() {
                return Err(anyhow!(
                    "{source}: data row {i} has {} fields, header has {}",
                    cells.len(),
                    columns.len()
                ));
            }
            rows.push(cells);
        }
        Ok(Self {
            source: source.to_owned(),
            columns,
            rows,
        })
    }

    /// Read and parse a file.
    ///
    /// # Errors
    /// I/O or format errors, with the path.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Number of data rows.
    #[must_use]
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// No data rows.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Index of a named column.
    ///
    /// # Errors
    /// The column does not exist.
    pub fn column(&self, name: &str) -> anyhow::Result<usize> {
        self.columns
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| anyhow!("{}: no column {name:?}", self.source))
    }

    /// Raw text of a cell (empty string if out of range).
    #[must_use]
    pub fn text(&self, row: usize, col: usize) -> &str {
        self.rows
            .get(row)
            .and_then(|r| r.get(col))
            .map_or("", String::as_str)
    }

    /// A cell as `f64`.
    ///
    /// # Errors
    /// The cell is empty or not a number.
    pub fn f64(&self, row: usize, col: usize) -> anyhow::Result<f64> {
        let t = self.text(row, col);
        t.parse::<f64>().map_err(|e| {
            anyhow!(
                "{}: row {row}, column {:?}: {t:?} is not a number ({e})",
                self.source,
                self.columns.get(col).map_or("?", String::as_str)
            )
        })
    }

    /// Three columns `<prefix>x`, `<prefix>y`, `<prefix>z` (or with `_kms` suffixes) as a vector.
    ///
    /// # Errors
    /// Missing columns or bad cells.
    pub fn vec3(&self, row: usize, names: [&str; 3]) -> anyhow::Result<nalgebra::Vector3<f64>> {
        Ok(nalgebra::Vector3::new(
            self.f64(row, self.column(names[0])?)?,
            self.f64(row, self.column(names[1])?)?,
            self.f64(row, self.column(names[2])?)?,
        ))
    }

    /// [`CsvTable::vec3`] of the columns `pattern` names with `{}` as `x`, `y` and `z`
    /// (`"B_{}_gcrs_nT"`: `B_x_gcrs_nT`, `B_y_gcrs_nT`, `B_z_gcrs_nT`).
    ///
    /// # Errors
    /// Missing columns or bad cells.
    pub fn xyz(&self, row: usize, pattern: &str) -> anyhow::Result<nalgebra::Vector3<f64>> {
        let [x, y, z] = ["x", "y", "z"].map(|axis| pattern.replace("{}", axis));
        self.vec3(row, [&x, &y, &z])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_comments_header_rows_and_reports_bad_cells() {
        let t = CsvTable::parse("# c\n#x\na,b\n1,2.5\n3,x\n", "t").unwrap();
        assert_eq!(t.len(), 2);
        let b = t.column("b").unwrap();
        assert_eq!(t.f64(0, b).unwrap(), 2.5);
        let err = t.f64(1, b).unwrap_err().to_string();
        assert!(err.contains("row 1") && err.contains("\"b\""), "{err}");
        assert!(CsvTable::parse("a,b\n1\n", "t").is_err());
        assert!(t.column("zz").is_err());
    }
}
