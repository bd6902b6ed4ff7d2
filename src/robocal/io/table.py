"""The one CSV table reader of robocal: header, column mapping, numeric cells, one-line errors.

Measurement files, compensation goal files and the parallel mechanism's files are all
read through :func:`read_csv` and then take their columns with :func:`numbers` and
:func:`strings`; what columns a file must have is checked by each file's own module.
Rows are named by their line number in the file (header = line 1).
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError


@dataclass(frozen=True)
class CsvTable:
    """A comma-separated table: header (after the column mapping), data rows, their line numbers."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    lines: np.ndarray
    header_line: int
    source: str
    #: columns of the file left out (not robocal's, in a mapped export)
    ignored: tuple[str, ...] = ()

    @property
    def index(self) -> dict[str, int]:
        return {h: i for i, h in enumerate(self.header)}

    def __contains__(self, column: str) -> bool:
        return column in self.header

    def require(self, names: Sequence[str]) -> None:
        for name in names:
            if name not in self.header:
                raise InputError(f"missing column '{name}'", source=self.source)

    def together(self, names: Sequence[str], what: str) -> bool:
        """Whether the table has the columns ``names`` (``what`` they are, for the message): all
        of them or none; some without the others is refused (an angle dropped would leave the
        rest meaningless)."""
        have = [name in self.header for name in names]
        if any(have) and not all(have):
            missing = next(name for name, h in zip(names, have) if not h)
            raise InputError(f"{what} columns {', '.join(names)} come together; '{missing}' is missing",
                             source=self.source)
        return all(have)


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


#: cell separators a file may use, by the name an option gives them
DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\t": "\t", "space": " "}
DECIMALS = (".", ",")


_NESTING = frozenset("()[]{}")
_QUOTES = frozenset("'\"")


def split_top(text: str, quotes: bool = False) -> list[str]:
    """``text`` split at the commas outside parentheses, brackets and braces (and, with ``quotes``, outside
    quoted text), every part kept, empty ones too."""
    if _NESTING.isdisjoint(text) and not (quotes and _QUOTES.intersection(text)):
        return text.split(",")
    parts, depth, quote, last = [], 0, None, 0
    for i, c in enumerate(text):
        if quote:
            quote = None if c == quote else quote
        elif quotes and c in "'\"":
            quote = c
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "," and depth == 0:
            parts.append(text[last:i])
            last = i + 1
    parts.append(text[last:])
    return parts


def _robot_file(text: str) -> str | None:
    """What kind of robot file ``text`` is (``TOML``, ``URDF``, ``UR kinematics YAML``), or None: its first
    lines that are not blank or comments tell."""
    lines = [x.strip() for x in text.lstrip("\ufeff").splitlines() if x.strip() and not x.strip().startswith("#")]
    head = " ".join(lines[:5])
    if lines and (lines[0].startswith("<?xml") or "<robot" in head):
        return "URDF"
    if lines and lines[0].startswith("kinematics:"):
        return "UR kinematics YAML"
    if re.search(r"^\s*(\[\[joint\]\]|convention\s*=|name\s*=\s*\")", "\n".join(lines[:10]), re.M):
        return "TOML"
    return None


