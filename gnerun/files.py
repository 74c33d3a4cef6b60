"""Reading and writing gnerun's files safely.

- Reads take regular files only, with a size cap: a device (``/dev/zero``) is refused before a byte is read,
  and a FIFO is opened without blocking and refused too.
- Writes never follow a symbolic link planted where a file is written (``O_NOFOLLOW``): the link is refused
  with one message, and what it points to is left alone.
- A file that readers may look at while it is written (summary.json, the sweep index) is written to a
  temporary file beside it and moved into place; the temporary file is removed on every exit.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from .errors import InputError

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


class LinkRefused(InputError):
    """A symbolic link stands where gnerun writes a file."""


def _refuse_link(path: Path) -> LinkRefused:
    return LinkRefused(f"{path}: is a symbolic link; gnerun does not write through one (remove it, or choose "
                       "another output)")


def not_a_link(path: str | Path) -> None:
    """Refuse a symbolic link planted at ``path`` (a directory gnerun writes into, reached through a link, would put
    its files elsewhere)."""
    if Path(path).is_symlink():
        raise _refuse_link(Path(path))


def open_fd(path: str | Path, flags: int = os.O_WRONLY, *, exclusive: bool = False) -> int:
    """A file descriptor of ``path`` (created if missing) opened with ``flags``, never through a symbolic link,
    and only if it is (or becomes) a regular file: a planted FIFO or device is refused too."""
    p = Path(path)
    flags |= os.O_CREAT | _NOFOLLOW | _CLOEXEC | _NONBLOCK | (os.O_EXCL if exclusive else 0)
    try:
        fd = os.open(p, flags, 0o666)
    except OSError as e:
        if e.errno == errno.ELOOP or (e.errno == errno.EEXIST and p.is_symlink()):
            raise _refuse_link(p) from None
        if e.errno == errno.ENXIO:  # a FIFO with no reader
            raise InputError(f"{p}: is a FIFO, not a regular file") from None
        raise
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f"{p}: is {_kind(mode)}, not a regular file")
        os.set_blocking(fd, True)
        return fd
    except BaseException:
        os.close(fd)
        raise


def open_for_writing(path: str | Path, *, exclusive: bool = False) -> BinaryIO:
    """``path`` opened for writing in binary, created or emptied (``exclusive``: created, and refused if it
    exists), as :func:`open_fd` opens it."""
    fd = open_fd(path, os.O_WRONLY, exclusive=exclusive)
    try:
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        raise


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` (see :func:`open_for_writing`)."""
    with open_for_writing(path) as f:
        f.write(data)


