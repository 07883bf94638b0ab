//! A run's CSV tables (`metrics.csv`, `eval.csv`) read by column name: the readers behind
//! `vge plot`, model selection, scoring and shipping.

use std::path::Path;

use super::RunFileError;

/// A run's CSV table or JSON record (the larger bound of the two).
fn read(path: &Path) -> Result<String, RunFileError> {
    crate::read_limits::read_to_string_bounded(path, crate::read_limits::MAX_TABLE_FILE_LEN)
        .map_err(|source| RunFileError::Io { path: path.to_owned(), source })
}

/// Columns of a CSV with a header row, by name; a name the header lacks is an error naming
/// it. An empty field (a metrics window in which no episode ended, or before the first
/// update) is NaN: nothing was measured there, and curves leave it out
/// (the plots' curves).
pub fn csv_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<f64>>, RunFileError> {
    let columns = columns_by_name(path, names)?;
    names
        .iter()
        .zip(columns)
        .map(|(n, c)| {
            c.ok_or_else(|| RunFileError::Format {
                path: path.to_owned(),
                message: format!("no column `{n}`"),
            })
        })
        .collect()
}

/// [`csv_columns`], or None when the file or one of the columns is missing (a run from
/// before the column existed, or without periodic evaluations).
pub fn csv_columns_if_present(path: &Path, names: &[&str]) -> Result<Option<Vec<Vec<f64>>>, RunFileError> {
    if !path.exists() {
        return Ok(None);
    }
    Ok(columns_by_name(path, names)?.into_iter().collect())
}

/// Each of `names`' column, None where the header lacks it. A last line without its newline
/// is a row still being written (or cut short by a kill, which a resume drops too) and is
/// not read; a complete row without a field of a named column is an error naming the row.
fn columns_by_name(path: &Path, names: &[&str]) -> Result<Vec<Option<Vec<f64>>>, RunFileError> {
    let bad = |message: String| RunFileError::Format { path: path.to_owned(), message };
    let text = read(path)?;
    let complete = text.rfind('\n').map_or("", |end| &text[..=end]);
    let mut reader =
        csv::ReaderBuilder::new().flexible(true).trim(csv::Trim::All).from_reader(complete.as_bytes());
    let header = reader.headers().map_err(|e| bad(e.to_string()))?.clone();
    let index: Vec<Option<usize>> = names.iter().map(|n| header.iter().position(|h| h == *n)).collect();
    let mut columns: Vec<Option<Vec<f64>>> = index.iter().map(|i| i.map(|_| Vec::new())).collect();
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| bad(e.to_string()))?;
        if record.iter().all(str::is_empty) {
            continue;
        }
        for (col, i) in index.iter().enumerate() {
            let (Some(i), Some(values)) = (i, columns[col].as_mut()) else { continue };
            let field = record.get(*i).ok_or_else(|| {
                bad(format!(
                    "row {} has {} fields, the header {}: no `{}`",
                    row + 2,
                    record.len(),
                    header.len(),
                    names[col]
                ))
            })?;
            let value = if field.is_empty() {
                f64::NAN
            } else {
                field.parse::<f64>().map_err(|_| {
                    bad(format!("row {}: column `{}` is `{field}`, not a number", row + 2, names[col]))
                })?
            };
            values.push(value);
        }
    }
    Ok(columns)
}

/// A CSV's step column as whole env steps: a negative, fractional or non-finite step is
/// refused, naming its row, rather than cast to another step.
pub fn whole_steps(path: &Path, steps: &[f64]) -> Result<Vec<u64>, RunFileError> {
    // Below 2^53 every whole f64 is exact, and no run takes that many steps.
    const EXACT: f64 = 9_007_199_254_740_992.0;
    steps
        .iter()
        .enumerate()
        .map(|(i, &step)| {
            if step.is_finite() && (0.0..=EXACT).contains(&step) && step.fract() == 0.0 {
                Ok(step as u64)
            } else {
                Err(RunFileError::Format {
                    path: path.to_owned(),
                    message: format!("row {}: step `{step}` is not a whole number of env steps", i + 2),
                })
            }
        })
        .collect()
}

/// A curve's steps and values.
pub type StepsAndValues = (Vec<f64>, Vec<f64>);

/// `(step, success)` of a CSV's `column`; `None` when the file or the column is missing (a
/// run from before the per-object columns, or without periodic evaluations).
pub fn object_success(path: &Path, column: &str) -> Result<Option<StepsAndValues>, RunFileError> {
    let Some(columns) = csv_columns_if_present(path, &["step", column])? else { return Ok(None) };
    let [step, success]: [Vec<f64>; 2] = columns
        .try_into()
        .map_err(|_| RunFileError::Format { path: path.to_owned(), message: "columns".into() })?;
    Ok(Some((step, success)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_must_be_whole_env_steps() {
        let path = Path::new("eval.csv");
        assert_eq!(whole_steps(path, &[0.0, 250_000.0, 2e6]).expect("whole"), [0, 250_000, 2_000_000]);
        for (step, row) in [(-5.0, 3), (12.7, 3), (f64::NAN, 3), (f64::INFINITY, 3), (1e30, 3)] {
            let err = whole_steps(path, &[100.0, step]).expect_err("refused").to_string();
            assert!(err.contains(&format!("row {row}: step `{step}` is not a whole number")), "{err}");
        }
    }

    #[test]
    fn a_row_being_written_is_not_read_and_a_short_complete_row_is_refused_naming_it() {
        let dir = std::env::temp_dir().join(format!("vge-run-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let csv = dir.join("eval.csv");
        // The last row has no newline yet: the writer is still at it.
        std::fs::write(&csv, "step,success,return\n100,0.5,3\n200,,4\n300,0.").expect("write");
        let columns = csv_columns(&csv, &["step", "success"]).expect("reads the complete rows");
        assert_eq!(columns[0], vec![100.0, 200.0]);
        assert!(columns[1][0] == 0.5 && columns[1][1].is_nan(), "an empty field is NaN: {columns:?}");
        assert_eq!(csv_columns_if_present(&csv, &["step", "mean_q"]).expect("reads"), None);
        assert_eq!(csv_columns_if_present(&dir.join("absent.csv"), &["step"]).expect("no file"), None);
        let err = csv_columns(&csv, &["step", "mean_q"]).expect_err("no such column").to_string();
        assert!(err.contains("no column `mean_q`"), "{err}");
        std::fs::write(&csv, "step,success,return\n100,0.5,3\n200,0.7\n").expect("write");
        let err = csv_columns(&csv, &["return"]).expect_err("a short row").to_string();
        assert!(err.contains("row 3 has 2 fields, the header 3: no `return`"), "{err}");
        assert_eq!(csv_columns(&csv, &["success"]).expect("the fields it has"), vec![vec![0.5, 0.7]]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
