"""Writing goldens, reports and command outputs without destroying data.

One owner for every write of ``refraster golden generate``, ``golden compare --report/--json``
and ``refraster render``:

* **Lock.** Writers of one target exclude each other with ``fcntl.flock`` on ``.NAME.lock``
  beside it (:func:`locked`). The loser waits, or (``wait=False``) fails with
  :class:`LockedError` naming the holder (pid, host, command). The lock file is removed when
  the holder is done (the inode is re-checked after locking, so a waiter never holds a lock on
  a removed file).
* **Temporary tree.** A directory is built in ``.NAME.tmp-…`` beside the target
  (:func:`make_tree`) and committed by :func:`commit_tree`.
* **Final check.** The commit refuses (:class:`RefusedError`, nothing deleted) unless what is at
  the target is still what the writer found when it started (:func:`snapshot`: nothing, an
  empty directory, or the same golden or report by the digest of its manifest or marker, with no
  file that refraster did not write).
* **Atomic swap.** With ``renameat2(RENAME_EXCHANGE)`` the old and the new tree trade places in
  one step and the one swapped out is checked again (changed meanwhile → swapped back and
  refused); a new target is moved in with ``RENAME_NOREPLACE``. Where the kernel or the file
  system lacks ``renameat2`` the swap is two renames with a journal (``.NAME.journal``) that the
  next refraster command on that target reads to roll forward (:func:`recover`).
* **Debris.** Temporary trees of a dead run are removed by the next run on the same target, under
  the lock: a live run holds the lock, so its debris is never touched (:func:`clean_debris`).
  A tree is removed file by file, only the files its manifest or report marker lists; anything
  else found in it is kept (renamed to ``NAME.kept-…``).
* **Several outputs** (:class:`Outputs`): each staged under a temporary name first; the commit
  renames them in order; if a step fails, the ones already renamed are undone and the files they
  replaced restored.
* **Signals.** :func:`terminate_as_interrupt` turns SIGTERM into :class:`Terminated` (a
  ``KeyboardInterrupt``), so it cleans up like Ctrl-C; SIGINT and SIGTERM are blocked while a
  commit renames (they take effect right after it).

``HOOKS`` lets tests stop or kill a run at a named step (``locked``, ``waiting``,
``before_commit``, ``before_swap``, ``between_renames``, ``after_swap``, ``commit_step``), which
makes races and crashes deterministic without sleeps.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import fcntl
import hashlib
import json
import os
import re
import shutil
import signal
import socket
import stat
import sys
import tempfile
import threading
import time
from pathlib import Path

from .errors import GoldenError

__all__ = ["HOOKS", "RefusedError", "LockedError", "Terminated", "locked", "snapshot",
           "make_tree", "commit_tree", "recover", "clean_debris", "discard_tree", "Outputs",
           "check_output_path", "check_regular_output", "check_report_dir", "pending_swap",
           "commit_report", "resolve_target",
           "terminate_as_interrupt", "dir_mode", "REPORT_MARKER", "CANDIDATE_MARKER",
           "rename_exchange",
           "rename_noreplace"]

#: Test hooks: ``HOOKS[name] = fn``; ``fn(**info)`` is called at that step of a write.
HOOKS: dict = {}

#: Tests set this to exercise the two-renames-and-journal swap where ``renameat2`` works.
FORCE_FALLBACK = False

#: The marker file a report directory written by refraster holds (lists its files).
REPORT_MARKER = ".refraster-report"
#: The marker file a candidate directory written by ``refraster golden candidate`` holds (lists
#: its files, the scenes rendered and the scenes skipped with the reason).
CANDIDATE_MARKER = ".refraster-candidate"

MANIFEST = "manifest.json"


def _hook(name, **info):
    fn = HOOKS.get(name)
    if fn is not None:
        fn(**info)


class RefusedError(FileExistsError):
    """A write was refused to keep existing data (nothing was deleted)."""


class LockedError(RefusedError):
    """Another refraster process is writing the same target (``wait=False``)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like a ``KeyboardInterrupt`` so that the same clean-up runs."""


# --- modes ---------------------------------------------------------------------------------------

def _umask():
    """The process umask, read without changing it (``/proc/self/status`` on Linux)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def dir_mode():
    """Mode of a new directory under the current umask (``mkdtemp`` makes 0700)."""
    return 0o777 & ~_umask()


