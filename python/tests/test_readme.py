"""The Python guide's example runs as written: it is python/examples/quickstart.py, run
here from the repository root, and the "## Python" section of docs/python.md shows that file."""

import re
import subprocess
import sys


def test_quickstart_runs(repo):
    out = subprocess.run(
        [sys.executable, "python/examples/quickstart.py"], cwd=repo, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr
    assert "dropped: False" in out.stdout


def test_readme_shows_the_quickstart(repo):
    readme = (repo / "docs/python.md").read_text()
    section = re.search(r"^## Python\n(.*?)(?=^## |\Z)", readme, flags=re.M | re.S)
    assert section is not None, "docs/python.md has no `## Python` section"
    blocks = re.findall(r"```python\n(.*?)```", section.group(1), flags=re.S)
    assert blocks, "the `## Python` section of docs/python.md has no python code block"
    assert blocks[0] == (repo / "python/examples/quickstart.py").read_text()