def write_text(path: str | Path, text: str) -> None:
    write_bytes(path, text.encode())


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[BinaryIO]:
    """A file to write that replaces ``path`` at once when the block ends without an error: it is written as
    ``<name>.tmp`` beside it (a stale one, or a link planted there, is removed first: the name is gnerun's) and
    moved into place; on any exit the temporary file is gone. Replacing a link at ``path`` replaces the link,
    never what it points to."""
    target = Path(path)
    tmp = target.with_name(target.name + ".tmp")
    with contextlib.suppress(FileNotFoundError):
        os.unlink(tmp)  # never follows a link
    try:
        with open_for_writing(tmp, exclusive=True) as f:
            yield f
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def replace_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`replacing`)."""
    with replacing(path) as f:
        f.write(text.encode())


def read_regular(path: str | Path, limit: int, what: str = "file") -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them. Anything else is an InputError in one
    line: a missing file, a directory, a device or a FIFO (opened without blocking), a file larger than
    ``limit`` (checked before reading, and again while reading, for files that grow)."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | _CLOEXEC | _NONBLOCK)
    except FileNotFoundError:
        raise InputError(f"{p}: no such file (a {what} was expected)") from None
    except OSError as e:
        raise InputError(f"{p}: cannot read: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{p}: is {_kind(st.st_mode)}, not a {what}")
        if st.st_size > limit:
            raise InputError(f"{p}: the {what} is {st.st_size} bytes; the limit is {limit}")
        os.set_blocking(fd, True)
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > limit:
            raise InputError(f"{p}: the {what} is more than {limit} bytes; the limit is {limit}")
        return b"".join(chunks)
    except OSError as e:
        raise InputError(f"{p}: cannot read: {e.strerror or e}") from None
    finally:
        os.close(fd)


MAX_JSON_BYTES = 256 * 2**20  # a summary.json of a long closed loop is tens of MB


def read_json_object(path: str | Path, what: str | None = None, limit: int = MAX_JSON_BYTES) -> dict:
    """The JSON object in ``path`` (summary.json, sweep.json, point.json); a file that is not one (invalid
    JSON, a list, a special file, too large) is an InputError that says it is damaged."""
    import json

    p = Path(path)
    what = what or p.name
    data = read_regular(p, limit, what)
    try:
        value = json.loads(data)
    except (ValueError, RecursionError) as e:
        raise InputError(f"{p}: damaged {what}: not valid JSON ({str(e).splitlines()[0][:80]})") from None
    if not isinstance(value, dict):
        raise InputError(f"{p}: damaged {what}: a JSON {type(value).__name__}, not an object")
    return value


def output_directory(path: str | Path, what: str = "output directory", *, create: bool = True) -> Path:
    """``path`` as a directory to write into, created if missing (``create=False``: only checked, the nearest
    existing ancestor standing in for it); a file there, or a place where no directory can be made or written
    (``/proc``, a read-only disk), is an InputError in one line."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{p}: exists and is not a directory (the {what} must be one)")
    if not create:
        existing = next((a for a in (p, *p.absolute().parents) if a.exists()), Path("/"))
        if not existing.is_dir():
            raise InputError(f"{existing}: is not a directory, so {p} cannot be created (the {what})")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise InputError(f"{p}: cannot create the {what}: permission denied in {existing}")
        return p
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{p}: cannot create the {what}: {e.strerror or e}") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise InputError(f"{p}: cannot write into the {what}: permission denied")
    return p


def replaceable_file(path: str | Path, what: str = "output file") -> Path:
    """``path`` as a file that :func:`replacing` will put in place whole: what stands there now may only be a regular
    file (a directory, a device or a FIFO is never replaced by a file, a link never written through), and its
    directory must exist or be creatable, and take the temporary file beside it (created and removed here)."""
    p = Path(path)
    try:
        mode = os.lstat(p).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as e:
        raise InputError(f"{p}: cannot write the {what}: {e.strerror or e}") from None
    if mode is not None and stat.S_ISLNK(mode):
        raise _refuse_link(p)
    if mode is not None and not stat.S_ISREG(mode):
        raise InputError(f"{p}: is {_kind(mode)}; the {what} is a regular file")
    output_directory(p.parent, f"directory of the {what}")
    tmp = p.with_name(p.name + ".tmp")
    try:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)  # a stale one of gnerun's; never follows a link
        os.close(open_fd(tmp, exclusive=True))
        os.unlink(tmp)
    except OSError as e:
        raise InputError(f"{p}: cannot write the {what}: {e.strerror or e}") from None
    return p


def output_file(path: str | Path, what: str = "output file") -> Path:
    """``path`` as a file to be written by another library (a recording, an image): it must not be a directory,
    a link or a special file, and its directory must exist or be creatable; it is created (empty) here if it is
    missing, and left as it is otherwise, so that a target that cannot work is one message before any work is
    done."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a directory; the {what} is a file (e.g. {p / 'replay.rrd'})")
    output_directory(p.parent, f"directory of the {what}")
    try:
        os.close(open_fd(p))
    except OSError as e:
        raise InputError(f"{p}: cannot write the {what}: {e.strerror or e}") from None
    return p
