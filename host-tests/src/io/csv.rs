//! Measured-style records: CSV files with a header row naming the columns.
//!
//! ```text
//! # any line starting with '#' is a comment (anywhere in the file)
//! t,u,y,r
//! 0.00000,0.0,0.0012,0.0
//! 0.00002,1.0,0.0009,1.0
//! ```
//! * `t`: time, seconds; strictly increasing and **uniformly sampled** at any rate. An
//!   interval may differ from the mean interval by up to [`TIME_JITTER_MAX`] (20 %) of it:
//!   time stamps rounded to `f32` or to a few printed digits, or taken from a jittery clock,
//!   while the converters run on a steady one. Beyond 0.1 % (plus 1 ns) the times are replaced
//!   by the uniform grid `t0 + i T` at the mean interval and [`Record::original_jitter`] says
//!   by how much they differed (the verbs print a note); beyond 20 % (a gap, a change of rate)
//!   the record is refused;
//! * `u`: volts at the amplifier's control input (required);
//! * `y`: sensor monitor volts (required by [`Record::require_y`], optional for inputs);
//! * `r`: reference volts (optional); any other column is ignored.
//!
//! A file whose first row (after comments) is numbers and empty fields has no header: its
//! columns are named by their 1-based numbers ([`Record::parse_named`] with `["1", "2",
//! "3"]`, `piezo gap --vars t=1,u=2,y=3`), and names are refused with the numbers to use.
//! Under a header a number names a column where no column has that name; a header of the
//! integers from 0 in order, after an empty name or not (`,0,1,2` or `0,1,2`, a data frame's
//! unnamed columns), is a header of those labels, and a number under it is a label.
//!
//! Columns are separated by commas (or, when the header has no comma, by semicolons or tabs,
//! as spreadsheets in decimal-comma locales export them; a decimal comma is then read as a
//! point), surrounding spaces and double quotes are trimmed (a separator inside quotes is the
//! field's; under commas a quoted `"1,234"` is refused, as a thousands separator or a
//! decimal comma it cannot tell), blank lines are skipped,
//! a UTF-8 byte-order mark at the start is ignored. Every failure is a [`RecordError`] naming
//! where (the line of a CSV file, the element of a column handed to [`Record::new`], e.g. from
//! a `.mat` file) and the problem: a missing column, a field that is not a number, NaN or
//! infinite values, a value beyond [`MAX_ABS_V`], a row with the wrong number of fields, an
//! empty file, a single sample, non-increasing or non-uniform time, a sampling rate outside
//! [`MIN_RATE_HZ`]..[`MAX_RATE_HZ`]. Nothing here panics on any input (fuzzed in
//! `tests/records.rs` and `tests/robustness.rs`).
//!
//! The bounds keep every value that reaches model-core (in `f32`) far inside its range, and
//! every run's length in stage steps a number the verbs can bound before they start
//! ([`crate::io::checks`]).

use std::fmt::Write as _;
use std::path::Path;

/// Largest magnitude of a sample value (`u`, `y`, `r`), volts: the board's signals are within
/// +-20 V; this leaves room for other scalings while keeping model-core's `f32` maths finite.
pub const MAX_ABS_V: f64 = 1e6;
/// Lowest sampling rate of a record, Hz (one sample every 1000 s).
pub const MIN_RATE_HZ: f64 = 1e-3;
/// Highest sampling rate of a record, Hz (10 MHz, 50 times the fastest loop rate).
pub const MAX_RATE_HZ: f64 = 1e7;
/// Largest magnitude of a sample time, seconds (about 30 000 years).
pub const MAX_ABS_T_S: f64 = 1e12;

/// Where in its source a sample is: a CSV line, or the element of a column (a `.mat`
/// variable, or columns handed to [`Record::new`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum At {
    /// 1-based line of a CSV file.
    Line(usize),
    /// 1-based element of a column.
    Element(usize),
}

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Line(n) => write!(f, "line {n}"),
            Self::Element(n) => write!(f, "element {n}"),
        }
    }
}

