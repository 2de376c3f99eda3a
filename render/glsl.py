"""GLSL sources from render/shaders/ with `#include "file.glsl"` expanded and defines injected.

GLSL has no include mechanism, and moderngl passes source text through unchanged, so
shared pieces (the grid traversal, random numbers, the lighting inputs) are pasted in
here. Each file is included at most once per program, so includes may nest freely.
"""

from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)
GLSL_VERSION = "#version 430 core"


@lru_cache(maxsize=None)
def _read(name: str) -> str:
    return resources.files("sasprobe.render").joinpath("shaders", name).read_text()


def _expand(name: str, seen: set[str]) -> str:
    if name in seen:
        return ""
    seen.add(name)

    def include(match: re.Match) -> str:
        return _expand(match.group(1), seen)

    return _INCLUDE.sub(include, _read(name))


def shader_source(name: str, defines: dict[str, object] | None = None) -> str:
    """The full text of shader `name`: version line, `#define`s, then the expanded body."""
    lines = [GLSL_VERSION]
    for key, value in (defines or {}).items():
        lines.append(f"#define {key} {_glsl_literal(value)}")
    body = _expand(name, set())
    return "\n".join(lines) + "\n#line 1\n" + body


def _glsl_literal(value: object) -> str:
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return repr(value) if "e" in repr(value) or "." in repr(value) else f"{value}.0"
    return str(value)


def set_uniforms(program, values: dict[str, object]) -> None:
    """Set the uniforms a program uses; names the compiler optimised away are skipped.

    Arrays (clip planes, index lists) are given as numpy arrays and written whole
    (float32 or int32).
    """
    import numpy as np

    for name, value in values.items():
        if name not in program:
            continue
        uniform = program[name]
        if isinstance(value, np.ndarray):
            dtype = np.float32 if value.dtype.kind == "f" else np.int32
            uniform.write(np.ascontiguousarray(value, dtype=dtype).tobytes())
        else:
            uniform.value = value
