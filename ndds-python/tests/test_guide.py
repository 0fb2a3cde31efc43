"""The Python section of the user guide (docs/user-guide.md, "From Python") runs as written:
its ```python blocks, in order, in one namespace, from the repository's root, against this
test's daemon."""

from __future__ import annotations

import contextlib
import io
import os
import pathlib
import re
import sys
import types

REPO = pathlib.Path(__file__).resolve().parents[2]


def guide_blocks() -> list:
    text = (REPO / "docs" / "user-guide.md").read_text()
    section = text[text.index("## 9. From Python") :]
    return re.findall(r"```python\n(.*?)```", section, re.S)


def test_the_guides_python_examples_run(domain, monkeypatch):
    blocks = guide_blocks()
    assert len(blocks) >= 6, "the guide's Python section lost its examples"
    monkeypatch.chdir(REPO)
    for key, value in domain.env().items():
        if key.startswith("NDDS_"):
            monkeypatch.setenv(key, value)
    # A module of its own: dataclasses look their module up in sys.modules.
    module = types.ModuleType("ndds_user_guide")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    namespace = module.__dict__
    out = io.StringIO()
    for i, block in enumerate(blocks):
        with contextlib.redirect_stdout(out):
            exec(compile(block, f"user-guide.md python block {i + 1}", "exec"), namespace)
    printed = out.getvalue()
    # What the guide's comments say is printed.
    assert "{'x': 5.0, 'y': 6.0, 'theta': 0.0, 'frame': 'odom'}" in printed
    assert "0.2 ['rad', 'rad']" in printed
    assert "closed to 12.5 mm for planner" in printed
    assert re.search(r"^Home -?0\.0", printed, re.M), printed


def test_the_readmes_python_example_runs(domain, monkeypatch, capsys):
    text = (REPO / "README.md").read_text()
    section = text[text.index("## From Python") :]
    block = re.findall(r"```python\n(.*?)```", section, re.S)[0]
    for key, value in domain.env().items():
        if key.startswith("NDDS_"):
            monkeypatch.setenv(key, value)
    module = types.ModuleType("ndds_readme")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    exec(compile(block, "README.md", "exec"), module.__dict__)
    assert "Pose(x=1.0, y=2.0)" in capsys.readouterr().out