/// Largest deviation of a sampling interval from the mean interval, as a fraction of it,
/// taken as time-stamp rounding or jitter of a uniformly clocked acquisition (our assumption:
/// `f32` time stamps round a 50 kHz record's intervals by up to 5 % of them); larger is a gap
/// or a non-uniform record.
pub const TIME_JITTER_MAX: f64 = 0.2;

/// Deviations up to this fraction of the mean interval (plus 1 ns) count as exact uniform
/// sampling: the times are kept as given.
pub const TIME_EXACT: f64 = 1e-3;

/// A uniformly sampled record.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// Sample times, seconds (uniform: see [`Record::time_jitter`]).
    pub t_s: Vec<f64>,
    /// Amplifier control input, volts.
    pub u_v: Vec<f64>,
    /// Sensor monitor, volts, when the file has a `y` column.
    pub y_v: Option<Vec<f64>>,
    /// Reference, volts, when the file has an `r` column.
    pub r_v: Option<Vec<f64>>,
    /// The jitter of the given times ([`Record::time_jitter`] before they were made uniform),
    /// when they were not uniform to [`TIME_EXACT`].
    pub original_jitter: Option<f64>,
}

/// Why a record was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RecordError {
    /// The file could not be read.
    #[error("cannot read {path}: {msg}")]
    Io {
        /// The path.
        path: String,
        /// The system's message.
        msg: String,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {msg}")]
    Write {
        /// The path.
        path: String,
        /// The system's message.
        msg: String,
    },
    /// The file is not UTF-8 text.
    #[error("line {line}: not UTF-8 text")]
    NotText {
        /// 1-based line.
        line: usize,
    },
    /// No header row.
    #[error("empty record: no header row (expected a line naming the columns, e.g. `t,u,y`)")]
    Empty,
    /// The first row holds numbers: a record without a header, whose columns were named, not
    /// numbered.
    #[error(
        "line {line}: the first row holds numbers, not column names: a record without a header \
         names its columns by number, 1 to {columns} (`piezo gap --vars t=1,u=2,y=3`)"
    )]
    NoHeader {
        /// 1-based line of the first row.
        line: usize,
        /// Fields in it.
        columns: usize,
    },
    /// A required column is missing from the header.
    #[error("line {line}: header has no column `{column}` (found: {found})")]
    MissingColumn {
        /// 1-based line of the header.
        line: usize,
        /// The missing column.
        column: String,
        /// The columns found.
        found: String,
    },
    /// A column name appears twice.
    #[error("line {line}: column `{column}` appears twice in the header")]
    DuplicateColumn {
        /// 1-based line of the header.
        line: usize,
        /// The column.
        column: String,
    },
    /// A row has a different number of fields than the header.
    #[error("line {line}: {found} fields, but the header names {expected} columns")]
    FieldCount {
        /// 1-based line.
        line: usize,
        /// Fields found.
        found: usize,
        /// Columns in the header.
        expected: usize,
    },
    /// A field is not a number.
    #[error("line {line}: column `{column}`: `{text}` is not a number")]
    NotANumber {
        /// 1-based line.
        line: usize,
        /// The column.
        column: String,
        /// The field (truncated to 40 characters).
        text: String,
    },
    /// A field is NaN or infinite.
    #[error("{at}: column `{column}` is {text} (samples must be finite)")]
    NotFinite {
        /// Where.
        at: At,
        /// The column.
        column: String,
        /// The field.
        text: String,
    },
    /// A value beyond [`MAX_ABS_V`] (or a time beyond [`MAX_ABS_T_S`]).
    #[error(
        "{at}: column `{column}` is {value:e}, beyond +-{limit:e} (the largest magnitude a record may hold)"
    )]
    TooLarge {
        /// Where.
        at: At,
        /// The column.
        column: String,
        /// The value.
        value: f64,
        /// The bound.
        limit: f64,
    },
    /// The sampling rate is outside [`MIN_RATE_HZ`]..[`MAX_RATE_HZ`].
    #[error(
        "sampling rate {rate_hz:e} Hz (interval {period_s:e} s) is outside {min:e}..{max:e} Hz"
    )]
    Rate {
        /// The record's rate.
        rate_hz: f64,
        /// Its mean interval.
        period_s: f64,
        /// Lowest rate accepted.
        min: f64,
        /// Highest rate accepted.
        max: f64,
    },
    /// Fewer than two samples.
    #[error("record has {0} sample(s): at least 2 are needed to know the sampling rate")]
    TooShort(usize),
    /// Time does not increase.
    #[error("{at}: time {t} s does not increase (previous sample {prev} s)")]
    NotIncreasing {
        /// Where.
        at: At,
        /// This time.
        t: f64,
        /// The previous time.
        prev: f64,
    },
    /// Non-uniform sampling.
    #[error(
        "{at}: sampling interval {dt} s differs from the mean interval {mean} s (records must be uniformly sampled)"
    )]
    NonUniform {
        /// Where.
        at: At,
        /// This interval.
        dt: f64,
        /// The mean interval.
        mean: f64,
    },
    /// A column the caller needs is absent.
    #[error("record has no `{0}` column")]
    NeedColumn(&'static str),
    /// Columns of different lengths handed to the writer.
    #[error("columns have different lengths: t {t}, {column} {len}")]
    Mismatched {
        /// Length of `t`.
        t: usize,
        /// The other column.
        column: &'static str,
        /// Its length.
        len: usize,
    },
}

