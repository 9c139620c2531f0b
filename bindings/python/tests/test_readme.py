"""The README's Python example runs as written, on the flat sample (its one path pointed at
wherever the tests find the sample), and what it prints the ends of holds together."""

import re

from conftest import REPO


def readme_python_block() -> str:
    text = (REPO / "README.md").read_text()
    section = text.split("\n## Python\n", 1)[1]
    return re.search(r"```python\n(.*?)\n```", section, re.S).group(1)


def test_the_readme_python_example_runs(flat_dir, tmp_path, monkeypatch):
    block = readme_python_block()
    assert '"../shared/data/flat"' in block
    monkeypatch.chdir(tmp_path)  # it saves map.voxpan into the working folder
    scope: dict = {}
    exec(compile(block.replace('"../shared/data/flat"', repr(str(flat_dir))), "README.md", "exec"), scope)
    assert (tmp_path / "map.voxpan").is_file()
    assert scope["m2"].block_count == scope["m"].block_count > 0
    assert len(scope["triangles"]) > 0 and scope["views"]["depth"].shape == (480, 640)
    assert 0.0 < scope["pq"]["all"]["pq"] < 100.0 and scope["pq"]["objects"] > 5
