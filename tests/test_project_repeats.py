"""No block of code written twice in devices/ or render/: six or more identical lines in two
places (indentation, blank lines, imports, docstrings, comment lines and lines of brackets
aside), Python and shaders alike, belong in one function or one shader include. The report
names both places and their lines."""

from __future__ import annotations

import ast
import re

from tests.conftest import REPO_ROOT

REPEAT_LINES = 6  # this many identical lines in a row, in two places, are one block written twice
REPEAT_FOLDERS = ("devices", "render")
SHADER_SUFFIXES = {".glsl", ".vert", ".frag", ".geom", ".comp"}
TRIVIAL_LINE = re.compile(r"[\s()\[\]{},;:]*")  # brackets alone say nothing


def significant_lines(path: str, source: str) -> list[tuple[int, str]]:
    """(line number, stripped text) of the lines that count, in order: no blank line, no line
    of brackets alone; in Python no import and no docstring; in GLSL no comment line."""
    skipped: set[int] = set()
    if path.endswith(".py"):
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import | ast.ImportFrom):
                skipped.update(range(node.lineno, node.end_lineno + 1))
            body = getattr(node, "body", None)
            if (
                isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                and body
                and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)
            ):
                skipped.update(range(body[0].lineno, body[0].end_lineno + 1))
    comment = "#" if path.endswith(".py") else "//"
    return [
        (number, text)
        for number, line in enumerate(source.splitlines(), 1)
        if number not in skipped
        and not TRIVIAL_LINE.fullmatch(text := line.strip())
        and not text.startswith(comment)
    ]


def repeated_blocks(sources: dict[str, str]) -> list[str]:
    """Every block of REPEAT_LINES or more significant lines that appears twice (in two files
    or twice in one), as `a.py:10-19 = b.py:40-49 (8 lines): first line`, longest first."""
    lines = {path: significant_lines(path, source) for path, source in sources.items()}
    where: dict[tuple[str, ...], list[tuple[str, int]]] = {}
    for path, found in lines.items():
        for i in range(len(found) - REPEAT_LINES + 1):
            window = tuple(text for _, text in found[i : i + REPEAT_LINES])
            where.setdefault(window, []).append((path, i))
    pairs = set()  # (path a, start a, path b, start b) of equal windows, a before b
    for places in where.values():
        for k, (a, i) in enumerate(places):
            for b, j in places[k + 1 :]:
                if a != b or j - i >= REPEAT_LINES:  # a run of one line is not a copy of itself
                    pairs.add((a, i, b, j))
    blocks = []
    for a, i, b, j in pairs:
        if (a, i - 1, b, j - 1) in pairs:
            continue  # the middle of a longer block: reported from its start
        n = REPEAT_LINES
        while (a, i + n - REPEAT_LINES + 1, b, j + n - REPEAT_LINES + 1) in pairs:
            n += 1
        first, last = lines[a][i][0], lines[a][i + n - 1][0]
        other_first, other_last = lines[b][j][0], lines[b][j + n - 1][0]
        blocks.append(
            (
                -n,
                f"{a}:{first}-{last} = {b}:{other_first}-{other_last} ({n} lines): "
                f"{lines[a][i][1]}",
            )
        )
    return [text for _, text in sorted(blocks)]


def test_no_block_is_written_twice_in_devices_or_render():
    """Six or more identical lines (indentation, blank lines, imports, docstrings and lines of
    brackets aside) in two places of devices/ or render/, shaders included, are one piece of
    code written twice: it belongs in one function (or one shader include)."""
    sources = {
        path.relative_to(REPO_ROOT).as_posix(): path.read_text()
        for folder in REPEAT_FOLDERS
        for path in sorted((REPO_ROOT / folder).rglob("*"))
        if path.suffix == ".py" or path.suffix in SHADER_SUFFIXES
    }
    assert len(sources) > 100
    blocks = repeated_blocks(sources)
    assert blocks == [], "blocks written twice:\n" + "\n".join(blocks)


def test_a_block_written_twice_is_caught():
    block = "try:\n    lib = load(path)\nexcept OSError as exc:\n    raise Missing(exc)\n"
    block += "for name in NAMES:\n    declare(lib, name)\nreturn lib\n"
    first = '"""One loader."""\nimport ctypes\n\n\ndef load_a(path):\n' + "".join(
        f"    {line}\n" for line in block.splitlines()
    )
    # the same block, at another indentation, with blank lines and a docstring of its own
    second = 'def load_b(path):\n    """Another."""\n    if path:\n' + "".join(
        f"        {line}\n\n" for line in block.splitlines()
    )
    found = repeated_blocks({"a.py": first, "b.py": second})
    assert found == ["a.py:6-12 = b.py:4-16 (7 lines): try:"], found


def test_short_or_trivial_repeats_pass():
    five = "".join(f"x{i} = f({i})\n" for i in range(5))
    imports = "".join(f"import m{i}\n" for i in range(8))
    doc = '"""' + "\n".join(f"line {i}" for i in range(8)) + '\n"""\n'
    sources = {  # five lines alike, after eight alike imports and a docstring alike
        "a.py": doc + imports + five + "a = 1\n",
        "b.py": doc + imports + "b = 0\n" + five + "b = 1\n",
    }
    assert repeated_blocks(sources) == []
    shader = (
        "// the same comment\n// on six\n// lines\n// of a\n// shader\n// file\nvoid main() {}\n"
    )
    assert repeated_blocks({"a.frag": shader, "b.frag": shader}) == []
    block = "".join(f"float v{i} = {i}.0;\n" for i in range(6))
    spread = "// x\n" + block.replace(";\n", ";\n}\n  );\n", 2)  # lines of brackets between
    assert repeated_blocks({"a.frag": block, "b.vert": spread}) == [
        "a.frag:1-6 = b.vert:2-11 (6 lines): float v0 = 0.0;"
    ]
