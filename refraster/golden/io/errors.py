"""Names shared by the golden modules (errors, exit codes), in a module that imports nothing of
refraster, so that the reading, writing, comparing and reporting modules can use them without
importing each other."""

from __future__ import annotations

__all__ = ["GoldenError", "CandidateError", "EXIT_PASS", "EXIT_FAIL", "EXIT_UNUSABLE"]

EXIT_PASS, EXIT_FAIL, EXIT_UNUSABLE = 0, 1, 2


class GoldenError(ValueError):
    """The golden directory, the arguments or the report directory cannot be used."""


class CandidateError(ValueError):
    """A candidate scene's files are missing, unreadable or of the wrong shape or dtype."""
