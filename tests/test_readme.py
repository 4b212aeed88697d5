"""The README's Python examples run as written."""

import pathlib
import re
import textwrap

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run(capsys):
    # blocks may be indented (inside a list item)
    blocks = [textwrap.dedent(b) for b in re.findall(r"^ *```python\n(.*?)^ *```", README.read_text(), flags=re.S | re.M)]
    assert blocks
    for block in blocks:
        exec(compile(block, str(README), "exec"), {})
