"""Structures by PDB id: `4hhb` or `pdb:4hhb` wherever a structure file is taken.

An id is resolved to a file: the id of an entry shipped with the package (1CRN) to that
copy, with no network; any other to a file in a cache folder: a cached copy is used as
it is (so a fetched entry works offline), otherwise the entry's mmCIF is downloaded from
a mirror and kept. A bare id counts as an id only when no file of that name exists, so a file
always wins. Ids are the classic four characters, a digit first (`1crn`, `6ZU5`).

Mirrors (`--pdb-mirror`, `$SASPROBE_PDB_MIRROR`, or `pdb-mirror` in a command's TOML
section) are a name below or any URL template with `{id}` (lower case), `{ID}` (upper
case) and optionally `{mid}` (the id's middle two characters, the wwPDB archive's
folders). The cache is `--pdb-cache`, `$SASPROBE_PDB_CACHE`, else
`$XDG_CACHE_HOME/sasprobe/pdb` (default `~/.cache/sasprobe/pdb`). Downloads larger than
a megabyte show a progress bar; every failure is one line (FetchError).
"""

from __future__ import annotations

import os
import re
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from sasprobe.common.errors import UserError

# The wwPDB archive's layout, data/structures/divided/mmCIF/<mid>/<id>.cif.gz, on the
# partners' servers; the RCSB's own download service by default.
MIRRORS = {
    "rcsb": "https://files.rcsb.org/download/{ID}.cif.gz",
    "pdbe": "https://ftp.ebi.ac.uk/pub/databases/pdb/data/structures/divided/mmCIF/{mid}/{id}.cif.gz",
    "pdbj": "https://ftp.pdbj.org/pub/pdb/data/structures/divided/mmCIF/{mid}/{id}.cif.gz",
}
DEFAULT_MIRROR = "rcsb"
MIRROR_ENV = "SASPROBE_PDB_MIRROR"
CACHE_ENV = "SASPROBE_PDB_CACHE"
TIMEOUT_S = 30.0
PROGRESS_ABOVE_BYTES = 1 << 20
MAX_ENTRY_BYTES = 1 << 30  # larger than any PDB entry's compressed mmCIF
_CHUNK = 1 << 16
_ID = re.compile(r"[0-9][A-Za-z0-9]{3}")
PREFIX = "pdb:"


class FetchError(UserError):
    """An id that cannot be fetched; the message is one line naming the id and the mirror."""


def pdb_id(text: str) -> str | None:
    """The (lower-case) PDB id `text` names, or None when it names a file."""
    if text.lower().startswith(PREFIX):
        ident = text[len(PREFIX) :]
        if not _ID.fullmatch(ident):
            raise FetchError(
                f"{text}: not a PDB id (four characters, a digit first, e.g. pdb:4hhb)"
            )
        return ident.lower()
    if _ID.fullmatch(text) and not Path(text).exists():
        return text.lower()
    return None


@dataclass(frozen=True)
class FetchSettings:
    mirror: str = DEFAULT_MIRROR  # a MIRRORS name or a URL template
    cache: Path | None = None  # None: cache_dir()'s default
    timeout_s: float = TIMEOUT_S

    @classmethod
    def from_environment(
        cls, mirror: str | None = None, cache: str | Path | None = None
    ) -> FetchSettings:
        """Settings given (flags, config), else the environment's, else the defaults."""
        mirror = mirror or os.environ.get(MIRROR_ENV) or DEFAULT_MIRROR
        cache = cache or os.environ.get(CACHE_ENV) or None
        settings = cls(mirror=mirror, cache=Path(cache) if cache else None)
        settings.template()  # a bad mirror fails here, before anything is loaded
        return settings

    def template(self) -> str:
        template = MIRRORS.get(self.mirror.lower(), self.mirror)
        if "{id}" not in template and "{ID}" not in template:
            raise FetchError(
                f"PDB mirror {self.mirror!r} is neither {', '.join(MIRRORS)} nor a URL template "
                "with {id} or {ID} (e.g. https://host/{id}.cif.gz)"
            )
        return template

    def url(self, ident: str) -> str:
        return self.template().format(id=ident.lower(), ID=ident.upper(), mid=ident[1:3].lower())

    def cache_dir(self) -> Path:
        if self.cache is not None:
            return self.cache
        base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        return Path(base) / "sasprobe" / "pdb"


