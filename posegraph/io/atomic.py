"""Atomic file output: write a temporary file beside the target, then rename it over; several
outputs of one command all at once (``output_batch``); devices and FIFOs written through."""

from __future__ import annotations

import contextvars
import errno
import os
import shutil
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


def is_special(path: str | os.PathLike) -> bool:
    """Whether ``path`` (its symlinks followed) exists and is not a regular file: a device, a
    FIFO or a socket, which a write goes through to and a rename would replace."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _failed(error: OSError, target: Path) -> OSError:
    """``error`` naming the output ``target``, not a temporary."""
    return OSError(error.errno, f"cannot write: {error.strerror or error}", str(target))


class _Staged:
    """A complete temporary file waiting to become ``target``."""

    def __init__(self, temporary: Path, target: Path, special: bool, name: Path) -> None:
        self.temporary, self.target, self.special, self.name = temporary, target, special, name

    def write_through(self) -> None:
        """Copy the temporary into the device or FIFO ``target`` (opened, never replaced)."""
        try:
            with open(self.temporary, "rb") as source, open(self.target, "wb") as sink:
                shutil.copyfileobj(source, sink)
        except OSError as error:
            raise _failed(error, self.name) from None

    def rename(self) -> None:
        try:
            os.chmod(self.temporary, _file_mode(self.target))
            os.replace(self.temporary, self.target)
        except OSError as error:
            raise _failed(error, self.name) from None

    def discard(self) -> None:
        self.temporary.unlink(missing_ok=True)


class OutputBatch:
    """The outputs of one command, staged as complete temporaries and committed together:
    the writes through to devices first (they can fail: ``/dev/full``), then the renames,
    which cannot fail for want of space. A failure while staging replaces no file."""

    def __init__(self) -> None:
        self.staged: list[_Staged] = []

    def commit(self) -> list[str]:
        """Put every staged output in place; returns their paths."""
        try:
            for staged in self.staged:
                if staged.special:
                    staged.write_through()
            for staged in self.staged:
                if not staged.special:
                    staged.rename()
        finally:
            self.discard()
        return [str(staged.name) for staged in self.staged]

    def discard(self) -> None:
        for staged in self.staged:
            staged.discard()


_BATCH: contextvars.ContextVar[OutputBatch | None] = contextvars.ContextVar("batch", default=None)


class InterruptedAfterWriting(KeyboardInterrupt):
    """Ctrl-C stopped a command after some of its outputs were complete; those were written
    (``paths``), the others not."""

    def __init__(self, paths: list[str]) -> None:
        super().__init__(paths)
        self.paths = paths


@contextmanager
def output_batch() -> Iterator[OutputBatch]:
    """Within the block, every ``atomic_path`` is staged and the batch committed when the block
    ends: all outputs are written or, if it raises, none is replaced. Ctrl-C (``KeyboardInterrupt``)
    commits the outputs already complete (a converged result is not lost to a later phase) and
    raises ``InterruptedAfterWriting`` naming them, if there were any."""
    batch = OutputBatch()
    token = _BATCH.set(batch)
    try:
        yield batch
    except KeyboardInterrupt:
        if not batch.staged:
            raise
        raise InterruptedAfterWriting(batch.commit()) from None
    except BaseException:
        batch.discard()
        raise
    else:
        batch.commit()
    finally:
        _BATCH.reset(token)


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path (``path``'s suffix, so writers that go by it still can) to write to;
    when the block ends it replaces ``path``, or in an ``output_batch`` is staged until the
    batch commits; removed if the block raises. Readers see the old file or the new one, never
    half. A symlink is followed (its target replaced, the link kept); a device or FIFO is
    written through, not replaced. The file gets ``path``'s permissions (``_file_mode``); a
    read-only file is not replaced (``check_replaceable``). An ``OSError`` names ``path``."""
    name = Path(path)
    special = is_special(name)
    target = name if special else Path(os.path.realpath(name))
    check_replaceable(target)
    try:
        handle, temporary = tempfile.mkstemp(
            prefix=f".{target.stem}.",
            suffix=Path(path).suffix,
            dir=None if special else target.parent,
        )
    except OSError as error:
        raise _failed(error, name) from None
    os.close(handle)
    staged = _Staged(Path(temporary), target, special, name)
    try:
        try:
            yield staged.temporary
        except OSError as error:  # disk full while writing, say
            if error.filename not in (None, temporary):
                raise
            raise _failed(error, name) from None
        batch = _BATCH.get()
        if batch is not None:
            batch.staged.append(staged)
            return
        if special:
            staged.write_through()
        else:
            staged.rename()
    except BaseException:
        staged.discard()
        raise
    staged.discard()  # the temporary that a write through leaves


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (``atomic_path``)."""
    with atomic_path(path) as temporary:
        temporary.write_text(text)
