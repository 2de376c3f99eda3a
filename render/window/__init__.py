"""The interactive window (glfw): its loop and input (`window_app.py`), the text over the
frame, picking an atom, screenshots and videos, the lighting keys, and what it shows while
a daemon's structure is on its way."""
