//! Python keyword arguments as `[env]` keys: each value becomes the TOML value a config file
//! would hold, so keyword arguments and config files are read by the one
//! [`vge_config_file::EnvKeys`] reader (unknown keys and wrong types refused by name).

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyString};
use vge_config_file::EnvKeys;

use crate::errors;

fn to_toml(key: &str, value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    if value.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(value.extract()?));
    }
    if value.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(value.extract()?));
    }
    if value.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(value.extract()?));
    }
    // Python ints, numpy integers (and numpy bools, through bool above or here).
    if let Ok(i) = value.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(items) = value.extract::<Vec<Bound<'_, PyAny>>>() {
        return items.iter().map(|v| to_toml(key, v)).collect::<PyResult<Vec<_>>>().map(toml::Value::Array);
    }
    // numpy floats and anything else with __float__.
    if let Ok(f) = value.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    let type_name = value.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".to_owned());
    Err(errors::value(format!(
        "env key `{key}`: a value of type {type_name} is not a config value (bool, int, float, str or a list of them)"
    )))
}

/// `kwargs` as a TOML table; a `None` value leaves the key at its default (left out).
pub fn table(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    let Some(kwargs) = kwargs else { return Ok(table) };
    for (k, v) in kwargs.iter() {
        let key: String = k.extract()?;
        if v.is_none() {
            continue;
        }
        let value = to_toml(&key, &v)?;
        table.insert(key, value);
    }
    Ok(table)
}

/// The keys of `config_path`'s `[env]` (if given) with `kwargs` over them, and a name for
/// messages.
pub fn read(config_path: Option<&str>, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<(EnvKeys, String)> {
    let overrides = table(kwargs)?;
    let (table, origin) = match config_path {
        Some(path) => {
            let t =
                EnvKeys::config_file_table(std::path::Path::new(path), overrides).map_err(errors::keys)?;
            (t, format!("{path} [env]"))
        }
        None => (overrides, "env keys".to_owned()),
    };
    let keys = EnvKeys::from_table(table, &origin).map_err(errors::keys)?;
    Ok((keys, origin))
}
