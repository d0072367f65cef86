//! Result CSVs as typed rows: every CSV a run writes (results and cache entries) is a list of
//! one serde struct, written by `to_csv` and read back by `from_csv`. A row's columns are its
//! fields in order; an array field spreads over as many columns (named by `CsvRow::header`).
//! How a number is written is part of the row type (`num`), so that a file reads the same
//! whatever wrote it.

use serde::de::{self, DeserializeOwned, Visitor};
use serde::Serialize;

/// One line of a result CSV.
pub trait CsvRow: Serialize + DeserializeOwned {
    /// Whether text cells are always quoted (numbers never are); otherwise only where a cell
    /// needs it.
    const QUOTE_TEXT: bool = false;

    /// The column names in field order. The default is the field names, which is right for
    /// rows without array fields; rows with array fields name each of their columns.
    fn header() -> Vec<String> {
        field_names::<Self>()
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RowsError {
    #[error("{name}: the header is `{found}`, expected `{expected}`")]
    Header {
        name: String,
        found: String,
        expected: String,
    },
    #[error("{name}:{line}: {message}")]
    Line {
        name: String,
        line: u64,
        message: String,
    },
}

/// The rows as CSV text: the header, then one line per row.
pub fn to_csv<R: CsvRow>(rows: &[R]) -> String {
    let mut out = R::header().join(",");
    out.push('\n');
    let mut writer = csv::WriterBuilder::new()
        .has_headers(false)
        .quote_style(if R::QUOTE_TEXT {
            csv::QuoteStyle::NonNumeric
        } else {
            csv::QuoteStyle::Necessary
        })
        .from_writer(Vec::new());
    for row in rows {
        // Rows are structs of numbers, names and arrays of numbers: writing them into memory
        // cannot fail.
        writer.serialize(row).expect("a row serializes");
    }
    let bytes = writer.into_inner().expect("writing into memory");
    out.push_str(std::str::from_utf8(&bytes).expect("rows write UTF-8"));
    out
}

/// Reads rows written by `to_csv`; `name` (the file) and the line are in every error.
pub fn from_csv<R: CsvRow>(text: &str, name: &str) -> Result<Vec<R>, RowsError> {
    let expected = R::header().join(",");
    let (found, body) = text.split_once('\n').unwrap_or((text, ""));
    if found.trim_end_matches('\r') != expected {
        return Err(RowsError::Header {
            name: name.to_string(),
            found: found.chars().take(200).collect(),
            expected: expected.chars().take(200).collect(),
        });
    }
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .from_reader(body.as_bytes());
    reader
        .deserialize::<R>()
        .map(|row| {
            row.map_err(|e| {
                let line = e.position().map_or(0, |p| p.line()) + 1;
                let message = match e.into_kind() {
                    csv::ErrorKind::Deserialize { err, .. } => err.to_string(),
                    csv::ErrorKind::UnequalLengths {
                        expected_len, len, ..
                    } => format!("{len} cells, expected {expected_len}"),
                    kind => format!("{kind:?}"),
                };
                RowsError::Line {
                    name: name.to_string(),
                    line,
                    message,
                }
            })
        })
        .collect()
}

/// The header of a row of the face's numbers: `head`, then `AU01..AU45`, then the 56 control
/// names (the order of `[f64; AU_COUNT]` and `[f64; CONTROL_COUNT]` fields).
pub fn wide(head: &[&str]) -> Vec<String> {
    let head = head
        .iter()
        .chain(&crate::observe::AU_NAMES)
        .map(|s| s.to_string());
    head.chain(crate::sim::controls::control_names().iter().cloned())
        .collect()
}

/// The field names of a struct, as serde sees them: a deserializer that only listens to the
/// names `deserialize_struct` is given.
pub fn field_names<T: DeserializeOwned>() -> Vec<String> {
    struct Names(Vec<String>);
    #[derive(Debug)]
    struct Stop;
    impl std::fmt::Display for Stop {
        fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("field names read")
        }
    }
    impl std::error::Error for Stop {}
    impl de::Error for Stop {
        fn custom<M: std::fmt::Display>(_: M) -> Self {
            Stop
        }
    }
    impl<'de> de::Deserializer<'de> for &mut Names {
        type Error = Stop;
        fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Stop> {
            Err(Stop)
        }
        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _: &'static str,
            fields: &'static [&'static str],
            _: V,
        ) -> Result<V::Value, Stop> {
            self.0 = fields.iter().map(|f| f.to_string()).collect();
            Err(Stop)
        }
        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes
            byte_buf option unit unit_struct newtype_struct seq tuple tuple_struct map enum
            identifier ignored_any
        }
    }
    let mut names = Names(Vec::new());
    let _ = T::deserialize(&mut names);
    names.0
}

/// How numbers are written (`#[serde(serialize_with = "num::...")]`); any of them reads back
/// as a plain float.
pub mod num {
    use serde::ser::SerializeTuple;
    use serde::Serializer;