def _file_mode():
    return 0o666 & ~_umask()


# --- renameat2 -----------------------------------------------------------------------------------

RENAME_NOREPLACE, RENAME_EXCHANGE = 1, 2
_AT_FDCWD = -100
_UNSUPPORTED = {errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP}
_libc_fn = None


def _renameat2_fn():
    global _libc_fn
    if _libc_fn is None:
        fn = False
        if sys.platform.startswith("linux"):
            try:
                libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
                fn = libc.renameat2
                fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                               ctypes.c_uint]
                fn.restype = ctypes.c_int
            except (OSError, AttributeError):
                fn = False
        _libc_fn = fn
    return _libc_fn


def _renameat2(src, dst, flags):
    """True when done; False when the kernel or the file system does not offer it."""
    fn = _renameat2_fn()
    if not fn or FORCE_FALLBACK:
        return False
    if fn(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in _UNSUPPORTED and os.path.lexists(src) and os.path.lexists(os.path.dirname(
            os.path.abspath(dst))):
        return False
    raise OSError(err, os.strerror(err), str(src), None, str(dst))


def rename_noreplace(src, dst):
    """Rename ``src`` to ``dst``, failing with ``FileExistsError`` if ``dst`` exists.

    ``renameat2(RENAME_NOREPLACE)`` is atomic. The fallback checks and renames; POSIX
    ``rename`` never replaces a non-empty directory, so what it could replace in the gap is an
    empty directory."""
    if _renameat2(src, dst, RENAME_NOREPLACE):
        return
    if os.path.lexists(dst):
        raise FileExistsError(errno.EEXIST, "File exists", str(dst))
    if os.path.isdir(src) and not os.path.islink(src):
        os.rename(src, dst)
    else:  # a file: link() fails atomically when dst exists
        os.link(src, dst, follow_symlinks=False)
        os.unlink(src)


def rename_exchange(a, b):
    """Swap ``a`` and ``b`` atomically; False when ``renameat2`` is not available here."""
    return _renameat2(a, b, RENAME_EXCHANGE)


# --- signals -------------------------------------------------------------------------------------

@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block SIGTERM raises :class:`Terminated` (a ``KeyboardInterrupt``) in the
    main thread, so a terminated command cleans up like an interrupted one."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise Terminated(f"terminated by signal {signum}")

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


@contextlib.contextmanager
def _signals_deferred():
    """SIGINT and SIGTERM wait until the renames of a commit are done."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


# --- the lock ------------------------------------------------------------------------------------

def _lock_path(target):
    target = Path(target)
    return target.parent / f".{target.name}.lock"


def _holder_text(command):
    return json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                       "command": command, "since": time.strftime("%Y-%m-%dT%H:%M:%S%z")})


def _describe_holder(raw):
    try:
        info = json.loads(raw)
        return (f"process {int(info['pid'])} on {info['host']} ({info['command']}, since "
                f"{info['since']})")
    except (ValueError, KeyError, TypeError):
        return "another process"


def _open_lock(path):
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, _file_mode())
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise RefusedError(f"lock file {path} is a symbolic link; refusing to use it") \
                from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1 or st.st_size > 4096:
        os.close(fd)
        raise RefusedError(f"{path} is not a refraster lock file (not a small regular file "
                           "with one link); refusing to use it")
    return fd


@contextlib.contextmanager
def locked(target, *, wait=True, command="refraster", on_wait=None):
    """Hold the advisory lock of ``target`` (``.NAME.lock`` beside it) within the block.

    ``wait=False``: raise :class:`LockedError` naming the holder if another process holds it.
    ``on_wait(holder)`` is called (with a description of the holder) before waiting.
    """
    path = _lock_path(target)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = _open_lock(path)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _describe_holder(os.pread(fd, 4096, 0).decode("utf-8", "replace"))
                if not wait:
                    raise LockedError(f"{target} is being written by {holder} (lock {path}); "
                                      "try again when it has finished, or leave out "
                                      "--no-wait to wait for it") from None
                if on_wait is not None:
                    on_wait(holder)
                _hook("waiting", target=target, holder=holder)
                fcntl.flock(fd, fcntl.LOCK_EX)
            # the previous holder removes the file when done: lock the file that is there
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False))
            except FileNotFoundError:
                same = False
        except BaseException:
            os.close(fd)
            raise
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, _holder_text(command).encode("utf-8"), 0)
        yield path
    finally:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
        os.close(fd)


# --- targets and what is at them -----------------------------------------------------------------

def resolve_target(out, what="--out"):
    """The real path a write to ``out`` goes to: a symlink at ``out`` is followed (the
    directory it points to is updated, the link stays); a dangling link is refused."""
    out = Path(out)
    if out.is_symlink() and not out.exists():
        raise RefusedError(f"{what} {out} is a symbolic link to {os.readlink(out)}, which does "
                           "not exist; refusing to write through it")
    return Path(os.path.realpath(out))


def _kind(mode):
    for test, word in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISDIR, "a directory")):
        if test(mode):
            return word
    return "not a regular file"


def check_regular_output(path, what):
    """Refuse (:class:`RefusedError`, one line naming ``what``) an output path where something
    other than a regular file is: a FIFO, a socket, a device, a directory, or a link to one of
    them. Nothing is opened (a FIFO is never blocked on) and nothing is written. Nothing there,
    a regular file, or a link to one is accepted (the link is replaced, as before)."""
    try:
        st = os.stat(path)      # through a link: what a write would reach
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise RefusedError(f"{what} cannot be checked ({exc.strerror}); refusing to write "
                           "there") from None
    if stat.S_ISREG(st.st_mode):
        return path
    if stat.S_ISDIR(st.st_mode):
        raise RefusedError(f"{what} is a directory")
    raise RefusedError(f"{what} is {_kind(st.st_mode)}, not a regular file; refraster writes "
                       "only regular files (use '-' for standard output)")


def _sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


_LISTINGS = (("report", REPORT_MARKER, "refraster golden compare", "report marker"),
             ("golden", MANIFEST, None, "golden manifest"),
             ("candidate", CANDIDATE_MARKER, "refraster golden candidate", "candidate marker"))


def _listing(tree):
    """``(kind, digest, files, hashes)`` of a tree refraster wrote: files its report marker or
    golden manifest lists (relative paths, the listing file included) and their sha256;
    ``None`` if it has neither. A listing file that is there but cannot be trusted (a link,
    not a regular file, larger than :data:`~.safe.MAX_SIDE_FILE_BYTES`, not JSON, nested too
    deeply, an integer beyond the conversion limit, or breaking its schema) is refused with
    :class:`RefusedError`, one line naming it, before anything it lists is read."""
    from .safe import read_json_file
    from .schema import (CANDIDATE_MARKER_SCHEMA, LISTING_SCHEMA, REPORT_MARKER_SCHEMA,
                         SchemaError, validate)
    schemas = {"report": REPORT_MARKER_SCHEMA, "golden": LISTING_SCHEMA,
               "candidate": CANDIDATE_MARKER_SCHEMA}
    tree = Path(tree)
    for kind, name, writer, what in _LISTINGS:
        path = tree / name
        if not os.path.lexists(path):
            continue
        doc, raw = read_json_file(path, RefusedError, what)
        if writer is not None and (not isinstance(doc, dict) or doc.get("written_by") != writer):
            continue
        try:
            validate(doc, schemas[kind])
        except SchemaError as exc:
            raise RefusedError(f"{what} {path} {exc}; refusing to trust it") from None
        except RecursionError:
            raise RefusedError(f"{what} {path}: JSON nested too deeply; refusing to trust "
                               "it") from None
        files = doc["files"]
        return kind, hashlib.sha256(raw).hexdigest(), set(files) | {name}, files
    return None


def _tree_files(tree):
    """Relative paths of every non-directory entry under ``tree`` (links not followed)."""
    out = set()
    for dirpath, dirnames, filenames in os.walk(tree, followlinks=False):
        rel = Path(dirpath).relative_to(tree)
        for name in filenames:
            out.add((rel / name).as_posix())
        for name in dirnames:
            if os.path.islink(os.path.join(dirpath, name)):
                out.add((rel / name).as_posix())
    return out


def snapshot(target):
    """What is at ``target``, to be compared at the final step: ``None`` (nothing),
    ``("empty",)``, ``(kind, digest, foreign)`` for a golden or report refraster wrote
    (``foreign``: files it does not list, then listed files whose sha256 differs),
    ``("file",)`` or ``("foreign", names)``. Raises :class:`RefusedError` (one line) for a
    marker or manifest not to trust (:func:`_listing`) or a file it lists that is not a
    regular file (a FIFO is refused, never opened for reading)."""
    target = Path(target)
    if not os.path.lexists(target):
        return None
    if target.is_symlink() or not target.is_dir():
        return ("file",)
    files = _tree_files(target)
    if not files and not any(target.iterdir()):
        return ("empty",)
    listing = _listing(target)
    if listing is None:
        return ("foreign", tuple(sorted(files)[:5]))
    kind, digest, owned, hashes = listing
    from .safe import sha256_regular
    changed = [rel for rel, h in sorted(hashes.items())
               if rel in files and (os.path.islink(target / rel)
                                      or sha256_regular(target / rel, RefusedError,
                                                        f"{kind} file") != h)]
    return (kind, digest, tuple(sorted(files - owned)) + tuple(changed))


# --- temporary trees, debris, journal ------------------------------------------------------------

def make_tree(target):
    """A new temporary directory ``.NAME.tmp-PID-…`` beside ``target`` (same file system)."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-{os.getpid()}-",
                                 dir=target.parent))


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _debris_owner(name, prefix):
    """The pid in ``.NAME.tmp-PID-…`` (``None`` if the name carries none)."""
    head = name[len(prefix):].split("-", 1)[0]
    return int(head) if head.isdigit() else None


