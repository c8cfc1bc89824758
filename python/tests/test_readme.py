"""The README's Python example runs as written, from the repository's root."""

import os
import re

from conftest import ROOT


def test_readme_python_example_runs(tmp_path, capsys):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks, "the README has a Python example"
    (tmp_path / "assets").symlink_to(ROOT / "assets")
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        for block in blocks:
            exec(compile(block, "README.md", "exec"), {})
    finally:
        os.chdir(cwd)
    out = capsys.readouterr().out
    assert "of the pixels hit the bunny" in out and "[ True False]" in out
    assert (tmp_path / "bunny.oct").exists()
