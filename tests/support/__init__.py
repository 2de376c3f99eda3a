"""Helpers the test files share: real daemons and CLI processes, presses through them, the
schemas every received message is checked against, windows under Xvfb, small fixtures of
data. They may use sasprobe; the independent references are in tests/references/."""