def _kept_name(path, target_name):
    stamp = time.strftime("%Y%m%dT%H%M%S")
    base = Path(path).parent / f"{target_name}.kept-{stamp}"
    candidate, n = base, 1
    while os.path.lexists(candidate):
        candidate = base.with_name(f"{base.name}-{n}")
        n += 1
    return candidate


def discard_tree(tree, target_name=None, *, building=False):
    """Remove a tree refraster wrote: only the files its manifest or report marker lists (all
    of it for a tree still being built, ``building=True``, which has no listing yet), then the
    directories left empty. Anything else is kept: the tree is renamed to ``NAME.kept-…`` and
    that path returned (else ``None``)."""
    tree = Path(tree)
    if not os.path.lexists(tree):
        return None
    if tree.is_symlink() or not tree.is_dir():
        os.unlink(tree)
        return None
    try:
        listing = _listing(tree)
    except RefusedError:        # a listing not to trust owns nothing: the tree is kept
        listing = None
    if listing is None and building:
        shutil.rmtree(tree)
        return None
    owned = listing[2] if listing is not None else set()
    # the listing file goes last: a crash half-way leaves a tree that still says what it owns
    listing_file = ({"report": REPORT_MARKER, "golden": MANIFEST,
                     "candidate": CANDIDATE_MARKER}[listing[0]] if listing else None)
    real = os.path.realpath(tree)
    for rel in sorted(owned - {listing_file}) + ([listing_file] if listing_file else []):
        path = tree / rel
        # never through a linked directory: the file must be where the listing says
        if os.path.realpath(path.parent) != os.path.normpath(os.path.join(real, Path(rel).parent)):
            continue
        if path.is_symlink() or path.is_file():
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)
    for dirpath, _, _ in sorted(os.walk(tree, topdown=False, followlinks=False),
                                key=lambda w: -len(Path(w[0]).parts)):
        with contextlib.suppress(OSError):
            os.rmdir(dirpath)
    if os.path.lexists(tree):
        kept = _kept_name(tree, target_name or tree.name.lstrip("."))
        os.rename(tree, kept)
        return kept
    return None


