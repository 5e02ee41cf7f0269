"""onionsort: the command-line application around the irl library."""

__version__ = "0.1.0"
