"""Recording a session and playing it back: the MCAP writer thread, the replay device
and `replay --verify`. The file format and its reader are protocol/recording.py (the
renderer reads recordings too)."""
