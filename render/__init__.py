"""The render process: moderngl passes, lighting and the subscriber."""