def _journal_path(target):
    target = Path(target)
    return target.parent / f".{target.name}.journal"


def _debris(target):
    target = Path(target)
    prefixes = (f".{target.name}.tmp-", f".{target.name}.old-")
    return sorted(p for p in target.parent.iterdir() if p.name.startswith(prefixes))


def recover(target, *, wait=True, command="refraster"):
    """Finish a swap a dead run left half-done (two renames and a journal, where ``renameat2``
    is missing): the new tree is moved into place (roll forward) or, if it is gone, the old one
    back. Takes the lock only when there is a journal. Returns what it did or ``None``.

    Only a command that may write ``target`` calls this (``golden generate`` on its ``--out``,
    ``golden candidate`` on its ``--out``); a command that only reads a directory never acts on
    a journal beside it (:func:`pending_swap`). The journal is trusted only when it is a small
    regular file (not a link) naming exactly the target and two trees beside it that a swap
    of this target makes (``.NAME.tmp-PID-…`` and ``.NAME.old-PID-…``), neither a link."""
    target = Path(os.path.realpath(target))
    if not os.path.lexists(_journal_path(target)):
        return None
    with locked(target, wait=wait, command=command):
        return _recover_locked(target)


def pending_swap(target, what="golden directory"):
    """For a command that only reads ``target``: refuse (:class:`GoldenError`, one line) when
    ``target`` is missing and a journal lies beside it (a swap stopped between its two renames),
    saying which command finishes it. Reads nothing but the two names; acts on nothing."""
    target = Path(os.path.realpath(target))
    journal = _journal_path(target)
    if os.path.lexists(journal) and not os.path.lexists(target):
        raise GoldenError(f"{what} {target} is missing and the journal {journal} lies beside "
                          "it: a `refraster golden generate` was stopped in the middle of "
                          f"replacing it; run `refraster golden generate --out {target} "
                          "--update` (it finishes the swap first), or move the journal away")


