"""The examples run as documented."""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parent.parent / "examples").glob("*.py"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(path, capsys):
    runpy.run_path(str(path), run_name="__main__")
    assert capsys.readouterr().out


def test_readme_demo_table_is_what_make_demo_prints(capsys):
    """The table in the README under "`make demo` prints" is the demo's own output."""
    import re
    from pathlib import Path

    from csdf.demo import compile_table

    compile_table()
    printed = capsys.readouterr().out.split("\n\n")[0].strip().splitlines()
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    block = re.search(r"`make demo` prints.*?```\n(.*?)```", readme, re.S)
    assert block is not None
    assert block.group(1).strip().splitlines() == printed
