//! Plain-YAML numbers and fields shared by the ROS and kalibr files: writing floats that every
//! YAML 1.1 and 1.2 reader (PyYAML, yaml-cpp, this crate) reads back as the same `f64`, and
//! reading typed fields with errors that name the file and the field.

use crate::error::CalibError;
use std::path::Path;
use yaml_rust2::{Yaml, YamlLoader};

/// A float as a YAML scalar that round-trips exactly: the shortest representation that parses
/// back to the same `f64`, always with a `.` in the mantissa and a signed exponent when there
/// is one (PyYAML's YAML 1.1 resolver reads `1e-05` or `1.5e3` as strings). Non-finite values
/// must be refused before writing; they are written as `.nan` / `.inf` only as a last resort.
pub fn yaml_float(v: f64) -> String {
    if v.is_nan() {
        return ".nan".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { ".inf".into() } else { "-.inf".into() };
    }
    let a = v.abs();
    if a == 0.0 || (1e-4..1e15).contains(&a) {
        let s = format!("{v}");
        if s.contains('.') {
            s
        } else {
            format!("{s}.0")
        }
    } else {
        let s = format!("{v:e}");
        let (mant, exp) = s.split_once('e').expect("`{:e}` always has an exponent");
        let mant = if mant.contains('.') { mant.to_string() } else { format!("{mant}.0") };
        let exp = if exp.starts_with('-') { exp.to_string() } else { format!("+{exp}") };
        format!("{mant}e{exp}")
    }
}

/// A flow sequence `[a, b, c]` of floats written with [`yaml_float`].
pub fn yaml_float_seq(values: &[f64]) -> String {
    format!("[{}]", values.iter().map(|v| yaml_float(*v)).collect::<Vec<_>>().join(", "))
}

/// A double-quoted YAML string (backslashes and quotes escaped; control characters refused by
/// the callers' name checks).
pub fn yaml_string(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// Parses `text` as a single YAML document whose top level is a mapping.
pub fn load_mapping(text: &str, path: &Path) -> Result<Yaml, CalibError> {
    let docs = YamlLoader::load_from_str(text).map_err(|e| CalibError::parse(path, format!("not valid YAML: {e}")))?;
    match docs.into_iter().next() {
        Some(doc @ Yaml::Hash(_)) => Ok(doc),
        Some(_) => Err(CalibError::parse(path, "the top level is not a mapping of `key: value` fields")),
        None => Err(CalibError::parse(path, "empty file")),
    }
}

/// Typed access to the fields of one YAML mapping; `prefix` (e.g. `cam1.`) and the file name
/// appear in every error.
pub struct Fields<'a> {
    /// The mapping.
    pub node: &'a Yaml,
    /// Printed before field names, e.g. `"cam1."` (empty at the top level).
    pub prefix: String,
    /// The file, for errors.
    pub path: &'a Path,
}

/// A YAML number (integer or float) as `f64`; `None` for anything else.
pub fn as_number(v: &Yaml) -> Option<f64> {
    match v {
        Yaml::Integer(i) => Some(*i as f64),
        Yaml::Real(_) => v.as_f64(),
        _ => None,
    }
}

impl<'a> Fields<'a> {
    /// The top-level fields of a document.
    pub fn top(node: &'a Yaml, path: &'a Path) -> Self {
        Fields { node, prefix: String::new(), path }
    }

    /// An error about field `key`.
    pub fn error(&self, key: &str, msg: impl std::fmt::Display) -> CalibError {
        CalibError::parse(self.path, format!("{}{key}: {msg}", self.prefix))
    }

    /// True when the mapping has `key`.
    pub fn has(&self, key: &str) -> bool {
        !self.node[key].is_badvalue()
    }

    /// The raw value of a required field.
    pub fn get(&self, key: &str) -> Result<&'a Yaml, CalibError> {
        let v = &self.node[key];
        if v.is_badvalue() {
            Err(self.error(key, "missing"))
        } else {
            Ok(v)
        }
    }

    /// A nested mapping, as [`Fields`] with `key.` appended to the prefix.
    pub fn mapping(&self, key: &str) -> Result<Fields<'a>, CalibError> {
        let v = self.get(key)?;
        if !v.is_hash() {
            return Err(self.error(key, "expected a mapping"));
        }
        Ok(Fields { node: v, prefix: format!("{}{key}.", self.prefix), path: self.path })
    }

    /// A string field.
    pub fn string(&self, key: &str) -> Result<String, CalibError> {
        match self.get(key)? {
            Yaml::String(s) => Ok(s.clone()),
            _ => Err(self.error(key, "expected a string")),
        }
    }

    /// A finite number.
    pub fn number(&self, key: &str) -> Result<f64, CalibError> {
        let v = as_number(self.get(key)?).ok_or_else(|| self.error(key, "expected a number"))?;
        if !v.is_finite() {
            return Err(self.error(key, format!("{v} is not a finite number")));
        }
        Ok(v)
    }

    /// A positive integer that fits in `u32` (image sizes, matrix shapes).
    pub fn positive_u32(&self, key: &str) -> Result<u32, CalibError> {
        match self.get(key)? {
            Yaml::Integer(i) if *i > 0 && *i <= u32::MAX as i64 => Ok(*i as u32),
            _ => Err(self.error(key, "expected a positive integer")),
        }
    }

    /// A sequence of `n` finite numbers (`n = None`: any length).
    pub fn numbers(&self, key: &str, n: Option<usize>) -> Result<Vec<f64>, CalibError> {
        let items = self.get(key)?.as_vec().ok_or_else(|| self.error(key, "expected a sequence of numbers"))?;
        numbers_of(items, n).map_err(|m| self.error(key, m))
    }
}

/// The finite numbers of a YAML sequence, `n` of them when given; the error says what is wrong.
pub fn numbers_of(items: &[Yaml], n: Option<usize>) -> Result<Vec<f64>, String> {
    if let Some(n) = n {
        if items.len() != n {
            return Err(format!("expected {n} numbers, got {}", items.len()));
        }
    }
    items
        .iter()
        .enumerate()
        .map(|(i, v)| match as_number(v) {
            Some(x) if x.is_finite() => Ok(x),
            Some(x) => Err(format!("element {i} is {x}, not a finite number")),
            None => Err(format!("element {i} is not a number")),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_round_trip_through_the_yaml_parser() {
        for v in [0.0, -0.0, 1.0, -3.0, 0.1, 1.0 / 3.0, 1e-5, -2.5e-12, 1.7e-5, 123456.789, 1e15, 6.02e23, f64::MIN_POSITIVE, f64::MAX, 5e-324] {
            let s = yaml_float(v);
            assert!(s.contains('.'), "{s}");
            if let Some((_, e)) = s.split_once('e') {
                assert!(e.starts_with('+') || e.starts_with('-'), "{s}");
            }
            let doc = YamlLoader::load_from_str(&format!("x: {s}")).unwrap();
            assert_eq!(doc[0]["x"].as_f64().unwrap().to_bits(), v.to_bits(), "{v} -> {s}");
        }
        assert_eq!(yaml_float(2.0), "2.0");
        assert_eq!(yaml_float(1e-5), "1.0e-5");
    }
}