#: Largest journal read (one written by :func:`_swap_with_journal` is under 1 KiB).
JOURNAL_MAX_BYTES = 4096


def _read_journal(journal, target):
    """The ``(new, old)`` names of a journal refraster wrote for ``target``, or a
    :class:`RefusedError` naming what is wrong with it (nothing is acted on)."""
    def refuse(why):
        return RefusedError(f"journal {journal} is not one refraster wrote ({why}); refusing to "
                            "act on it (move it away by hand)")

    try:
        fd = os.open(journal, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise refuse("it is a symbolic link") from None
        raise refuse(exc.strerror) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise refuse(f"it is {_kind(st.st_mode)}, not a regular file")
        if st.st_size > JOURNAL_MAX_BYTES:
            raise refuse(f"it is larger than {JOURNAL_MAX_BYTES} bytes")
        raw = os.read(fd, JOURNAL_MAX_BYTES + 1)
    finally:
        os.close(fd)
    if len(raw) > JOURNAL_MAX_BYTES:
        raise refuse(f"it is larger than {JOURNAL_MAX_BYTES} bytes")
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise refuse("not JSON") from None
    if not isinstance(doc, dict) or sorted(doc) != ["new", "old", "target"]:
        raise refuse("its fields must be exactly target, new and old")
    if doc["target"] != target.name:
        raise refuse(f"it names the target {doc['target']!r}, not {target.name!r}")
    names = []
    for key, kind in (("new", "tmp"), ("old", "old")):
        value = doc[key]
        pattern = rf"\.{re.escape(target.name)}\.{kind}-[0-9]+-[A-Za-z0-9_]+"
        if not isinstance(value, str) or re.fullmatch(pattern, value) is None:
            raise refuse(f"{key} must name a .{target.name}.{kind}-PID-… tree beside the "
                         f"target, got {value!r}"[:300])
        path = target.parent / value
        if os.path.islink(path):
            raise refuse(f"{key} {path} is a symbolic link")
        if os.path.lexists(path) and not path.is_dir():
            raise refuse(f"{key} {path} is not a directory")
        names.append(value)
    return names


def _recover_locked(target):
    journal = _journal_path(target)
    if not os.path.lexists(journal):
        return None
    names = _read_journal(journal, target)
    new, old = (target.parent / n for n in names)
    done = None
    with _signals_deferred():
        if not os.path.lexists(target):
            if os.path.lexists(new):
                os.rename(new, target)
                done = "rolled forward"
            elif os.path.lexists(old):
                os.rename(old, target)
                done = "rolled back"
        else:
            done = "completed"
        os.unlink(journal)
    if done != "rolled back" and os.path.lexists(old):
        discard_tree(old, target.name)  # the tree the new one replaced
    return done


def clean_debris(target):
    """Remove temporary trees of dead runs on ``target``. Call with the lock held (a live
    ``generate`` holds it for its whole run); a tree whose name carries the pid of a live
    process (a report still being built, before its commit takes the lock) is left alone."""
    _recover_locked(target)
    kept = []
    name = Path(target).name
    for path in _debris(target):
        prefix = f".{name}.tmp-" if path.name.startswith(f".{name}.tmp-") else f".{name}.old-"
        pid = _debris_owner(path.name, prefix)
        if pid is not None and _pid_alive(pid):
            continue
        k = discard_tree(path, name, building=True)
        if k is not None:
            kept.append(k)
    return kept


# --- committing a tree ---------------------------------------------------------------------------

def _same(found, now):
    return found == now


def _describe(found):
    if found is None:
        return "nothing"
    if found[0] == "empty":
        return "an empty directory"
    if found[0] in ("golden", "report", "candidate"):
        return f"a {found[0]} (digest {found[1][:12]}…)"
    if found[0] == "foreign":
        return f"a directory holding {', '.join(found[1])}"
    return "a file"


def _refuse_changed(target, found, now, what):
    extra = ""
    if now is not None and now[0] in ("golden", "report") and now[2]:
        extra = (f"; it now holds files refraster did not write or that changed since: "
                 f"{', '.join(now[2][:5])}")
    return RefusedError(f"{target} changed while {what} ran (found {_describe(found)}, now "
                        f"{_describe(now)}{extra}); refusing to replace it, nothing was deleted")


def commit_tree(tmp, target, found, *, what="refraster"):
    """Put the finished tree ``tmp`` at ``target``, which must still be what :func:`snapshot`
    gave when the writer started (``found``). Call with the lock held.

    On success ``tmp`` no longer exists (the tree it replaced is removed file by file). On
    failure (refused or an OS error) ``tmp`` still holds the new tree and ``target`` is as it
    was."""
    tmp, target = Path(tmp), Path(target)
    os.chmod(tmp, dir_mode())
    _, finish = _swap_in(tmp, target, found, what)
    finish()


def _swap_in(tmp, target, found, what):
    """The renames of a commit: returns ``(undo, finish)``; ``undo()`` puts the old state back,
    ``finish()`` removes what the commit replaced."""
    with _signals_deferred():
        now = snapshot(target)
        if not _same(found, now):
            raise _refuse_changed(target, found, now, what)
        _hook("before_swap", target=target, tmp=tmp)
        if found is None:
            try:
                rename_noreplace(tmp, target)
            except FileExistsError:
                raise _refuse_changed(target, found, snapshot(target), what) from None

            def undo():
                rename_noreplace(target, tmp)
            return undo, lambda: None
        if rename_exchange(tmp, target):
            _hook("after_swap", target=target, old=tmp)
            # ``tmp`` now holds what was at the target: is it still what we found?
            if not _same(found, snapshot(tmp)):
                now = snapshot(tmp)
                if not rename_exchange(tmp, target):
                    raise OSError(f"could not swap {target} back")
                raise _refuse_changed(target, found, now, what)

            def undo():
                rename_exchange(tmp, target)
            return undo, lambda: discard_tree(tmp, target.name)
        return _swap_with_journal(tmp, target, found, what)


def _swap_with_journal(tmp, target, found, what):
    journal = _journal_path(target)
    old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-{os.getpid()}-",
                                dir=target.parent))
    os.rmdir(old)  # a free name on the same file system
    text = json.dumps({"target": target.name, "new": tmp.name, "old": old.name})
    fd = os.open(journal, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, _file_mode())
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    try:
        os.rename(target, old)
    except BaseException:
        os.unlink(journal)
        raise
    _hook("between_renames", target=target, old=old, new=tmp)
    try:
        os.rename(tmp, target)
    except BaseException:
        os.rename(old, target)
        os.unlink(journal)
        raise
    os.unlink(journal)
    _hook("after_swap", target=target, old=old)
    if not _same(found, snapshot(old)):
        now = snapshot(old)
        os.rename(target, tmp)
        os.rename(old, target)
        raise _refuse_changed(target, found, now, what)

    def undo():
        os.rename(target, tmp)
        os.rename(old, target)
    return undo, lambda: discard_tree(old, target.name)


