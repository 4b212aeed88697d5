"""The Python examples of README.md and docs/ run as written, and the README's growing-circle
table is what the command it shows prints."""

import pathlib
import re
import shlex
import textwrap

import pytest

from evomesh.cli import main
from evomesh.statistics import STATISTICS_COLUMNS

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"

# The README table's columns; ours are these columns of the printed table, then come the paper's.
HEADER = ["step", "points", "original", "% original", "triangles", "min angle",
          "paper: points", "original", "% original", "triangles", "min angle"]
OURS = ("iteration", "points", "original_points", "original_pct", "triangles", "min_angle_deg")


@pytest.mark.parametrize("document", [README, *sorted(DOCS.glob("*.md"))], ids=lambda path: path.name)
def test_python_blocks_run(document, capsys):
    """Every Python block of README.md and docs/*.md runs as written."""
    # blocks may be indented (inside a list item)
    found = re.findall(r"^ *```python\n(.*?)^ *```", document.read_text(), flags=re.S | re.M)
    blocks = [textwrap.dedent(block) for block in found]
    assert blocks or document != README
    for block in blocks:
        exec(compile(block, str(document), "exec"), {})


def readme_growing_circle_arguments(text: str) -> list[str]:
    """The arguments of the README's `evomesh growing-circle` command, without --out."""
    blocks = re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M)
    commands = [line for block in blocks for line in block.splitlines() if "evomesh growing-circle" in line]
    assert len(commands) == 1, f"expected one growing-circle command in README.md, found {commands}"
    words = shlex.split(commands[0].split("&&")[-1])
    arguments = words[words.index("growing-circle") + 1:]
    if "--out" in arguments:
        del arguments[arguments.index("--out"):arguments.index("--out") + 2]
    return arguments


def readme_table_rows(text: str) -> list[list[str]]:
    """Body rows of the growing-circle table in README.md, as cell strings."""
    lines = [line for line in text.splitlines() if line.startswith("| step | points |")]
    assert len(lines) == 1, "README.md must hold one growing-circle table"
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    assert header == HEADER, header
    body = text.splitlines()[text.splitlines().index(lines[0]) + 2:]
    rows = []
    for line in body:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip("|").split("|")])
    return rows


def printed_table_rows(output: str) -> list[list[str]]:
    """The rows of `evomesh growing-circle`'s printed table, in the README's columns."""
    lines = output.splitlines()
    start = next(i for i, line in enumerate(lines) if line.lstrip().startswith("iter "))
    rows = []
    for line in lines[start + 1:]:
        if "|" not in line:
            break
        ours, paper = line.split("|")
        values = dict(zip(STATISTICS_COLUMNS, ours.split()))
        assert len(ours.split()) == len(STATISTICS_COLUMNS), line
        rows.append([values[name] for name in OURS] + paper.split())
    return rows


def markdown(rows: list[list[str]]) -> str:
    return "\n".join("| " + " | ".join(row) + " |" for row in rows)


def test_readme_growing_circle_table_is_what_the_command_prints(tmp_path, capsys):
    # The README's own command and parameters (figures off: they do not change the table).
    text = README.read_text()
    status = main(["growing-circle", *readme_growing_circle_arguments(text), "--out", str(tmp_path / "gc"),
                   "--no-figures"])
    assert status == 0
    output = capsys.readouterr().out
    printed = printed_table_rows(output)
    assert len(printed) == 6
    readme = readme_table_rows(text)
    assert readme == printed, (
        "README.md's growing-circle table differs from what `evomesh growing-circle` prints; "
        f"the current rows are:\n{markdown(printed)}"
    )
    initial = re.search(r"initial mesh: (\d+) points", output)
    assert initial and f"a {initial.group(1)}-point mesh" in text, "the README's initial mesh size is stale"
