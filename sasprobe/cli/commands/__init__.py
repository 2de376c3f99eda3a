"""Subcommands of the `sasprobe` CLI, one module each, found automatically."""