# --- several outputs of one command --------------------------------------------------------------

def _clean_file_debris(path):
    prefix = f".{path.name}.tmp-"
    for p in path.parent.iterdir():
        if p.name.startswith(prefix) and not p.is_symlink() and p.is_file():
            pid = _debris_owner(p.name, prefix)
            if pid is not None and not _pid_alive(pid):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(p)


class Outputs:
    """The outputs of one command, committed together.

    ``file(path, data)`` and ``tree(tmp, target, ...)`` stage; ``commit()`` renames them in
    order. If a step fails, the outputs already renamed are undone (new files removed, the
    files they replaced restored, trees swapped back) and every staged temporary removed. The
    window that remains: a process killed (SIGKILL, power loss) in the middle of ``commit()``
    leaves the outputs renamed so far in place and the replaced files as ``.NAME.bak-…``
    beside them (kept: they hold the data that was replaced).
    """

    def __init__(self, *, wait=True, command="refraster"):
        self._items = []
        self._wait = wait
        self._command = command

    def file(self, path, data):
        """Stage ``data`` for ``path`` (a temporary file ``.NAME.tmp-PID-…`` beside it; those
        of dead processes, never committed, are removed first)."""
        path = Path(path)
        check_regular_output(path, str(path))
        path.parent.mkdir(parents=True, exist_ok=True)
        _clean_file_debris(path)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-{os.getpid()}-", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, _file_mode())
        except BaseException:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            raise
        self._items.append(("file", Path(tmp), path, None))
        return path

    def tree(self, tmp, target, *, check=None):
        """Stage the finished directory ``tmp`` for ``target``; at commit, under the target's
        lock, ``check(target)`` returns what must be at the target (a :func:`snapshot`) or
        raises."""
        self._items.append(("tree", Path(tmp), Path(target), check))
        return Path(target)

    def discard(self):
        """Remove every staged temporary (nothing was committed)."""
        for kind, tmp, target, _ in self._items:
            if kind == "file":
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(tmp)
            else:
                with contextlib.suppress(FileNotFoundError):
                    discard_tree(tmp, target.name, building=True)
        self._items = []

    def commit(self):
        """Rename every staged output into place, or none of them (see the class)."""
        done, finishes = [], []
        with contextlib.ExitStack() as locks:
            try:
                for kind, tmp, target, check in self._items:
                    if kind == "tree":
                        locks.enter_context(locked(target, wait=self._wait,
                                                   command=self._command))
                        clean_debris(target)
                # no signal between a rename and the note of how to undo it
                with _signals_deferred():
                    try:
                        for index, (kind, tmp, target, check) in enumerate(self._items):
                            _hook("commit_step", index=index, target=target)
                            if kind == "file":
                                undo, finish = self._commit_file(tmp, target)
                            else:
                                found = check(target) if check is not None else \
                                    snapshot(target)
                                os.chmod(tmp, dir_mode())
                                undo, finish = _swap_in(tmp, target, found, self._command)
                            done.append(undo)
                            finishes.append(finish)
                    except BaseException:
                        for undo in reversed(done):
                            undo()
                        raise
            except BaseException:
                self.discard()
                raise
            self._items = []
            for finish in finishes:  # what was replaced; debris for the next run if this fails
                with contextlib.suppress(OSError):
                    finish()

    @staticmethod
    def _commit_file(tmp, target):
        backup = None
        with _signals_deferred():
            check_regular_output(target, str(target))   # what may have appeared since staging
            if os.path.lexists(target) and not os.path.isdir(target):
                fd, name = tempfile.mkstemp(prefix=f".{target.name}.bak-", dir=target.parent)
                os.close(fd)
                backup = Path(name)
                try:
                    os.replace(target, backup)  # keeps the old file (and its inode) aside
                except BaseException:
                    os.unlink(backup)
                    raise
            try:
                os.replace(tmp, target)
            except BaseException:
                if backup is not None:
                    os.replace(backup, target)
                raise

        def undo():
            if backup is not None:
                os.replace(backup, target)
            else:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(target)

        def finish():
            if backup is not None:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(backup)
        return undo, finish


