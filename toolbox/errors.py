"""Errors the host reports as one line with an exit code.

Usage errors (exit 2) are mistakes in how the toolbox was called: an unknown algorithm,
parameter or value. Data errors (exit 1) come from the inputs themselves: a file that is not
LAS, a truncated file, an empty cloud, an output that cannot be written.
"""


class ToolboxError(Exception):
    """Base class: the message is one line that names the thing and says what to do."""

    exit_code = 1


class UsageError(ToolboxError):
    exit_code = 2


class DataError(ToolboxError):
    exit_code = 1


class NothingFound(DataError):
    """The input holds none of what the algorithm looks for (no building, no wire). One run says
    so and fails; a survey's tile that finds nothing is empty, as a tile without points is."""


class PluginError(ToolboxError):
    """A plugin is broken (fails to import, raises in a hook, or clashes with another)."""

    exit_code = 1