    /// Rust's shortest form that reads back to the same bits, never in exponent notation.
    pub fn shortest<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(v)
    }

    /// Each element of a list, one cell each, as `text` writes it.
    fn each<S: Serializer>(
        v: &[f64],
        s: S,
        text: impl Fn(f64) -> String,
    ) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(v.len())?;
        for &x in v {
            t.serialize_element(&text(x))?;
        }
        t.end()
    }

    /// A number as `text` writes it, or an empty cell for none.
    fn or_empty<S: Serializer>(
        v: &Option<f64>,
        s: S,
        text: impl Fn(f64) -> String,
    ) -> Result<S::Ok, S::Error> {
        match v {
            Some(v) => s.serialize_str(&text(*v)),
            None => s.serialize_none(),
        }
    }

    /// `shortest` for each element of an array.
    pub fn shortest_all<S: Serializer, const N: usize>(
        v: &[f64; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        each(v, s, |x| x.to_string())
    }

    /// `shortest` for each element of an array, read back as an array of any length
    /// (`#[serde(with = "num::all")]`; serde's own arrays stop at 32).
    pub mod all {
        pub use super::shortest_all as serialize;
        use serde::de::{self, Deserializer, SeqAccess, Visitor};

        pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
            d: D,
        ) -> Result<[f64; N], D::Error> {
            struct Numbers<const N: usize>;
            impl<'de, const N: usize> Visitor<'de> for Numbers<N> {
                type Value = [f64; N];
                fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                    write!(f, "{N} numbers")
                }
                fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[f64; N], A::Error> {
                    let mut out = [0.0; N];
                    for (i, x) in out.iter_mut().enumerate() {
                        *x = seq
                            .next_element()?
                            .ok_or_else(|| de::Error::invalid_length(i, &self))?;
                    }
                    Ok(out)
                }
            }
            d.deserialize_tuple(N, Numbers::<N>)
        }
    }

    /// `D` digits after the point.
    pub fn fixed<const D: usize, S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&format_args!("{v:.D$}"))
    }

    /// `fixed`, or an empty cell for none.
    pub fn fixed_or_empty<const D: usize, S: Serializer>(
        v: &Option<f64>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        or_empty(v, s, |x| format!("{x:.D$}"))
    }

    /// `sci`, or an empty cell for none.
    pub fn sci_or_empty<const D: usize, S: Serializer>(
        v: &Option<f64>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        or_empty(v, s, |x| format!("{x:.D$e}"))
    }

    /// `fixed` for each element of a list.
    pub fn fixed_each<const D: usize, S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        each(v, s, |x| format!("{x:.D$}"))
    }

    /// Exponent notation with `D` digits after the point.
    pub fn sci<const D: usize, S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&format_args!("{v:.D$e}"))
    }

    /// `sci` for each element of a list.
    pub fn sci_each<const D: usize, S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        each(v, s, |x| format!("{x:.D$e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(rename_all = "snake_case")]
    enum Kind {
        Images,
        OnsetVideos,
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Simple {
        kind: Kind,
        frames: usize,
        #[serde(serialize_with = "num::sci::<3, _>")]
        mse: f64,
    }
    impl CsvRow for Simple {}

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Wide {
        name: String,
        #[serde(serialize_with = "num::shortest_all")]
        values: [f64; 3],
    }
    impl CsvRow for Wide {
        fn header() -> Vec<String> {
            ["name", "a", "b", "c"].map(String::from).into()
        }
    }

    #[test]
    fn rows_write_their_fields_and_read_back() {
        assert_eq!(Simple::header(), ["kind", "frames", "mse"]);
        let rows = vec![Simple {
            kind: Kind::OnsetVideos,
            frames: 12,
            mse: 0.001_234_5,
        }];
        let text = to_csv(&rows);
        assert_eq!(text, "kind,frames,mse\nonset_videos,12,1.234e-3\n");
        let back: Vec<Simple> = from_csv(&text, "s.csv").unwrap();
        assert_eq!(back[0].mse, 0.001234);

        let wide = vec![Wide {
            name: "x".into(),
            values: [1.0, 1e-7, 0.1 + 0.2],
        }];
        let text = to_csv(&wide);
        assert_eq!(text, "name,a,b,c\nx,1,0.0000001,0.30000000000000004\n");
        assert_eq!(from_csv::<Wide>(&text, "w.csv").unwrap(), wide);
    }

    #[test]
    fn bad_files_name_the_file_and_line() {
        let err = from_csv::<Simple>("kind,frame,mse\n", "s.csv").unwrap_err();
        assert!(err
            .to_string()
            .starts_with("s.csv: the header is `kind,frame,mse`"));
        let text = "kind,frames,mse\nimages,1,0.5\nimages,x,0.5\n";
        let err = from_csv::<Simple>(text, "s.csv").unwrap_err().to_string();
        assert!(err.starts_with("s.csv:3: "), "{err}");
        let err = from_csv::<Simple>("kind,frames,mse\nimages,1\n", "s.csv")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("s.csv:2: "), "{err}");
        let err = from_csv::<Simple>("kind,frames,mse\nvideos,1,2\n", "s.csv")
            .unwrap_err()
            .to_string();
        assert!(err.contains("s.csv:2") && err.contains("videos"), "{err}");
    }
}
