"""The CLI's structure arguments: a file, or a PDB id fetched into the cache
(sasprobe.molecule.fetch), with the mirror and cache options every such command shares."""

from __future__ import annotations

import argparse

MOLECULE_HELP = (
    "PDB or mmCIF file (optionally .gz), or a PDB id (4hhb, pdb:4hhb) fetched into the cache "
    "(default: embedded 1CRN)"
)


def add_fetch_options(parser: argparse.ArgumentParser) -> None:
    from sasprobe.molecule.fetch import CACHE_ENV, DEFAULT_MIRROR, MIRROR_ENV, MIRRORS

    parser.add_argument(
        "--pdb-mirror",
        metavar="NAME|URL",
        default=None,
        help=f"where PDB ids are fetched from: {', '.join(MIRRORS)} or a URL template with {{id}} "
        f"or {{ID}} (default ${MIRROR_ENV}, else {DEFAULT_MIRROR})",
    )
    parser.add_argument(
        "--pdb-cache",
        metavar="DIR",
        default=None,
        help=f"folder of fetched entries (default ${CACHE_ENV}, else ~/.cache/sasprobe/pdb)",
    )


def resolve_molecule(args: argparse.Namespace, text: str | None) -> str | None:
    """A structure argument as a file path (a PDB id is fetched, or found in the cache)."""
    if text is None:
        return None
    from sasprobe.molecule.fetch import FetchSettings, resolve

    return resolve(text, FetchSettings.from_environment(args.pdb_mirror, args.pdb_cache))
