//! Reading a scene's TOML table key by key: typed access to a section with errors that name
//! `section.key` and what was expected ([`Section`]), `--set` overrides, unknown keys, and the
//! isosurface list. [`super::Scene::parse`] reads every section through these.

use super::{KNOWN, MAX_COLOUR, SceneError};
use crate::view::shading::{Isosurface, MAX_ISOSURFACES};
use toml::{Table, Value};

/// A value as an error message quotes it: short and escaped (see [`crate::files::excerpt`]).
pub(super) fn describe(v: &Value) -> String {
    use crate::files::{EXCERPT_CHARS, excerpt_text};
    match v {
        Value::String(s) => format!("\"{}\"", excerpt_text(s, EXCERPT_CHARS)),
        other => excerpt_text(&other.to_string(), 2 * EXCERPT_CHARS),
    }
}

/// A bound as an error message prints it: plain, or in e-notation when very large or small.
pub(super) fn short(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) {
        x.to_string()
    } else {
        format!("{x:e}")
    }
}

/// Typed access to one section, with errors naming `section.key`.
pub(super) struct Section<'a> {
    pub(super) origin: &'a str,
    pub(super) name: &'static str,
    pub(super) table: Option<&'a Table>,
}

impl<'a> Section<'a> {
    pub(super) fn key(&self, key: &str) -> String {
        format!("{}.{key}", self.name)
    }

    pub(super) fn err(&self, key: &str, expected: &str, found: &Value) -> SceneError {
        SceneError::Key {
            origin: self.origin.to_string(),
            key: self.key(key),
            expected: expected.to_string(),
            found: describe(found),
        }
    }

    pub(super) fn get(&self, key: &str) -> Option<&'a Value> {
        self.table.and_then(|t| t.get(key))
    }

    pub(super) fn float(
        &self,
        key: &str,
        default: f64,
        lo: f64,
        hi: f64,
    ) -> Result<f64, SceneError> {
        let Some(v) = self.get(key) else {
            return Ok(default);
        };
        let x = match v {
            Value::Float(f) => *f,
            Value::Integer(i) => *i as f64,
            _ => return Err(self.err(key, "a number", v)),
        };
        if !(x.is_finite() && x >= lo && x <= hi) {
            return Err(self.err(key, &format!("a number in [{lo}, {hi}]"), v));
        }
        Ok(x)
    }

    pub(super) fn positive(&self, key: &str, default: f64, hi: f64) -> Result<f64, SceneError> {
        let x = self.float(key, default, 0.0, hi)?;
        if x <= 0.0 {
            return Err(self.err(key, &format!("a number in (0, {hi}]"), &Value::Float(x)));
        }
        Ok(x)
    }

    pub(super) fn int(&self, key: &str, default: i64, lo: i64, hi: i64) -> Result<i64, SceneError> {
        let Some(v) = self.get(key) else {
            return Ok(default);
        };
        match v {
            Value::Integer(i) if (lo..=hi).contains(i) => Ok(*i),
            _ => Err(self.err(key, &format!("an integer in [{lo}, {hi}]"), v)),
        }
    }

    /// A key that takes true, false or "auto": `None` for "auto" and for a key left out.
    pub(super) fn on_off_auto(&self, key: &str) -> Result<Option<bool>, SceneError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Boolean(b)) => Ok(Some(*b)),
            Some(Value::String(a)) if a == "auto" => Ok(None),
            Some(v) => Err(self.err(key, "true, false or \"auto\"", v)),
        }
    }

    pub(super) fn string(&self, key: &str) -> Result<Option<&'a str>, SceneError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(v) => Err(self.err(key, "a string", v)),
        }
    }

    pub(super) fn choice<T: Copy>(
        &self,
        key: &str,
        default: T,
        options: &[(&str, T)],
    ) -> Result<T, SceneError> {
        let Some(v) = self.get(key) else {
            return Ok(default);
        };
        let names: Vec<String> = options.iter().map(|(n, _)| format!("\"{n}\"")).collect();
        let expected = format!("one of {}", names.join(", "));
        match v {
            Value::String(s) => options
                .iter()
                .find(|(n, _)| n == s)
                .map(|(_, t)| *t)
                .ok_or_else(|| self.err(key, &expected, v)),
            _ => Err(self.err(key, &expected, v)),
        }
    }

    /// Three numbers, each in [lo, hi].
    pub(super) fn vec3(
        &self,
        key: &str,
        default: [f64; 3],
        lo: f64,
        hi: f64,
    ) -> Result<[f64; 3], SceneError> {
        let Some(v) = self.get(key) else {
            return Ok(default);
        };
        let expected = format!(
            "an array of 3 numbers, each in [{}, {}]",
            short(lo),
            short(hi)
        );
        let bad = || self.err(key, &expected, v);
        let Value::Array(a) = v else {
            return Err(bad());
        };
        if a.len() != 3 {
            return Err(bad());
        }
        let mut out = [0.0; 3];
        for (o, x) in out.iter_mut().zip(a) {
            *o = match x {
                Value::Float(f) if (lo..=hi).contains(f) => *f,
                Value::Integer(i) if (lo..=hi).contains(&(*i as f64)) => *i as f64,
                _ => return Err(bad()),
            };
        }
        Ok(out)
    }
}

