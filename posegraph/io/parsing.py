"""Line-table parsing shared by the g2o and TORO readers.

A file is split into lines of ``TAG number number …``. Lines of one tag are converted to a float
array in one call of numpy's C reader; only when that fails are they tokenised and the offending
line searched for. Every check is vectorised. A bad line is recorded and left out; in lenient
mode it stays skipped, and in strict mode the reader raises, once a stage's checks are done
(``LineChecker.raise_first``), for the earliest bad line, as ``file:line: message``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import re
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .errors import GraphFileError


@dataclasses.dataclass(frozen=True)
class Rows:
    """The lines of one tag: their line numbers and their numbers (tag excluded)."""

    tag: str
    line_numbers: np.ndarray
    numbers: np.ndarray
    node_ids: np.ndarray
    """(n, k) int64: the tag's id columns, which lead its numbers, read exactly."""

    def __len__(self) -> int:
        return int(self.line_numbers.size)

    def subset(self, keep: np.ndarray) -> Rows:
        return Rows(self.tag, self.line_numbers[keep], self.numbers[keep], self.node_ids[keep])

    def ids(self, column: int) -> np.ndarray:
        return self.node_ids[:, column]


class LineChecker:
    """Records bad lines, which the callers leave out. Strict reading raises for the earliest
    of them when a stage of checks ends (``raise_first``), so that the error names the stage's
    first bad line in the file, whatever order its checks ran in; lenient reading keeps them
    as skipped."""

    def __init__(self, path: str, lenient: bool) -> None:
        self.path, self.lenient = path, lenient
        self.skipped: list[tuple[int, str]] = []

    def fail(self, line: int | None, message: str) -> None:
        """Record a bad line; a problem of the whole file (``line`` None) raises at once."""
        if line is None:
            raise GraphFileError(self.path, line, message)
        self.skipped.append((line, message))

    def raise_first(self) -> None:
        """In strict mode, raise ``GraphFileError`` for the earliest bad line recorded, saying
        how many were found; in lenient mode, nothing."""
        if self.lenient or not self.skipped:
            return
        line, message = min(self.skipped, key=lambda skipped: skipped[0])
        count = len({number for number, _ in self.skipped})
        more = f" (the first of {count} bad lines found)" if count > 1 else ""
        raise GraphFileError(self.path, line, message + more)

    def keep_good(self, rows: Rows, bad: np.ndarray, message) -> Rows:
        """Handle the rows where ``bad`` holds; ``message(k)`` describes row k."""
        bad_rows = np.flatnonzero(bad)
        for k in bad_rows:
            self.fail(int(rows.line_numbers[k]), f"{rows.tag}: {message(k)}")
        return rows.subset(~bad) if bad_rows.size else rows


