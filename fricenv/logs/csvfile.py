"""The text of a log file: its ``#`` comment lines, its header row and its numeric table (docs/contracts.md, section 1).

The header is the first line that does not begin with ``#``, unless the last ``#`` line before it names the columns:
when that line has as many comma-separated cells as the next line, is not itself a row of numbers, and the next line
is one, it is the header (an export that writes its header as a comment, ``# time(s),vx(m/s),...``) and the next
line is the first data row.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from fricenv.errors import InvalidInputError
from fricenv.logs.logmap import HEADER_UNIT, SI_UNITS, unit_key

__all__ = ["LogFormatError", "column_name", "parse", "read_text"]

# A number as a CSV holds it: ASCII decimal, optional exponent, or nan/inf (rejected later with their line). Python's
# float() alone would also take "1_0" and non-ASCII digits.
_NUMBER = re.compile(r"^\s*[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|nan|inf|infinity)\s*$", re.IGNORECASE | re.ASCII)


class LogFormatError(InvalidInputError):
    """A log file that does not follow the docs/contracts.md contract (a ``ValueError``; one line naming the file)."""


def read_text(path: Path) -> str:
    """The file's text; a missing, unreadable or binary file is a :class:`LogFormatError`."""
    try:
        return path.read_text(encoding="utf-8-sig")  # -sig: a leading byte-order mark is not part of the header
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LogFormatError(f"{path}: is a directory, expected a CSV file") from None
    except UnicodeDecodeError:
        raise LogFormatError(f"{path}: not a text (CSV) file") from None
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read the file ({exc.strerror})") from None


def _is_numeric_row(line: str) -> bool:
    """Every cell a number or empty (a data row, not a header)."""
    return all(not cell.strip(" \t") or _NUMBER.match(cell) for cell in line.split(","))


def _row(path: Path, lineno: int, line: str, header: list[str]) -> list[float]:
    """The values of a data row; an empty cell is NaN (a missing sample)."""
    cells = line.split(",")
    if len(cells) != len(header):
        raise LogFormatError(f"{path}:{lineno}: {len(cells)} values, the header has {len(header)} columns")
    empty = [not cell.strip(" \t") for cell in cells]  # ASCII blanks only: a no-break space is not "empty"
    for name, cell, blank in zip(header, cells, empty):
        if not blank and not _NUMBER.match(cell):
            raise LogFormatError(f"{path}:{lineno}: column {name!r}: {cell.strip()!r} is not a number")
    return [np.nan if blank else float(cell) for cell, blank in zip(cells, empty)]


def _header_in_comment(comments: list[str], line: str) -> bool:
    """The last comment line is the header: as many cells as the data line ``line``, which is numeric, while the
    comment is not."""
    if not comments:
        return False
    last = comments[-1]
    cells = last.split(",")
    return (len(cells) > 1 and len(cells) == len(line.split(",")) and all(c.strip() for c in cells)
            and _is_numeric_row(line) and not _is_numeric_row(last))


def _header(path: Path, lineno: int, line: str, raw_header: bool) -> list[str]:
    header = [c.strip() if raw_header else column_name(path, lineno, c) for c in line.split(",")]
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise LogFormatError(f"{path}:{lineno}: duplicate column(s) {', '.join(dup)} in header")
    return header


def parse(path: Path, raw_header: bool = False):
    """Comments, header and a float table with the file line number of each row.

    :param raw_header: keep the header cells as written (a column map names them); else reduce ``name [SI unit]``.
    :return: ``(comments, header, table, line_numbers)``; a header read from a comment line is not a comment.
    """
    comments: list[str] = []
    comment_lines: list[int] = []
    header: list[str] | None = None
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    for lineno, raw in enumerate(read_text(path).splitlines(), start=1):
        line = raw.strip(" \t")  # ASCII blanks only: a no-break space at an end is a bad cell, not nothing
        if not line:
            continue
        if header is None:
            if line.startswith("#"):
                comments.append(line[1:].strip())
                comment_lines.append(lineno)
                continue
            if not _header_in_comment(comments, line):
                header = _header(path, lineno, line, raw_header)
                continue
            header = _header(path, comment_lines[-1], comments.pop(), raw_header)
        rows.append(_row(path, lineno, line, header))
        line_numbers.append(lineno)
    if header is None:
        raise LogFormatError(f"{path}: no header row")
    if len(rows) < 3:
        raise LogFormatError(f"{path}: needs at least 3 data rows, found {len(rows)}")
    return comments, header, np.array(rows, dtype=float), np.array(line_numbers)


def column_name(path: Path, lineno: int, cell: str) -> str:
    """The column name of a header cell; a unit in brackets is accepted if it is the column's SI unit."""
    cell = cell.strip()
    match = HEADER_UNIT.match(cell)
    if match is None or match["name"].strip() not in SI_UNITS:
        return cell
    name, unit = match["name"].strip(), (match["u1"] if match["u1"] is not None else match["u2"]).strip()
    if unit_key(unit) != unit_key(SI_UNITS[name]):
        raise LogFormatError(f"{path}:{lineno}: column {cell!r}: unit {unit!r}, expected {SI_UNITS[name]}; "
                             f"convert the column to SI units or give a column map (--map)")
    return name