def cached_entry(ident: str, settings: FetchSettings) -> Path | None:
    folder = settings.cache_dir()
    for name in (f"{ident}.cif.gz", f"{ident}.cif"):
        if (folder / name).is_file():
            return folder / name
    return None


def resolve(text: str, settings: FetchSettings | None = None) -> str:
    """A structure argument as a file path: itself, the shipped copy of an embedded entry,
    or the cached file of the PDB id it names."""
    ident = pdb_id(text)
    if ident is None:
        return text
    shipped = embedded_entry(ident)
    if shipped is not None:
        return str(shipped)
    return str(fetch_entry(ident, settings or FetchSettings.from_environment()))


def embedded_entry(ident: str) -> Path | None:
    """The package's own file of an entry (the default structure), when it ships one as a file."""
    from importlib import resources

    from sasprobe.molecule.structure import DEFAULT_STRUCTURE, structure_name

    if ident != structure_name(DEFAULT_STRUCTURE):
        return None
    shipped = resources.files("sasprobe.molecule").joinpath("data", DEFAULT_STRUCTURE)
    return shipped if isinstance(shipped, Path) and shipped.is_file() else None


def fetch_entry(ident: str, settings: FetchSettings) -> Path:
    """The cached mmCIF of an entry, downloaded first when the cache does not hold it."""
    hit = cached_entry(ident, settings)
    if hit is not None:
        return hit
    url = settings.url(ident)
    host = urllib.parse.urlsplit(url).netloc or url
    folder = settings.cache_dir()
    data = _download(ident, url, host, folder, settings.timeout_s)
    if data[:2] != b"\x1f\x8b" and not data.lstrip()[:5] == b"data_":
        raise FetchError(f"pdb:{ident}: {host} did not send an mmCIF file ({url})")
    name = f"{ident}.cif.gz" if data[:2] == b"\x1f\x8b" else f"{ident}.cif"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=f".{ident}.", delete=False) as tmp:
            tmp.write(data)
        os.replace(tmp.name, folder / name)  # another process never sees half a file
    except OSError as exc:
        raise FetchError(
            f"pdb:{ident}: cannot write the cache folder {folder} ({exc.strerror or exc})"
        ) from None
    return folder / name


def _download(ident: str, url: str, host: str, folder: Path, timeout_s: float) -> bytes:
    from sasprobe import __version__

    request = urllib.request.Request(url, headers={"User-Agent": f"sasprobe/{__version__}"})
    try:
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            return _read_body(response, ident)
    except urllib.error.HTTPError as exc:
        if exc.code in (404, 410):
            raise FetchError(
                f"pdb:{ident}: no such entry at {host} (HTTP {exc.code} for {url})"
            ) from None
        raise FetchError(
            f"pdb:{ident}: {host} answered HTTP {exc.code} {exc.reason} ({url})"
        ) from None
    except (urllib.error.URLError, OSError, ValueError) as exc:
        reason = getattr(exc, "reason", None) or exc
        raise FetchError(
            f"pdb:{ident}: cannot reach {host} ({reason}) and no copy is cached in {folder}"
        ) from None


def _read_body(response, ident: str) -> bytes:
    length = response.headers.get("Content-Length")
    total = int(length) if length and length.isdigit() else None
    bar = None
    if total is None or total > PROGRESS_ABOVE_BYTES:
        from sasprobe.common.progress import progress_bar

        bar = progress_bar(total, f"fetch {ident}", unit="B", unit_scale=True)
    chunks, size = [], 0
    try:
        while True:
            chunk = response.read(_CHUNK)
            if not chunk:
                break
            size += len(chunk)
            if size > MAX_ENTRY_BYTES:
                raise FetchError(
                    f"pdb:{ident}: the download exceeds "
                    f"{MAX_ENTRY_BYTES >> 20} MiB; not a PDB entry"
                )
            chunks.append(chunk)
            if bar is not None:
                bar.update(len(chunk))
    finally:
        if bar is not None:
            bar.close()
    if total is not None and size != total:
        raise FetchError(f"pdb:{ident}: the download stopped after {size} of {total} bytes")
    return b"".join(chunks)
