"""The README's Python example runs as written: it is python/examples/quickstart.py, run
here from the repository root, and the README's "## Python" section shows that file."""

import re
import subprocess
import sys

import pytest


def test_quickstart_runs(repo):
    out = subprocess.run(
        [sys.executable, "python/examples/quickstart.py"], cwd=repo, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr
    assert "dropped: False" in out.stdout


def test_readme_shows_the_quickstart(repo):
    readme = (repo / "README.md").read_text()
    section = re.search(r"^## Python\n(.*?)(?=^## |\Z)", readme, flags=re.M | re.S)
    if section is None:
        pytest.skip("README.md has no `## Python` section yet")
    blocks = re.findall(r"```python\n(.*?)```", section.group(1), flags=re.S)
    assert blocks, "the README's Python section has no python code block"
    assert blocks[0] == (repo / "python/examples/quickstart.py").read_text()
