//! The Python interpreter the tests that read vge's outputs back with real Python packages
//! (rerun-sdk, MuJoCo, TensorBoard's reader) run: VGE_PYTHON, else the venv that
//! scripts/test.sh fills in `.deps/py`, else `python3`. Included by path
//! (`#[path = ".../tests/support/python.rs"] mod python_env;`) from every crate's tests, since
//! no test-support crate is shared across the workspace; so `CARGO_MANIFEST_DIR` below is
//! the including crate's (every crate sits one level below the workspace root).

use std::path::{Path, PathBuf};

/// VGE_PYTHON, else `<workspace>/.deps/py/bin/python`, else `python3`.
pub fn python() -> PathBuf {
    if let Ok(p) = std::env::var("VGE_PYTHON") {
        return p.into();
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.deps/py/bin/python");
    if venv.exists() { venv } else { "python3".into() }
}