def read_csv(text: str, *, source: str, columns: Mapping[str, str] | None = None, delimiter: str = ",",
             decimal: str = ".") -> CsvTable:
    """Parse CSV text with a header row; blank lines are skipped, a byte-order mark ignored.

    columns maps file column names to robocal's (``{"A1": "q1"}``).  delimiter: ``,`` (the
    default), ``;``, ``tab`` or ``space``; decimal: ``.`` or ``,`` (a decimal comma needs another
    delimiter), as spreadsheets and tracker software export.
    """
    if not text.strip():
        raise InputError("file is empty", source=source)
    robot = _robot_file(text)
    if robot:
        raise InputError(f"is a robot file ({robot}), not a table of rows: give it as the robot (the first "
                         "argument), and the measurements after it", source=source)
    sep = DELIMITERS[delimiter]
    if decimal == "," and sep == ",":
        raise InputError("decimal commas need another cell separator (--delimiter ';')", option="decimal")
    reader = csv.reader(io.StringIO(text.lstrip("\ufeff")), delimiter=sep, skipinitialspace=sep == " ")
    try:
        rows = [(reader.line_num, r) for r in reader]
    except csv.Error as exc:
        raise InputError(f"not a valid CSV file ({exc})", source=source) from None
    rows = [(ln, r) for ln, r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError("file has no header row (only empty cells)", source=source)
    header_line, raw = rows[0]
    header = [h.strip() for h in raw]
    if len(header) > 1 and header[-1] == "" and all(len(r) == len(raw) and not r[-1].strip() for _, r in rows[1:]):
        # a delimiter closing every line, as some tracker software writes: an empty last column, not data
        header, rows = header[:-1], [(ln, r[:-1]) for ln, r in rows]
    if len(header) == 1 and any(c in header[0] for c in (";", "\t", ",")):
        found = ";" if ";" in header[0] else ("tab" if "\t" in header[0] else ",")
        raise InputError(f"header is separated by {found!r}, not {delimiter!r}: read it with --delimiter "
                         f"{found!r}" + (" (and --decimal ',' for decimal commas)" if found == ";" else ""),
                         source=source, where=f"row {header_line}")
    if all(_looks_numeric(h) for h in header) or (len(header) == 1 and len(header[0].split()) > 1):
        raise InputError("no header row, or not comma-separated: the first row must name the columns "
                         "(q1, …, x, y, z) and cells are separated by commas", source=source,
                         where=f"row {header_line}")
    mapping = dict(columns or {})
    for old in mapping:
        if old not in header:
            raise InputError(f"column '{old}' named in the column mapping is not in the file", source=source)
    header = [mapping.get(h, h) for h in header]
    seen: set[str] = set()
    for i, h in enumerate(header):
        if h == "":
            raise InputError(f"column {i + 1} has an empty name", source=source, where=f"row {header_line}")
        if h in seen:
            raise InputError(f"column '{h}' appears twice", source=source, where=f"row {header_line}")
        seen.add(h)
    data = rows[1:]
    if decimal == ",":  # 1,5 → 1.5; a cell's other text is not a number anyway
        data = [(ln, [c.replace(",", ".") for c in cells]) for ln, cells in data]
    if not data:
        raise InputError("file has a header but no data rows", source=source)
    for ln, cells in data:
        if len(cells) != len(header):
            extra = " (decimal commas? use '.' for decimals)" if len(cells) > len(header) else ""
            raise InputError(f"has {len(cells)} cells, the header has {len(header)}{extra}", source=source,
                             where=f"row {ln}")
    return CsvTable(tuple(header), tuple(tuple(r) for _, r in data), np.array([ln for ln, _ in data], dtype=int),
                    header_line, source)


def _number(cell: str, source: str, line: int, column: str) -> float:
    text = cell.strip()
    try:
        value = float(text)
    except ValueError:
        hint = " (decimal comma? use '.' for decimals)" if re.fullmatch(r"[-+]?\d+,\d+", text) else ""
        raise InputError(f"{cell!r} is not a number{hint}", source=source,
                         where=f"row {line}, column '{column}'") from None
    if not math.isfinite(value):
        raise InputError(f"value is not finite ({text})", source=source, where=f"row {line}, column '{column}'")
    return value


def numbers(table: CsvTable, names: Sequence[str], limit: float | None = None, unit: str = "") -> np.ndarray:
    """The named columns as finite floats, (rows, len(names)); with ``limit``, a magnitude
    beyond it (in the file's ``unit``) is an error naming the row and column: 1e308 is finite,
    but no robot turns or reaches that far, and the arithmetic on it overflows."""
    idx = table.index
    cols = [idx[n] for n in names]
    out = np.empty((len(table.rows), len(cols)))
    for r, (ln, cells) in enumerate(zip(table.lines, table.rows)):
        for j, (c, name) in enumerate(zip(cols, names)):
            out[r, j] = _number(cells[c], table.source, int(ln), name)
    if limit is not None and out.size and np.abs(out).max() > limit:
        r, j = np.unravel_index(int(np.argmax(np.abs(out) > limit)), out.shape)
        raise InputError(f"{out[r, j]:.6g} is not a plausible value (beyond ±{limit:g}{' ' + unit if unit else ''})",
                         source=table.source, where=f"row {int(table.lines[r])}, column '{names[j]}'")
    return out


def strings(table: CsvTable, name: str, *, required: bool = False) -> list[str]:
    """The named column as stripped text; ``required`` makes an empty cell an error."""
    c = table.index[name]
    out = []
    for ln, cells in zip(table.lines, table.rows):
        value = cells[c].strip()
        if required and not value:
            raise InputError(f"empty {name}", source=table.source, where=f"row {ln}, column '{name}'")
        out.append(value)
    return out


def rows_to_csv(rows: list[dict], columns: Sequence[str]) -> str:
    """CSV text of dict rows (floats in shortest round-trip form, booleans as 0/1)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([repr(v) if isinstance(v, float) else (int(v) if isinstance(v, bool) else v)
                    for v in (r[c] for c in columns)])
    return out.getvalue()