/// Is every field of a row a number under `sep`, or empty (an index column without a name)?
fn numeric_row(fields: &[&str], sep: char) -> bool {
    fields
        .iter()
        .all(|f| f.trim().is_empty() || number_of(f, sep).is_some())
}

/// A header of column labels that are numbers, as a data frame whose columns were never
/// named writes it: the integers from 0 in order (`0,1,2`), or an empty index column's name
/// and then the integers from 0 or 1 (`,0,1,2`). Read as a header, as such files were before
/// records without one were (a first row of samples that reads so is taken for labels).
fn numbered_labels(fields: &[&str]) -> bool {
    let labels: Vec<&str> = fields.iter().map(|f| f.trim()).collect();
    let (rest, starts): (&[&str], &[usize]) = match labels.split_first() {
        Some((&"", rest)) => (rest, &[0, 1]),
        _ => (&labels, &[0]),
    };
    rest.len() >= 2
        && starts.iter().any(|&from| {
            rest.iter()
                .enumerate()
                .all(|(i, l)| l.parse::<usize>() == Ok(from + i))
        })
}

/// A column named by its 1-based number (`3`), as the 0-based index.
fn column_number(name: &str) -> Option<usize> {
    name.trim()
        .parse::<usize>()
        .ok()
        .filter(|&i| i >= 1)
        .map(|i| i - 1)
}

fn truncate(s: &str) -> String {
    s.chars().take(40).collect()
}

/// Every value of a column finite and within its bound ([`MAX_ABS_T_S`] for `t`, else
/// [`MAX_ABS_V`]); `at` turns an index into the place to name.
fn check_values(v: &[f64], column: &str, at: fn(usize) -> At) -> Result<(), RecordError> {
    let limit = if column == "t" {
        MAX_ABS_T_S
    } else {
        MAX_ABS_V
    };
    for (i, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            return Err(RecordError::NotFinite {
                at: at(i + 1),
                column: column.into(),
                text: x.to_string(),
            });
        }
        if x.abs() > limit {
            return Err(RecordError::TooLarge {
                at: at(i + 1),
                column: column.into(),
                value: x,
                limit,
            });
        }
    }
    Ok(())
}

