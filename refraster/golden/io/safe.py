"""Opening and parsing a file a golden command reads, without trusting it.

Shared by the readers (:mod:`refraster.golden.io.read`) and by the writers' look at what is
already at a target (:func:`refraster.golden.io.write.snapshot` reads the marker or manifest
there and hashes the files it lists):

* **Regular files only, no link followed**, checked before the open (``lstat``) and on the
  open descriptor (``fstat``: the same inode, still a regular file), the open itself with
  ``O_NOFOLLOW | O_NONBLOCK``: a FIFO, a socket or a device is refused before a byte is read,
  and never blocks (:func:`open_regular`, :func:`sha256_regular`).
* **Side files are size-capped before they are read** (:func:`read_json_file`: ``fstat``,
  then at most the cap plus one byte).
* **JSON is parsed into one error line**, never a ``RecursionError`` (too deep nesting) or a
  bare ``ValueError`` of Python's int-string conversion limit (an integer of thousands of
  digits): :func:`loads_json` names the file and the JSON path of the integer.

Imports nothing of refraster but :mod:`.errors`.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import sys

__all__ = ["MAX_SIDE_FILE_BYTES", "regular_stat", "open_regular", "loads_json",
           "read_capped", "read_json_file", "sha256_regular", "huge_int_digits"]

#: Largest side file read: ``manifest.json``, ``scene.json``, a candidate or report marker.
MAX_SIDE_FILE_BYTES = 64 << 20

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"))


def _kind(mode):
    return next((name for test, name in _KINDS if test(mode)), "not a plain file")


def regular_stat(path, error, what):
    """``os.lstat(path)``, refusing (``error``) a missing path, a symbolic link and anything
    but a regular file (one line naming ``what`` and the path)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise error(f"{what} {path} is missing") from None
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if stat.S_ISLNK(st.st_mode):
        raise error(f"{what} {path} is a symbolic link; links are never followed")
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{what} {path} is not a regular file ({_kind(st.st_mode)}); refusing to "
                    "read it")
    return st


def open_regular(path, error, what):
    """``path`` opened for reading (binary): a regular file reached by no link at its last
    component (:func:`regular_stat`), opened with ``O_NOFOLLOW | O_NONBLOCK`` (so a FIFO
    swapped in never blocks the open) and checked again on the descriptor."""
    st = regular_stat(path, error, what)
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) \
        | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    try:
        fst = os.fstat(fd)
        if not stat.S_ISREG(fst.st_mode) or (fst.st_dev, fst.st_ino) != (st.st_dev, st.st_ino):
            raise error(f"{what} {path} changed while it was opened; refusing to read it")
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


class _HugeInt:
    """An integer literal beyond the int-string conversion limit, kept as its length."""
    __slots__ = ("digits",)

    def __init__(self, digits):
        self.digits = digits


def huge_int_digits():
    """The interpreter's int-string conversion limit (digits; 0: none)."""
    get = getattr(sys, "get_int_max_str_digits", None)
    return get() if get is not None else 0


def _find_huge(doc):
    """JSON path and digit count of the first :class:`_HugeInt` in ``doc`` (iterative: ``doc``
    may be as deep as the parser allowed)."""
    stack = [(doc, "$")]
    while stack:
        node, path = stack.pop()
        if isinstance(node, _HugeInt):
            return path, node.digits
        if isinstance(node, dict):
            stack.extend((v, f"{path}.{k}") for k, v in reversed(list(node.items())))
        elif isinstance(node, list):
            stack.extend((v, f"{path}[{i}]") for i, v in reversed(list(enumerate(node))))
    return "$", 0


def loads_json(data, where, error):
    """Parse JSON ``data`` (bytes or text) from the file ``where``; every problem is one
    ``error`` naming it: not UTF-8, not JSON, nested too deeply, or an integer beyond the
    int-string conversion limit (its JSON path and digit count)."""
    huge = []

    def parse_int(text):
        try:
            return int(text)
        except ValueError:
            huge.append(True)
            return _HugeInt(len(text.lstrip("-")))

    try:
        text = data.decode("utf-8") if isinstance(data, (bytes, bytearray)) else data
        doc = json.loads(text, parse_int=parse_int)
    except UnicodeDecodeError as exc:
        raise error(f"cannot read {where}: not UTF-8 ({exc.reason} at byte {exc.start})") \
            from None
    except json.JSONDecodeError as exc:
        raise error(f"cannot read {where}: {exc}") from None
    except RecursionError:
        raise error(f"cannot read {where}: JSON nested too deeply") from None
    except ValueError as exc:   # e.g. a float literal Python refuses
        raise error(f"cannot read {where}: {' '.join(str(exc).split())}") from None
    if huge:
        path, digits = _find_huge(doc)
        raise error(f"{where} {path}: an integer of {digits} digits (more than the "
                    f"{huge_int_digits()} this reader converts); refusing to read it")
    return doc


def read_capped(fh, limit):
    """The bytes of ``fh`` up to its end or to ``limit + 1`` bytes (read in 1 MiB blocks: a
    single ``read(limit + 1)`` would allocate the whole limit up front)."""
    blocks, got = [], 0
    while got <= limit:
        block = fh.read(min(1 << 20, limit + 1 - got))
        if not block:
            break
        blocks.append(block)
        got += len(block)
    return b"".join(blocks)


def read_json_file(path, error, what, limit=MAX_SIDE_FILE_BYTES):
    """``(document, raw bytes)`` of the JSON side file ``path``: a regular file, no link
    (:func:`open_regular`), at most ``limit`` bytes (checked before reading), parsed by
    :func:`loads_json`."""
    with open_regular(path, error, what) as fh:
        size = os.fstat(fh.fileno()).st_size
        if size > limit:
            raise error(f"{what} {path} is larger than {limit >> 20} MiB ({size} bytes); "
                        "refusing to read it")
        try:
            raw = read_capped(fh, limit)
        except OSError as exc:
            raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if len(raw) > limit:
        raise error(f"{what} {path} is larger than {limit >> 20} MiB; refusing to read it")
    return loads_json(raw, f"{what} {path}", error), raw


def sha256_regular(path, error, what):
    """sha256 (hex) of the regular file ``path``, opened by :func:`open_regular` (a link or a
    special file is refused with ``error`` before a byte is read)."""
    h = hashlib.sha256()
    with open_regular(path, error, what) as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
