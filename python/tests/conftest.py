"""Shared fixtures: the repository, the pure-Rust reference binary (python/reference) and
the `vge` command line (the main workspace's release build), which the tests compare the
Python package with."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
REFERENCE = Path(os.environ.get("VGE_PYTHON_REFERENCE", REPO / "target/release/vge-python-reference"))
VGE = Path(os.environ.get("VGE_BIN", REPO / "target/release/vge"))


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def reference() -> Path:
    """The reference binary; built by the test command
    (`cargo build --release -p vge-python-reference`)."""
    if not REFERENCE.is_file():
        pytest.fail(
            f"{REFERENCE} is missing: build it with "
            "`cargo build --release -p vge-python-reference`"
        )
    return REFERENCE


@pytest.fixture(scope="session")
def vge_cli() -> Path:
    """The `vge` binary (target/release/vge, built by `cargo test --release --workspace
    --no-run`); the tests that compare with it are skipped, by name, without it."""
    if not VGE.is_file():
        pytest.skip(f"{VGE} not built (cargo test --release --workspace --no-run builds it)")
    return VGE


def run_json(args: list, stdin: str | None = None) -> dict:
    out = subprocess.run([str(a) for a in args], input=stdin, capture_output=True, text=True, cwd=REPO)
    if out.returncode != 0:
        raise AssertionError(f"{args} failed ({out.returncode}): {out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])
