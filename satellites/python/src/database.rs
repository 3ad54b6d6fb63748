//! `Database`: the hub's persisted pair database (JSON values by key, in named databases), as the Rust SDK's
//! `db_*` and `var_*` calls.

use pyo3::prelude::*;

use crate::errors::IntoPy;
use crate::runtime::wait;

/// The pair database of one connection: `get`, `set`, `delete`, `keys` in the selected database (`main` unless
/// `select` chose another; the choice survives reconnects).
#[pyclass(frozen, module = "flow._native")]
#[derive(Debug)]
pub struct Database {
    client: flow::Client,
}

impl Database {
    pub fn new(client: flow::Client) -> Self {
        Database { client }
    }
}

/// A Python value as the JSON the hub stores.
fn to_json(value: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    let text: String = value
        .py()
        .import("json")?
        .call_method1("dumps", (value,))?
        .extract()?;
    serde_json::from_str(&text).map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))
}

fn from_json<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?
        .call_method1("loads", (value.to_string(),))
}

#[pymethods]
impl Database {
    /// The value of `key`, or `default` when the database has no such key.
    #[pyo3(signature = (key, default=None))]
    fn get<'py>(
        &self,
        py: Python<'py>,
        key: &str,
        default: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        match wait(py, self.client.var_get(key))?.py_err()? {
            Some(v) => from_json(py, &v),
            None => Ok(default.unwrap_or_else(|| py.None().into_bound(py))),
        }
    }

    /// Stores any JSON-serialisable value; returns once the hub has made it durable.
    fn set(&self, py: Python<'_>, key: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let value = to_json(value)?;
        wait(py, self.client.var_set(key, &value))?.py_err()
    }

    /// Removes `key`.
    fn delete(&self, py: Python<'_>, key: &str) -> PyResult<()> {
        wait(py, self.client.var_del(key))?.py_err()
    }

    /// The keys of the selected database.
    fn keys(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        wait(py, self.client.var_list())?.py_err()
    }

    /// Makes `name` this connection's database (`DatabaseError` if it does not exist; see `create`).
    fn select(&self, py: Python<'_>, name: &str) -> PyResult<()> {
        wait(py, self.client.db_select(name))?.py_err()
    }

    /// Creates a database.
    fn create(&self, py: Python<'_>, name: &str) -> PyResult<()> {
        wait(py, self.client.db_create(name))?.py_err()
    }

    /// Removes a database and everything in it.
    fn remove(&self, py: Python<'_>, name: &str) -> PyResult<()> {
        wait(py, self.client.db_remove(name))?.py_err()
    }

    /// Every database on the hub.
    fn databases(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        wait(py, self.client.db_list())?.py_err()
    }
}