/// The field separator a header line uses: `,` if it has one, else `;` or a tab if it has
/// one, else a space (any run of blanks: a `.txt` or `.dat` column file as MATLAB's
/// `writematrix` or a logger writes it) if it has one, else `,`. Text inside double quotes
/// does not count (`"Zeit, s";"U";"Y"` is separated by semicolons).
pub fn separator(header: &str) -> char {
    let mut quoted = false;
    let bare: String = header
        .chars()
        .filter(|&c| {
            if c == '"' {
                quoted = !quoted;
            }
            !quoted && c != '"'
        })
        .collect();
    if bare.contains(',') {
        ','
    } else if bare.contains(';') {
        ';'
    } else if bare.contains('\t') {
        '\t'
    } else if bare.contains(' ') {
        ' '
    } else {
        ','
    }
}

/// A line's fields under separator `sep` (a space: any run of blanks), trimmed, each without
/// the double quotes around it (`"0.5"`, as spreadsheets and data frames write every field
/// when asked to quote): a separator inside quotes belongs to the field.
fn fields_of(s: &str, sep: char) -> Vec<&str> {
    if sep == ' ' {
        return s.split_whitespace().map(unquote).collect();
    }
    let mut out = Vec::new();
    let mut start = 0;
    let mut quoted = false;
    for (i, c) in s.char_indices() {
        if c == '"' {
            quoted = !quoted;
        } else if c == sep && !quoted {
            out.push(unquote(s.get(start..i).unwrap_or("")));
            start = i + c.len_utf8();
        }
    }
    out.push(unquote(s.get(start..).unwrap_or("")));
    out
}

/// A field trimmed, and without the double quotes around it if it has them.
fn unquote(f: &str) -> &str {
    let f = f.trim();
    f.strip_prefix('"')
        .and_then(|g| g.strip_suffix('"'))
        .map_or(f, str::trim)
}

/// A units row's field: text with a letter in it that is no number and no missing value's
/// mark (`s`, `V`, `[V]`, `(um)`; not `NA`, `NaN`, `null`).
fn is_unit(f: &str) -> bool {
    let bare = f
        .trim_matches(|c: char| "\"'[]()".contains(c))
        .to_ascii_lowercase();
    bare.chars().any(|c| c.is_alphabetic())
        && bare.parse::<f64>().is_err()
        && !["na", "nan", "null", "none", "n/a", "inf"].contains(&bare.as_str())
}

/// A field as a number: a decimal comma is read as a point where the separator is not a
/// comma. Under commas a comma inside a quoted field is not read: `"1,234"` may be a
/// thousands separator as well as a decimal comma, and is refused rather than guessed.
fn number_of(text: &str, sep: char) -> Option<f64> {
    if sep != ',' && text.contains(',') {
        text.replacen(',', ".", 1).parse().ok()
    } else {
        text.parse().ok()
    }
}

