"""`sasprobe replay FILE --findings DIR` (and the daemon's `findings`): every finding of a
session from its recording alone, written into one folder.

    findings.json         everything below, with the session, the files and notes
    touched_residues.tsv  chain, residue, number, atoms, contact time, largest force,
                          first and last time
    marks.tsv             each mark: time, position, label, the residues within 4 Å
    chart.png             passage radius and force along the path, with the marks
    path.pdb, path.cif    the path as pseudo-atoms, B-factor = passage radius
    structure.pdb|cif     the structure the session used (the recording's attachment)
    session.pml, session.cxc   PyMOL and ChimeraX: structure, path, marks, touched residues

Each long step shows a progress bar on stderr.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

from sasprobe.daemon.findings.bottleneck import (
    Profile,
    profile,
    verdict,
)
from sasprobe.daemon.findings.bottleneck import (
    bottleneck as find_bottleneck,
)
from sasprobe.daemon.findings.chart import draw_chart
from sasprobe.daemon.findings.contacts import Contacts, residues_near
from sasprobe.daemon.findings.exports import (
    ViewerScene,
    chimerax_script,
    pymol_script,
    write_path,
    write_structure,
)
from sasprobe.daemon.findings.path import ExploredPath, PathBuilder
from sasprobe.daemon.findings.session import Track, read_track
from sasprobe.molecule.clearance import MIN_RUN_A, OPEN_RADIUS_A, ClearanceField

from sasprobe.common.errors import UserError
from sasprobe.common.progress import progress_bar


def prepare_folder(out_dir: str | Path) -> Path:
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise UserError(f"--findings {folder}: exists and is not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--findings {folder}: cannot create it ({exc.strerror or exc})") from None
    return folder


@dataclass
class Analysis:
    found: dict  # findings.json's content (plain JSON)
    path: ExploredPath  # for the chart and the exports
    profile: Profile


def analyse(
    track: Track, probe_radius_A: float | None = None, ticks: int | None = None
) -> Analysis:
    """Every finding of a track, from one pass over its ticks (and a partial second one for
    the bottleneck); the verdict is about probe_radius_A (default: the session's). `ticks`:
    how many the pass will read, for its progress bar, when known."""
    radius = track.probe_radius_A if probe_radius_A is None else float(probe_radius_A)
    field = ClearanceField.of(track.structure)
    contacts = Contacts(track.structure, field, track.probe_radius_A)
    builder = PathBuilder()
    contact_s = 0.0
    bar = progress_bar(ticks, desc="findings: ticks", unit="tick")
    try:
        for block in track.blocks():
            touched = contacts.block(block)
            builder.add_block(
                block.first,
                block.seq.tolist(),
                block.proxy_A.tolist(),
                block.t_s.tolist(),
                block.contact.tolist(),
                block.force_N.tolist(),
                touched,
                set(block.marked),
            )
            contact_s += float(block.dt_s[block.contact].sum())
            bar.update(len(block))
    finally:
        bar.close()
    path = builder.finish()
    bar = progress_bar(path.n_points, desc="findings: passage", unit="point")
    try:
        prof = profile(path, field, progress=bar.update)
    finally:
        bar.close()
    neck, path, prof = find_bottleneck(track, path, prof, field)
    marks = [
        {**m, "residues_within_4A": residues_near(track.structure, m["position_A"])}
        for m in track.marks
    ]
    s = track.structure
    found = {
        "recording": track.source,
        "structure": {"name": s.name, "sha256": s.sha256, "n_atoms": s.n_atoms},
        "session": {
            "duration_s": track.duration_s,
            "ticks": track.n_ticks,
            "rate_hz": track.rate_hz,
            "finished": track.finished,
            "probe_radius_A": track.probe_radius_A,
            "contact_s": contact_s,
            "path_length_A": float(path.length_A[-1]),
        },
        "touched_residues": contacts.residues(),
        "marks": marks,
        "bottleneck": neck,
        "verdict": verdict(None if neck is None else neck["radius_A"], radius),
        "path": {
            "spacing_A": path.spacing_A,
            "open_radius_A": OPEN_RADIUS_A,
            "min_run_A": MIN_RUN_A,
            "points": _points(path, prof),
        },
        "notes": track.notes,
    }
    return Analysis(found, path, prof)


def _points(path: ExploredPath, prof: Profile) -> list[dict]:
    return [
        {
            "t_s": float(path.t_s[k]),
            "seq": int(path.seq[k]),
            "position_A": path.position_A[k].tolist(),
            "contact": bool(path.contact[k]),
            "force_max_N": float(path.force_max_N[k]),
            "length_A": float(path.length_A[k]),
            "clearance_A": float(prof.clearance_A[k]),
            "passage_A": float(prof.passage_A[k]),
            "bounded": bool(prof.bounded[k]),
            "widest_sphere_A": prof.passage[k].radius_A,
            "widest_sphere_center_A": prof.passage[k].center_A.tolist(),
        }
        for k in range(path.n_points)
    ]


def write_findings(
    recording: str | Path,
    out_dir: str | Path,
    probe_radius_A: float | None = None,
    ticks: int | None = None,
) -> dict:
    """Analyse a recording and write every file into out_dir; returns findings.json's content.
    `ticks`: the recording's tick count, for the progress bar, when known."""
    track = read_track(recording)  # a bad file ends here, before any folder is made
    folder = prepare_folder(out_dir)
    analysis = analyse(track, probe_radius_A, ticks)
    found, path, prof = analysis.found, analysis.path, analysis.profile
    radius = found["verdict"]["probe_radius_A"]
    title = f"{track.structure.name}: {Path(track.source).name}, {track.duration_s:.1f} s"
    files = {
        "json": "findings.json",
        "residues": "touched_residues.tsv",
        "marks": "marks.tsv",
        "chart": "chart.png",
    }
    structure_file = write_structure(track.structure_file, folder).name
    files["structure"] = structure_file
    files.update(write_path(folder, path.position_A, prof.passage_A, found["marks"]))
    scene = ViewerScene(
        folder,
        structure_file,
        radius,
        found["touched_residues"],
        found["marks"],
        found["bottleneck"],
        title,
    )
    (folder / "session.pml").write_text(pymol_script(scene))
    (folder / "session.cxc").write_text(chimerax_script(scene))
    files.update(pymol="session.pml", chimerax="session.cxc")
    _write_tables(folder, found)
    draw_chart(
        folder / "chart.png",
        title,
        path,
        prof,
        radius,
        found["bottleneck"],
        found["marks"],
        found["verdict"]["verdict"],
    )
    found["files"] = files
    (folder / "findings.json").write_text(json.dumps(found, indent=1, allow_nan=False))
    return found


def _write_tables(folder: Path, found: dict) -> None:
    with open(folder / "touched_residues.tsv", "w", newline="") as fh:
        w = csv.writer(fh, delimiter="\t", lineterminator="\n")
        w.writerow(
            ["chain", "residue", "number", "atoms", "contact_s", "max_force_N", "first_s", "last_s"]
        )
        for r in found["touched_residues"]:
            w.writerow(
                [
                    r["chain"],
                    r["name"],
                    f"{r['number']}{r['icode']}",
                    ",".join(r["atoms"]),
                    *(f"{r[k]:.3f}" for k in ("contact_s", "max_force_N", "first_s", "last_s")),
                ]
            )
    with open(folder / "marks.tsv", "w", newline="") as fh:
        w = csv.writer(fh, delimiter="\t", lineterminator="\n")
        w.writerow(["mark", "label", "t_s", "x_A", "y_A", "z_A", "residues_within_4A"])
        for m in found["marks"]:
            near = ",".join(
                f"{r['chain']}:{r['name']}{r['number']}{r['icode']}"
                for r in m["residues_within_4A"]
            )
            w.writerow(
                [
                    m["id"],
                    m["label"],
                    f"{m['t_s']:.3f}",
                    *(f"{v:.3f}" for v in m["position_A"]),
                    near,
                ]
            )


def summary_lines(found: dict, limit: int = 20) -> list[str]:
    """The findings as the terminal shows them: the session, the verdict, the marks and the
    touched residues (the first `limit`, by contact time)."""
    s, v = found["session"], found["verdict"]
    lines = [
        f"findings  {found['structure']['name']}: {s['duration_s']:.1f} s, "
        f"path {s['path_length_A']:.1f} Å, "
        f"in contact {s['contact_s']:.1f} s, {len(found['touched_residues'])} residues touched, "
        f"{len(found['marks'])} marks"
    ]
    neck = found["bottleneck"]
    if neck is not None:
        atoms = ", ".join(
            f"{a['chain']}:{a['name']}{a['number']}{a['icode']} {a['atom']}"
            for a in neck["atoms"][:6]
        )
        lines.append(
            f"  bottleneck {neck['radius_A']:.2f} Å at {neck['t_s']:.2f} s "
            f"(path {neck['path_length_A']:.1f} Å), lined by {atoms}"
        )
    lines.append(f"  verdict    {v['verdict']}")
    for m in found["marks"]:
        near = ", ".join(
            f"{r['chain']}:{r['name']}{r['number']}{r['icode']}"
            for r in m["residues_within_4A"][:6]
        )
        lines.append(
            f"  mark {m['id']:<3}  {m['t_s']:7.2f} s  {m['label']}: "
            f"{near or 'no residue within 4 Å'}"
        )
    rows = sorted(found["touched_residues"], key=lambda r: -r["contact_s"])[:limit]
    if rows:
        lines.append(
            f"  {'chain':<6}{'residue':<8}{'number':>7}  {'contact s':>9}  {'max N':>6}  "
            f"{'first s':>7}  {'last s':>7}  atoms"
        )
        for r in rows:
            lines.append(
                f"  {r['chain']:<6}{r['name']:<8}{str(r['number']) + r['icode']:>7}  "
                f"{r['contact_s']:9.3f}  {r['max_force_N']:6.2f}  {r['first_s']:7.2f}  "
                f"{r['last_s']:7.2f}  {','.join(r['atoms'])}"
            )
        if len(found["touched_residues"]) > limit:
            lines.append(
                f"  ... {len(found['touched_residues']) - limit} more in touched_residues.tsv"
            )
    lines += [f"  note       {n}" for n in found["notes"]]
    return lines
