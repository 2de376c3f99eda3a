"""The page's own files (web/page/, shipped with the package), as the bridge serves them and
the HTML export inlines them.

The page is plain ES modules, no bundler: the modules import each other by bare names
(`sasprobe/viewer.js`), which an import map resolves, to the bridge's files on the live page
and to `data:` URLs in the self-contained HTML, so the same modules run from either.
"""

from __future__ import annotations

import base64
import hashlib
import re
from functools import cache
from importlib import resources

CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
}
LIVE_PAGE = "index.html"
REPLAY_PAGE = "replay.html"  # the export's template, not served
IMPORT_MAP = re.compile(rb'<script type="importmap">(.*?)</script>', re.S)


@cache
def page_files() -> dict[str, bytes]:
    """Every file of web/page/ by name."""
    folder = resources.files("sasprobe.web").joinpath("page")
    return {
        entry.name: entry.read_bytes()
        for entry in folder.iterdir()
        if entry.is_file() and any(entry.name.endswith(s) for s in CONTENT_TYPES)
    }


def content_type(name: str) -> str:
    return next(t for suffix, t in CONTENT_TYPES.items() if name.endswith(suffix))


def modules() -> dict[str, bytes]:
    """The page's ES modules by name."""
    return {name: data for name, data in page_files().items() if name.endswith(".js")}


def script_hash(html: bytes) -> str:
    """The CSP source ('sha256-...') of a page's inline import map."""
    match = IMPORT_MAP.search(html)
    if match is None:
        raise ValueError("the page has no import map")
    return "'sha256-" + base64.b64encode(hashlib.sha256(match.group(1)).digest()).decode() + "'"
