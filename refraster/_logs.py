"""Log records of refraster and third-party libraries as one-line warnings on the command line.

trimesh, for one, logs a whole traceback when a texture a mesh names is missing; the command
line shows each record as ``refraster: warning: trimesh.util: unable to load image!
(FileNotFoundError: tex.png)`` — in full (traceback included) only with ``--debug``, not at all
with ``-q`` (errors still show, one line each).
"""

from __future__ import annotations

import logging
import sys
from contextlib import contextmanager

__all__ = ["one_line_logs"]


def _first_line(text):
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    return lines[0] if lines else ""


class OneLineHandler(logging.Handler):
    """Writes each record (warning level and up; error and up with ``quiet``) as one line
    ``PROG: warning: LOGGER: message (Exception: text)`` to the current ``sys.stderr``, or the
    full record with its traceback when ``debug``."""

    def __init__(self, prog, *, debug=False, quiet=False):
        super().__init__(logging.ERROR if quiet else logging.WARNING)
        self.prog, self.debug = prog, debug

    def emit(self, record):
        try:
            kind = "warning"   # a logged record never decides the exit status
            if self.debug:
                text = logging.Formatter("%(name)s: %(message)s").format(record)
            else:
                text = f"{record.name}: {_first_line(record.getMessage())}"
                if record.exc_info and record.exc_info[1] is not None:
                    exc = record.exc_info[1]
                    detail = _first_line(exc)
                    text += f" ({type(exc).__name__}{': ' + detail if detail else ''})"
            line = f"{self.prog}: {kind}: {text}"
            tqdm = sys.modules.get("tqdm")
            if tqdm is not None and hasattr(tqdm, "tqdm"):
                tqdm.tqdm.write(line, file=sys.stderr)   # above a progress bar, not inside it
            else:
                print(line, file=sys.stderr)
        except Exception:   # a broken record must not break the command
            self.handleError(record)


@contextmanager
def one_line_logs(prog, *, debug=False, quiet=False):
    """Route every log record (root logger) through :class:`OneLineHandler` while the block
    runs; nested uses install one handler only."""
    root = logging.getLogger()
    if any(isinstance(h, OneLineHandler) for h in root.handlers):
        yield
        return
    handler = OneLineHandler(prog, debug=debug, quiet=quiet)
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)
