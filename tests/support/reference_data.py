"""A small private copy of the reference structures' folder, for the benchmark tests."""

from __future__ import annotations

SMALL = ("1crn", "1oky")


def small_reference_data(reference_entries, folder, ids=SMALL):
    """A folder of the reference data's layout (links and a MANIFEST.tsv) holding only the
    structures `ids`, for SASPROBE_DATA."""
    folder.mkdir()
    header = "id\tfile\tformat\tatoms\tprotein_heavy_atoms_or_note"
    rows = [header]
    for entry in reference_entries:
        if entry.id in ids:
            (folder / entry.path.name).symlink_to(entry.path)
            rows.append(
                f"{entry.id}\t{entry.path.name}\t{entry.format}\t{entry.atoms}\t{entry.note}"
            )
    (folder / "MANIFEST.tsv").write_text("\n".join(rows) + "\n")
    return folder
