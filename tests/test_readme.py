"""The README's Python examples run as written."""

import pathlib
import re
import textwrap

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run(capsys):
    # blocks may be indented (inside a list item)
    found = re.findall(r"^ *```python\n(.*?)^ *```", README.read_text(), flags=re.S | re.M)
    blocks = [textwrap.dedent(block) for block in found]
    assert blocks
    for block in blocks:
        exec(compile(block, str(README), "exec"), {})
