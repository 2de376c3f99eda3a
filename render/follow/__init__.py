"""Following a running daemon (`sasprobe render --connect`) on protocol/follow.py: the
daemon as the renderer's source (`daemon_source.py`), what its messages put into the scene
(`messages.py`), the requests the window sends it (`requests.py`) and the readout's
clearance at the probe (`live_clearance.py`). No GL here: what is drawn is the scene these
modules fill in."""