# --- output paths of compare ---------------------------------------------------------------------

def _overlaps(a, b):
    return a == b or a.is_relative_to(b) or b.is_relative_to(a)


def check_output_path(path, option, protected):
    """Refuse an output file inside (or equal to) a protected directory, or that is a
    directory. ``protected``: ``{description: path}``."""
    real = Path(os.path.realpath(path))
    for what, root in protected.items():
        if root is None:
            continue
        root = Path(os.path.realpath(root))
        if real == root or real.is_relative_to(root):
            raise GoldenError(f"{option} {path} is inside the {what} {root}; refraster never "
                              "writes there, choose another path")
    if os.path.isdir(real):
        raise GoldenError(f"{option} {path} is a directory")
    return real


def check_report_dir(report, golden_dir, candidate_dir):
    """Refuse a report directory that overlaps the golden or candidate directory, or that
    holds anything but a report refraster wrote (its marker lists every file in it). Returns
    its :func:`snapshot` (what the commit expects to find)."""
    rep = Path(os.path.realpath(report))
    for other in (golden_dir, candidate_dir):
        other = Path(os.path.realpath(other))
        if _overlaps(rep, other):
            raise GoldenError(f"report directory {report} overlaps {other}; choose another")
    found = snapshot(rep)
    if found is None or found[0] == "empty":
        return found
    if found[0] == "file":
        raise GoldenError(f"report path {report} exists and is not a directory")
    if found[0] == "report" and not found[2]:
        return found
    if found[0] == "report":
        raise GoldenError(f"report directory {report} holds files refraster did not write or "
                          f"that changed since ({', '.join(found[2][:5])}); refusing to replace "
                          "it")
    raise GoldenError(f"report directory {report} is not empty and was not written by "
                      f"refraster (no {REPORT_MARKER} marker listing its files); refusing to "
                      "replace it")


