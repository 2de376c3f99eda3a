"""sasprobe: feel and see a protein's solvent accessible surface with a haptic arm."""


def __getattr__(name: str):
    # The version is looked up on first use: importlib.metadata costs the CLI's start-up
    # more than the rest of `sasprobe --help` together.
    if name == "__version__":
        from importlib import metadata

        try:
            version = metadata.version("sasprobe")
        except metadata.PackageNotFoundError:  # running from a source tree without install
            version = "0.0.0+unknown"
        globals()["__version__"] = version
        return version
    raise AttributeError(f"module 'sasprobe' has no attribute {name!r}")
