"""pytest: the README's Python example runs as written (from a folder holding the shipped data)."""
import os
import re

import lpoe  # noqa: F401  (the module under test must import)

HERE = os.path.dirname(os.path.abspath(__file__))
README = os.path.join(HERE, "..", "..", "README.md")
DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(HERE, "..", "..", "data"))


def test_readme_example_runs(tmp_path, monkeypatch, capsys):
    text = open(README, encoding="utf-8").read()
    section = text[text.index("\n## Python\n"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert 8 <= len(code.strip().splitlines()) <= 16  # "a ten-line example"
    os.symlink(os.path.abspath(DATA), tmp_path / "data")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    assert (tmp_path / "calibrated.yaml").stat().st_size > 0
    assert "True" in capsys.readouterr().out
