"""Atomic file output: write a temporary file beside the target, then rename it over."""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def _file_mode(target: Path) -> int:
    """The permissions the target keeps if it exists, else those a new file gets (0o666 less
    the umask); ``mkstemp`` itself creates files readable by their owner alone."""
    try:
        return stat.S_IMODE(target.stat().st_mode)
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def check_replaceable(path: str | os.PathLike) -> None:
    """Raise ``PermissionError`` naming ``path`` if it is a file that may not be written:
    ``open`` would refuse it (``os.access``), or none of its write bits is set, which only
    root's ``open`` ignores. An atomic write's rename would replace it regardless of either."""
    try:
        mode = os.stat(path).st_mode
    except OSError:  # no such file (or a path the write itself will report)
        return
    if not os.access(path, os.W_OK) or not mode & 0o222:
        raise PermissionError(
            errno.EACCES, "cannot write: the file is read-only (chmod u+w allows it)", str(path)
        )


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, so writers that go by it still can) to
    write to; renamed over ``path`` when the block ends, removed if it raises. Readers see the
    old file or the new one, never half. The file gets ``path``'s permissions (``_file_mode``);
    a read-only file is not replaced (``check_replaceable``). An ``OSError`` names ``path``, not
    the temporary."""
    target = Path(path)
    check_replaceable(target)

    def failed(error: OSError) -> OSError:
        return OSError(error.errno, f"cannot write: {error.strerror}", str(target))

    try:
        handle, temporary = tempfile.mkstemp(
            prefix=f".{target.stem}.", suffix=target.suffix, dir=target.parent
        )
    except OSError as error:
        raise failed(error) from None
    os.close(handle)
    try:
        yield Path(temporary)
        try:
            os.chmod(temporary, _file_mode(target))
            os.replace(temporary, target)
        except OSError as error:
            raise failed(error) from None
    finally:
        Path(temporary).unlink(missing_ok=True)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (``atomic_path``)."""
    with atomic_path(path) as temporary:
        temporary.write_text(text)