impl Record {
    /// A record from columns; checks lengths, values (finite, within [`MAX_ABS_V`]), uniform
    /// sampling and the rate. Errors name the element (1-based) of the column.
    pub fn new(
        t_s: Vec<f64>,
        u_v: Vec<f64>,
        y_v: Option<Vec<f64>>,
        r_v: Option<Vec<f64>>,
    ) -> Result<Self, RecordError> {
        let n = t_s.len();
        let check = |v: &[f64], column: &'static str| {
            if v.len() != n {
                Err(RecordError::Mismatched {
                    t: n,
                    column,
                    len: v.len(),
                })
            } else {
                check_values(v, column, At::Element)
            }
        };
        check(&t_s, "t")?;
        check(&u_v, "u")?;
        if let Some(y) = &y_v {
            check(y, "y")?;
        }
        if let Some(r) = &r_v {
            check(r, "r")?;
        }
        let mut rec = Self {
            t_s,
            u_v,
            y_v,
            r_v,
            original_jitter: None,
        };
        rec.settle_time(&|i| At::Element(i + 1))?;
        Ok(rec)
    }

    /// Largest deviation of a sampling interval from the mean interval, as a fraction of it;
    /// above [`TIME_EXACT`] the times were replaced by the uniform grid at the mean interval
    /// when the record was made.
    pub fn time_jitter(&self) -> f64 {
        let t = &self.t_s;
        let n = t.len();
        if n < 2 {
            return 0.0;
        }
        let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
        t.windows(2)
            .map(|w| ((w[1] - w[0]) - mean).abs() / mean)
            .fold(0.0, f64::max)
    }

    /// A one-line note when the file's times were not uniform to [`TIME_EXACT`] (`None` if
    /// they were): how much they jittered and the rate the record is taken at.
    pub fn time_note(&self, name: &str) -> Option<String> {
        let j = self.original_jitter?;
        Some(format!(
            "note: {name}: sampling intervals differ from their mean by up to {:.2} % (time stamps rounded or jittery); taken as uniform at {:.6} Hz",
            100.0 * j,
            self.rate_hz()
        ))
    }

    /// Times within [`TIME_JITTER_MAX`] but not [`TIME_EXACT`] of uniform: replaced by the
    /// uniform grid `t0 + i T` fitted to all of them by least squares (rounding errors average
    /// out; the end points alone would carry theirs into the rate).
    fn retime(&mut self) {
        let n = self.t_s.len();
        let j = self.time_jitter();
        let mean = (self.t_s[n - 1] - self.t_s[0]) / (n - 1) as f64;
        if j * mean <= TIME_EXACT * mean + 1e-9 {
            return;
        }
        let i_mean = (n - 1) as f64 / 2.0;
        let t_mean = self.t_s.iter().sum::<f64>() / n as f64;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for (i, t) in self.t_s.iter().enumerate() {
            let di = i as f64 - i_mean;
            sxy += di * (t - t_mean);
            sxx += di * di;
        }
        let period = sxy / sxx;
        let t0 = t_mean - period * i_mean;
        for (i, t) in self.t_s.iter_mut().enumerate() {
            *t = t0 + i as f64 * period;
        }
        self.original_jitter = Some(j);
    }

    /// The times checked ([`Self::check_time`]) and, if rounded or jittery, made uniform
    /// ([`Self::retime`]): the last step of making a record, from columns or from a file.
    fn settle_time(&mut self, at: &dyn Fn(usize) -> At) -> Result<(), RecordError> {
        self.check_time(at)?;
        self.retime();
        Ok(())
    }

    fn check_time(&self, at: &dyn Fn(usize) -> At) -> Result<(), RecordError> {
        let t = &self.t_s;
        let n = t.len();
        if n < 2 {
            return Err(RecordError::TooShort(n));
        }
        let line = at;
        for i in 1..n {
            if t[i] <= t[i - 1] {
                return Err(RecordError::NotIncreasing {
                    at: line(i),
                    t: t[i],
                    prev: t[i - 1],
                });
            }
        }
        let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
        let tol = TIME_JITTER_MAX * mean + 1e-9;
        for i in 1..n {
            let dt = t[i] - t[i - 1];
            if (dt - mean).abs() > tol {
                return Err(RecordError::NonUniform {
                    at: line(i),
                    dt,
                    mean,
                });
            }
        }
        let rate_hz = 1.0 / mean;
        if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz) {
            return Err(RecordError::Rate {
                rate_hz,
                period_s: mean,
                min: MIN_RATE_HZ,
                max: MAX_RATE_HZ,
            });
        }
        Ok(())
    }

    /// Parse CSV text (comma-, semicolon- or tab-separated: see [`separator`]).
    pub fn parse(text: &str) -> Result<Self, RecordError> {
        Self::parse_named(text, ["t", "u", "y"])
    }

    /// [`Record::parse`] with the time, input and output columns named `names` (a lab's own
    /// header: `time_s,input_V,sensor_V`); the reference column stays `r`.
    pub fn parse_named(text: &str, names_wanted: [&str; 3]) -> Result<Self, RecordError> {
        // A byte-order mark (as some spreadsheet programs write) is not part of the header.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut header: Option<(usize, Vec<String>)> = None;
        let (mut it, mut iu, mut iy, mut ir) = (0, 0, None, None);
        let mut cols: [Vec<f64>; 4] = Default::default();
        let mut lines = Vec::new();
        // The separator, from the header: a comma, else a semicolon or a tab (as spreadsheets
        // in locales with a decimal comma export), where a decimal comma is then read as a
        // point.
        let mut sep = ',';
        let mut units_skipped = false;
        for (k, raw) in text.lines().enumerate() {
            let line = k + 1;
            let s = raw.trim();
            if s.is_empty() || s.starts_with('#') {
                continue;
            }
            if header.is_none() {
                sep = separator(s);
                // A first row of numbers with decimal commas under semicolons or tabs (a
                // record without a header from a decimal-comma locale) holds commas too: its
                // separator is the one that splits it into numbers.
                if sep == ',' && !numeric_row(&fields_of(s, ','), ',') {
                    sep = [';', '\t']
                        .into_iter()
                        .find(|&alt| s.contains(alt) && numeric_row(&fields_of(s, alt), alt))
                        .unwrap_or(',');
                }
            }
            let fields: Vec<&str> = fields_of(s, sep);
            if header.is_none() {
                // A first row of numbers (and empty fields) is data: the record has no header,
                // and its columns are named by their 1-based numbers (`--vars t=1,u=2,y=3`).
                let labels = numbered_labels(&fields);
                let headerless = fields.iter().any(|f| number_of(f, sep).is_some())
                    && numeric_row(&fields, sep)
                    && !labels;
                let names: Vec<String> = if headerless {
                    (1..=fields.len()).map(|i| i.to_string()).collect()
                } else {
                    fields
                        .iter()
                        .map(|f| f.trim_matches('"').to_string())
                        .collect()
                };
                if headerless && column_number(names_wanted[0]).is_none() {
                    return Err(RecordError::NoHeader {
                        line,
                        columns: fields.len(),
                    });
                }
                for (a, name) in names.iter().enumerate() {
                    if names[..a].contains(name) {
                        return Err(RecordError::DuplicateColumn {
                            line,
                            column: name.clone(),
                        });
                    }
                }
                let wanted = names_wanted;
                // A column by its name, or by its 1-based number where no column has that name
                // (not under numbered labels: a number there is a label, or missing).
                let find = |c: &str| {
                    names
                        .iter()
                        .position(|n| n == c)
                        .or_else(|| column_number(c).filter(|&i| i < names.len() && !labels))
                };
                let missing = |column: &str| RecordError::MissingColumn {
                    line,
                    column: column.to_string(),
                    found: truncate(&names.join(",")),
                };
                it = find(wanted[0]).ok_or_else(|| missing(wanted[0]))?;
                iu = find(wanted[1]).ok_or_else(|| missing(wanted[1]))?;
                iy = find(wanted[2]);
                ir = if headerless { None } else { find("r") };
                header = Some((line, names));
                if !headerless {
                    continue;
                }
                // (no units row under a row of numbers)
                units_skipped = true;
            }
            match &header {
                None => {}
                Some((_, names)) => {
                    // A units row under the header (`s,V,V`, as loggers and spreadsheets
                    // write one): the first row, where none of the columns read is a number.
                    let wanted = [Some(it), Some(iu), iy, ir];
                    if lines.is_empty()
                        && !units_skipped
                        && fields.len() == names.len()
                        && wanted
                            .iter()
                            .flatten()
                            .all(|&i| fields.get(i).is_some_and(|f| is_unit(f)))
                    {
                        units_skipped = true;
                        continue;
                    }
                    if fields.len() != names.len() {
                        return Err(RecordError::FieldCount {
                            line,
                            found: fields.len(),
                            expected: names.len(),
                        });
                    }
                    for (c, idx) in wanted.iter().enumerate() {
                        let Some(idx) = *idx else { continue };
                        let text = fields.get(idx).copied().unwrap_or("");
                        let column = names.get(idx).cloned().unwrap_or_default();
                        let v: f64 =
                            number_of(text, sep).ok_or_else(|| RecordError::NotANumber {
                                line,
                                column: column.clone(),
                                text: truncate(text),
                            })?;
                        if !v.is_finite() {
                            return Err(RecordError::NotFinite {
                                at: At::Line(line),
                                column,
                                text: truncate(text),
                            });
                        }
                        let limit = if c == 0 { MAX_ABS_T_S } else { MAX_ABS_V };
                        if v.abs() > limit {
                            return Err(RecordError::TooLarge {
                                at: At::Line(line),
                                column,
                                value: v,
                                limit,
                            });
                        }
                        cols[c].push(v);
                    }
                    lines.push(line);
                }
            }
        }
        if header.is_none() {
            return Err(RecordError::Empty);
        }
        let [t_s, u_v, y_v, r_v] = cols;
        let mut rec = Self {
            t_s,
            u_v,
            y_v: iy.map(|_| y_v),
            r_v: ir.map(|_| r_v),
            original_jitter: None,
        };
        rec.settle_time(&|i| At::Line(lines.get(i).copied().unwrap_or(0)))?;
        Ok(rec)
    }

    /// Parse bytes (refuses non-UTF-8 with the line it starts on).
    pub fn parse_bytes(bytes: &[u8]) -> Result<Self, RecordError> {
        Self::parse_bytes_named(bytes, ["t", "u", "y"])
    }

    /// [`Record::parse_bytes`] with the columns named `names` ([`Record::parse_named`]).
    pub fn parse_bytes_named(bytes: &[u8], names: [&str; 3]) -> Result<Self, RecordError> {
        match std::str::from_utf8(bytes) {
            Ok(s) => Self::parse_named(s, names),
            Err(e) => {
                let line = bytes[..e.valid_up_to()]
                    .iter()
                    .filter(|b| **b == b'\n')
                    .count()
                    + 1;
                Err(RecordError::NotText { line })
            }
        }
    }

    /// Read a CSV file.
    pub fn read(path: &Path) -> Result<Self, RecordError> {
        Self::read_named(path, ["t", "u", "y"])
    }

    /// Read a CSV file whose columns are named `names` ([`Record::parse_named`]).
    pub fn read_named(path: &Path, names: [&str; 3]) -> Result<Self, RecordError> {
        let bytes = std::fs::read(path).map_err(|e| RecordError::Io {
            path: path.display().to_string(),
            msg: e.to_string(),
        })?;
        Self::parse_bytes_named(&bytes, names)
    }

    /// The CSV text: header `t,u[,y][,r]`, values in Rust's shortest round-trip form.
    pub fn to_csv(&self) -> String {
        let mut s = String::with_capacity(self.t_s.len() * 48);
        s.push('t');
        s.push_str(",u");
        if self.y_v.is_some() {
            s.push_str(",y");
        }
        if self.r_v.is_some() {
            s.push_str(",r");
        }
        s.push('\n');
        for i in 0..self.t_s.len() {
            let _ = write!(s, "{},{}", self.t_s[i], self.u_v[i]);
            for col in [&self.y_v, &self.r_v].into_iter().flatten() {
                let _ = write!(s, ",{}", col.get(i).copied().unwrap_or(f64::NAN));
            }
            s.push('\n');
        }
        s
    }

    /// Write a CSV file (atomically: a temporary file renamed into place).
    pub fn write(&self, path: &Path) -> Result<(), RecordError> {
        crate::io::checks::write_bytes(path, self.to_csv().as_bytes()).map_err(|e| {
            RecordError::Write {
                path: path.display().to_string(),
                msg: e.root_cause().to_string(),
            }
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when there are no samples (never for a checked record).
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Sampling interval, seconds (mean over the record).
    pub fn period_s(&self) -> f64 {
        let n = self.t_s.len();
        if n < 2 {
            return f64::NAN;
        }
        (self.t_s[n - 1] - self.t_s[0]) / (n - 1) as f64
    }

    /// Sampling rate, Hz.
    pub fn rate_hz(&self) -> f64 {
        1.0 / self.period_s()
    }

    /// The `y` column, or an error naming it.
    pub fn require_y(&self) -> Result<&[f64], RecordError> {
        self.y_v.as_deref().ok_or(RecordError::NeedColumn("y"))
    }
}