@contextlib.contextmanager
def paused_garbage_collection() -> Iterator[None]:
    """Pause Python's cyclic garbage collector (as a context or a decorator) while a file is
    read or its text formatted. Both make a list of tokens per line, none in a reference cycle,
    and the collections that their allocation sets off would take a large share of the time."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


REJECTED_PREFIX = "# posegraph:rejected "
"""Starts the line of a measurement that a robust run rejected: a comment to g2o and gtsam,
which then read the graph without it; posegraph reads it back as rejected
(``ReadResult.rejected``)."""


def code_lines(path: str, rejected: set[int] | None = None) -> list[tuple[int, str]]:
    """(line number, text before any ``#``) of every line that is not blank or a comment.
    UTF-8, with or without a byte-order mark. Lines end at ``\n`` alone, as g2o, gtsam and
    editors count them (a form feed or U+2028 inside a line or a comment does not end it).
    Given a set ``rejected``, a line that starts with ``REJECTED_PREFIX`` is read as the line
    after it, and its number added to the set; otherwise it is a comment."""
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise GraphFileError(path, None, "no such file") from None
    except IsADirectoryError:
        raise GraphFileError(path, None, "is a directory, not a graph file") from None
    except UnicodeDecodeError:
        raise GraphFileError(path, None, "is not a text file") from None
    except OSError as error:
        raise GraphFileError(path, None, f"cannot be read ({error.strerror})") from None
    lines = text.split("\n")
    if rejected is not None and REJECTED_PREFIX in text:
        for index, line in enumerate(lines):
            if line.startswith(REJECTED_PREFIX):
                lines[index] = line[len(REJECTED_PREFIX) :]
                rejected.add(index + 1)
    if "#" in text:
        lines = [line.partition("#")[0] for line in lines]
    return [(number, code) for number, code in enumerate(lines, 1) if code and not code.isspace()]


@paused_garbage_collection()
def read_lines(path: str) -> list[tuple[int, list[str]]]:
    """(line number, tokens) of every line that is not blank or a comment: ``#`` starts a
    comment, at the start of a line or after its numbers. A line of numbers holding a
    character outside the formats' syntax (``_OUTSIDE_SYNTAX``) is refused, naming it; a line
    that starts with a tag is left to the graph reader."""
    lines = []
    for number, code in code_lines(path):
        tokens = code.split()
        if not tokens[0][:1].isalpha() and not _all_in_syntax(code):
            checker = LineChecker(path, lenient=False)
            _in_syntax("", [(number, code)], checker)
            checker.raise_first()
        lines.append((number, tokens))
    return lines


@paused_garbage_collection()
def read_tagged_lines(path: str, rejected: set[int] | None = None) -> list[tuple[int, str, str]]:
    """(line number, tag, the text after the tag) of every line that is not blank or a
    comment, as ``read_lines`` finds them: three objects a line instead of one a token. Lines
    marked rejected are read too, their numbers added to ``rejected`` (``code_lines``)."""
    split = ((number, code.split(None, 1)) for number, code in code_lines(path, rejected))
    return [(number, words[0], words[1] if len(words) == 2 else "") for number, words in split]


def to_rows(
    tag: str,
    entries: list[tuple[int, str]],
    widths: tuple[int, ...],
    id_columns: tuple[int, ...],
    checker: LineChecker,
    without_information: frozenset[int] = frozenset(),
) -> Rows | None:
    """Convert the lines (line number, text after the tag) of one tag, checking token counts,
    numbers, finiteness and ids.

    ``widths`` are the accepted counts of numbers after the tag (several for dialects; an empty
    tuple accepts any count ≥ 1, all ids); a line with a count in ``without_information``
    (``TagFormat.widths_without_information``) is told that it lacks its information. Returns
    None when no line survives.
    """
    numbers = _uniform_numbers(entries, widths, len(id_columns))
    if numbers is None:
        entries = _in_syntax(tag, entries, checker)
        tokenized = [(number, text.split()) for number, text in entries]
        return _rows_from_tokens(tag, tokenized, widths, id_columns, checker, without_information)
    line_numbers = np.fromiter((number for number, _ in entries), np.int64, len(entries))
    ids = numbers[:, : len(id_columns)].astype(np.int64)
    return _checked(Rows(tag, line_numbers, numbers, ids), id_columns, checker)


_OUTSIDE_SYNTAX = re.compile(r"[^\x21-\x7e \t\r\v\f]|_")
"""A character that no number of the formats holds: outside printable ASCII and its blanks
(Python's ``float`` would take ``1_0`` as 10 and Arabic-Indic or full-width digits as digits,
and ``str.split`` would split at U+00A0; g2o and gtsam read ASCII)."""


_SYNTAX_BYTES = bytes(range(0x21, 0x7F)) + b" \t\r\v\f"


def _all_in_syntax(text: str) -> bool:
    """Whether ``text`` holds no character outside the formats' syntax (``_OUTSIDE_SYNTAX``),
    in three passes of C code rather than a regular expression's one of Python speed."""
    return (
        text.isascii()
        and "_" not in text
        and not text.encode("ascii").translate(None, _SYNTAX_BYTES)
    )


def _in_syntax(tag: str, entries: list[tuple[int, str]], checker: LineChecker) -> list:
    """The lines (line number, text after the tag) whose characters are all of the formats'
    ASCII syntax; the others are refused, naming the first character outside it."""
    kept = []
    for number, text in entries:
        outside = _OUTSIDE_SYNTAX.search(text)
        if outside is None:
            kept.append((number, text))
            continue
        character = outside.group()
        checker.fail(
            number,
            f"{tag}{': ' if tag else ''}{character!r} (U+{ord(character):04X}) is outside the"
            " ASCII syntax of numbers",
        )
    return kept


def _uniform_numbers(
    entries: list[tuple[int, str]], widths: tuple[int, ...], id_count: int
) -> np.ndarray | None:
    """Every line's numbers as one (n, w) array, parsed by numpy's C reader in one call, if
    every line parses as w numbers, w is one of ``widths`` and the ids are below 2⁵³ (exact
    as floats). None otherwise, and the lines are then tokenised and checked one by one (as
    they are when a character outside the formats' ASCII syntax is found)."""
    if not widths or not _all_in_syntax(" ".join(text for _, text in entries)):
        return None  # numpy's reader splits at U+00A0, say
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "input contained no data"
        try:
            numbers = np.loadtxt([text for _, text in entries], ndmin=2, comments=None)
        except ValueError:
            return None
    if numbers.shape[0] != len(entries) or numbers.shape[1] not in widths:
        return None  # a line of no numbers (skipped by loadtxt), or a width not accepted
    if not (np.abs(numbers[:, :id_count]) < 2.0**53).all():
        return None  # ids that floats may round, or NaN
    return numbers


def _rows_from_tokens(
    tag: str,
    entries: list[tuple[int, list[str]]],
    widths: tuple[int, ...],
    id_columns: tuple[int, ...],
    checker: LineChecker,
    without_information: frozenset[int],
) -> Rows | None:
    """``to_rows`` of lines as (line number, tokens after the tag), line by line where needed:
    it finds and names each bad line."""
    counts = np.fromiter((len(tokens) for _, tokens in entries), np.int64, len(entries))
    accepted = np.isin(counts, widths) if widths else counts >= 1
    for k in np.flatnonzero(~accepted):
        expected = " or ".join(str(w) for w in widths) if widths else "at least 1"
        advice = (
            ": the line has no information matrix (--identity-information weighs every edge"
            " by the identity, as TORO's -ic does)"
            if counts[k] in without_information
            else ""
        )
        checker.fail(
            entries[k][0],
            f"{tag}: expected {expected} numbers after the tag, found {counts[k]}{advice}",
        )
    found = np.unique(counts[accepted])
    if found.size > 1 and widths:
        first = entries[np.flatnonzero(accepted & (counts == found[-1]))[0]][0]
        checker.fail(
            first, f"{tag}: lines of {found.tolist()} numbers mixed in one file (two dialects)"
        )
        accepted &= counts == found[0]
    good = entries if accepted.all() else [entries[k] for k in np.flatnonzero(accepted)]
    if not good:
        return None
    if not widths:  # variable-length id lists (FIX)
        flat = [(number, [token]) for number, tokens in good for token in tokens]
        return _rows_from_tokens(tag, flat, (1,), (0,), checker, frozenset())
    line_numbers = np.fromiter((number for number, _ in good), np.int64, len(good))
    parsed = np.ones(len(good), dtype=bool)
    try:
        numbers = np.array([tokens for _, tokens in good], dtype=float)
    except ValueError:
        numbers = np.full((len(good), len(good[0][1])), np.nan)
        for k, (number, tokens) in enumerate(good):
            try:
                numbers[k] = np.array(tokens, dtype=float)
            except ValueError:
                bad = next(t for t in tokens if not _is_number(t))
                checker.fail(number, f"{tag}: {bad!r} is not a number")
                parsed[k] = False
    ids = numbers[:, : len(id_columns)]
    rows = Rows(tag, line_numbers, numbers, _node_ids(good, ids)).subset(parsed)
    return _checked(rows, id_columns, checker)


def _checked(rows: Rows, id_columns: tuple[int, ...], checker: LineChecker) -> Rows | None:
    """The rows whose numbers are finite and whose ids are whole numbers from 0 to 2⁶³ − 1;
    None if none are."""
    non_finite = ~np.isfinite(rows.numbers).all(axis=1)
    rows = checker.keep_good(rows, non_finite, lambda k: "NaN or infinite value")
    if id_columns:
        ids = rows.numbers[:, : len(id_columns)]
        not_integer = (ids != np.round(ids)).any(axis=1) | (rows.node_ids < 0).any(axis=1)
        rows = checker.keep_good(
            rows, not_integer, lambda k: "node ids must be whole numbers from 0 to 2⁶³ − 1"
        )
    return rows if len(rows) else None


def _node_ids(entries: list[tuple[int, list[str]]], ids: np.ndarray) -> np.ndarray:
    """The id columns as int64. Floats are exact below 2⁵³; when a file has larger ids (64-bit
    keys such as gtsam's symbols), its id tokens are parsed as integers instead, so that nearby
    ids stay apart, and a token that is not an integer within int64 becomes -1. Non-finite ids
    become -1 too; the caller refuses negative and fractional ids."""
    if not (np.abs(ids) >= 2.0**53).any():
        return np.nan_to_num(ids, nan=-1.0, posinf=-1.0, neginf=-1.0).astype(np.int64)
    exact = np.empty(ids.shape, dtype=np.int64)
    for k, (_, tokens) in enumerate(entries):
        try:
            exact[k] = [int(token) for token in tokens[: ids.shape[1]]]
        except (ValueError, OverflowError):
            exact[k] = -1
    return exact


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def symmetric_from_upper(values: np.ndarray, size: int) -> np.ndarray:
    """(k, size, size) symmetric matrices from (k, size(size+1)/2) upper triangles, row-major."""
    rows, cols = np.triu_indices(size)
    out = np.zeros((values.shape[0], size, size))
    out[:, rows, cols] = values
    out[:, cols, rows] = values
    return out


def upper_from_symmetric(matrices: np.ndarray) -> np.ndarray:
    """Inverse of :func:`symmetric_from_upper`."""
    rows, cols = np.triu_indices(matrices.shape[-1])
    return matrices[:, rows, cols]


def quaternion_problems(quaternions: np.ndarray) -> dict[int, str]:
    """The rows of (n, 4) quaternions that are not rotations, with why: a zero norm, or a norm
    too large to compute (the squares of its components overflow)."""
    with np.errstate(over="ignore"):
        norms = np.linalg.norm(quaternions, axis=1)
    return {
        int(k): "quaternion has zero norm" if norms[k] < 1e-9 else "quaternion's norm overflows"
        for k in np.flatnonzero(~((norms >= 1e-9) & (norms < np.inf)))
    }