/// Reads `[{ value, color, opacity }, …]`; the error says what was expected.
pub(super) fn parse_isosurfaces(v: &Value) -> Result<Vec<Isosurface>, String> {
    let expected = format!(
        "an array of at most {MAX_ISOSURFACES} tables {{ value = s, color = [r, g, b], opacity = a }} with |s| <= 1e30, colour in [0, 1e6] and opacity in [0, 1]"
    );
    let items = v
        .as_array()
        .filter(|a| a.len() <= MAX_ISOSURFACES)
        .ok_or(&expected)?;
    let num = |t: &Table, k: &str| match t.get(k) {
        Some(Value::Float(f)) if f.is_finite() => Some(*f),
        Some(Value::Integer(i)) => Some(*i as f64),
        _ => None,
    };
    items
        .iter()
        .enumerate()
        .map(|(i, item)| {
            let bad = || format!("{expected} (isosurface {i})");
            let t = item.as_table().ok_or_else(bad)?;
            if t.keys()
                .any(|k| !["value", "color", "opacity"].contains(&k.as_str()))
            {
                return Err(bad());
            }
            let color = match t.get("color").and_then(Value::as_array) {
                Some(a) if a.len() == 3 => {
                    let c: Vec<f64> = a
                        .iter()
                        .filter_map(|x| x.as_float().or(x.as_integer().map(|n| n as f64)))
                        .collect();
                    if c.len() != 3 || c.iter().any(|x| !(0.0..=MAX_COLOUR).contains(x)) {
                        return Err(bad());
                    }
                    [c[0], c[1], c[2]]
                }
                None if t.get("color").is_none() => [1.0, 1.0, 1.0],
                _ => return Err(bad()),
            };
            let value = num(t, "value")
                .filter(|v| v.abs() <= f64::from(crate::data::MAX_VALUE))
                .ok_or_else(bad)?;
            let opacity = match t.get("opacity") {
                None => 1.0,
                Some(_) => num(t, "opacity")
                    .filter(|o| (0.0..=1.0).contains(o))
                    .ok_or_else(bad)?,
            };
            Ok(Isosurface {
                value,
                color,
                opacity,
            })
        })
        .collect()
}

/// Parses a `--set section.key=value` argument into the table.
pub(super) fn apply_set(table: &mut Table, arg: &str) -> Result<(), SceneError> {
    let set_err = |message: String| SceneError::Set {
        arg: crate::files::excerpt_text(arg, 2 * crate::files::EXCERPT_CHARS),
        message,
    };
    // One line: TOML would read what follows a newline as more keys, and the value would
    // silently lose them.
    if arg.contains(|c: char| c.is_control()) {
        return Err(set_err(
            "expected section.key=value on one line (found a newline or another control \
             character)"
                .into(),
        ));
    }
    let (path, raw) = arg
        .split_once('=')
        .ok_or_else(|| set_err("expected section.key=value".into()))?;
    let (section, key) = path
        .trim()
        .split_once('.')
        .ok_or_else(|| set_err("expected section.key=value".into()))?;
    let value = format!("v = {raw}")
        .parse::<Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| Value::String(raw.trim().to_string()));
    let entry = table
        .entry(section.to_string())
        .or_insert_with(|| Value::Table(Table::new()));
    let Value::Table(t) = entry else {
        return Err(set_err(format!("'{section}' is not a section")));
    };
    // A new data source replaces the other kind: `--set volume.file=…` on the built-in scene
    // must not clash with its generator.
    if section.trim() == "volume" {
        match key.trim() {
            "file" => {
                t.remove("generator");
                t.remove("resolution");
            }
            "generator" => {
                t.remove("file");
                t.remove("scalars");
            }
            _ => {}
        }
    }
    t.insert(key.to_string(), value);
    Ok(())
}

pub(super) fn check_known(table: &Table, origin: &str) -> Result<(), SceneError> {
    for (section, value) in table {
        let Some((_, keys)) = KNOWN.iter().find(|(s, _)| s == section) else {
            return Err(SceneError::UnknownKey {
                origin: origin.into(),
                key: crate::files::excerpt_text(section, crate::files::EXCERPT_CHARS),
                context: " (sections)".into(),
                known: KNOWN.iter().map(|(s, _)| *s).collect::<Vec<_>>().join(", "),
            });
        };
        let Value::Table(t) = value else {
            return Err(SceneError::Key {
                origin: origin.into(),
                key: crate::files::excerpt_text(section, crate::files::EXCERPT_CHARS),
                expected: "a section".into(),
                found: describe(value),
            });
        };
        for key in t.keys() {
            if !keys.contains(&key.as_str()) {
                return Err(SceneError::UnknownKey {
                    origin: origin.into(),
                    key: crate::files::excerpt_text(
                        &format!("{section}.{key}"),
                        crate::files::EXCERPT_CHARS,
                    ),
                    context: format!(" of [{section}]"),
                    known: keys.join(", "),
                });
            }
        }
    }
    Ok(())
}
