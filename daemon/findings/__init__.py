"""What a session found, from its recording alone: the explored path, the residues touched,
the marks and what lies at them, the clearance and passage radius along the path and its
bottleneck; a chart and files for PyMOL and ChimeraX (report.py lists them).

session.py reads the recording, path.py decimates the probe's track, contacts.py finds
the residues, bottleneck.py the passage profile, chart.py and exports.py write the
pictures and files, report.py puts them in one folder. `python -m sasprobe.daemon.findings`
runs it as the daemon's `findings` child process.
"""

from sasprobe.daemon.findings.report import analyse, summary_lines, write_findings

__all__ = ["analyse", "summary_lines", "write_findings"]
