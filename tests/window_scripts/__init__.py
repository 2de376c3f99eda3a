"""Scripts a test runs in a process of its own on its Xvfb server (`python -m
tests.window_scripts.NAME`, conftest.run_window_check): a real glfw window whose keys and
pixels they check, printing 'keys ok' when every check passed."""