def _write_marker(tmp):
    files = {rel: _sha256(Path(tmp) / rel) for rel in sorted(_tree_files(tmp))
             if rel != REPORT_MARKER}
    doc = {"written_by": "refraster golden compare", "files": files}
    (Path(tmp) / REPORT_MARKER).write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n",
                                           encoding="utf-8")


def commit_report(tmp, report_dir, outputs=None, *, golden_dir=None, candidate_dir=None,
                  wait=True):
    """Commit the finished report tree ``tmp`` to ``report_dir``: now (under its lock), or as
    part of ``outputs`` (:class:`Outputs`). Writes the marker that lets a later report replace
    it. Returns the report directory (its real path)."""
    target = resolve_target(report_dir, "report directory")
    _write_marker(tmp)

    def check(t):
        if golden_dir is None or candidate_dir is None:
            return _report_check(t)
        return check_report_dir(t, golden_dir, candidate_dir)

    if outputs is not None:
        outputs.tree(tmp, target, check=check)
        return target
    own = Outputs(wait=wait, command="refraster golden compare --report")
    own.tree(tmp, target, check=check)
    own.commit()
    return target


def _report_check(target):
    found = snapshot(target)
    if found is None or found[0] == "empty" or (found[0] == "report" and not found[2]):
        return found
    raise GoldenError(f"report directory {target} holds something refraster did not write; "
                      "refusing to replace it")
