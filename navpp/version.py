"""The navpp version (PEP 440), as ``navpp --version`` and the reports show it."""

__version__ = "0.1.0"
