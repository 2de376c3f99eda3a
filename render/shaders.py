"""Shader sources under render/shaders/, with `#include "file"` and per-program defines."""

from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


@lru_cache(maxsize=None)
def _read(name: str) -> str:
    return resources.files("sasprobe.render").joinpath("shaders", name).read_text()


def source(name: str, defines: tuple[str, ...] = ()) -> str:
    """A shader's text with includes expanded (each file once) and `#define`s after #version."""
    seen: set[str] = set()

    def expand(text: str) -> str:
        def replace(match: re.Match) -> str:
            included = match.group(1)
            if included in seen:
                return ""
            seen.add(included)
            return expand(_read(included))

        return _INCLUDE.sub(replace, text)

    text = expand(_read(name))
    if defines:
        first, _, rest = text.partition("\n")
        if not first.startswith("#version"):
            raise ValueError(f"shader {name} must start with #version")
        text = first + "\n" + "".join(f"#define {d}\n" for d in defines) + rest
    return text


def program(ctx, vertex: str, fragment: str | None = None, geometry: str | None = None, defines=()):
    """Compile and link a program from shader file names."""
    defines = tuple(defines)
    return ctx.program(
        vertex_shader=source(vertex, defines),
        fragment_shader=source(fragment, defines) if fragment else None,
        geometry_shader=source(geometry, defines) if geometry else None,
    )


class ProgramCache:
    """Programs compiled once per (files, defines) and shared by the passes of a renderer."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._programs: dict = {}

    def get(self, vertex: str, fragment: str | None = None, geometry: str | None = None, defines=()):
        key = (vertex, fragment, geometry, tuple(defines))
        if key not in self._programs:
            self._programs[key] = program(self.ctx, vertex, fragment, geometry, defines)
        return self._programs[key]

    def release(self) -> None:
        for prog in self._programs.values():
            prog.release()
        self._programs.clear()
