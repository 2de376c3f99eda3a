"""sasprobe: feel and see a protein's solvent accessible surface with a haptic arm."""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("sasprobe")
except _metadata.PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"
