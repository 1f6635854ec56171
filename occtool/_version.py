"""The one version source: pyproject.toml reads it ([tool.setuptools.dynamic]), and what
writes a file that names occtool (an MCAP's library field) imports it from here, not from
the package's front door."""

__version__ = "0.1.0"
