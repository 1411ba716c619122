"""Reading a recording's text logs: one-line errors for what is not text."""

from __future__ import annotations

import codecs
import errno
import gzip
import logging
import os
import re
import zlib
from collections.abc import Iterator
from pathlib import Path

from slam.errors import GslamError
from validation.base.yamlio import wide_encoding

log = logging.getLogger(__name__)

SNIFF_BYTES = 1 << 20
"""How much of a text log is read at a time: a binary file (a disk image,
a sparse file of zeros) is refused on its first megabyte, not after
gigabytes are in memory."""
MAX_LINE_BYTES = 1 << 20
"""The longest line a text log may hold. The longest line of the nine
CARMEN logs in the data folder has 2,144 characters (freiburg-101), of the
libRSF files 126; a laser line of a few thousand beams with their
remissions stays within tens of kB. A line of megabytes is not a record
but a damaged or foreign file, and reading it would only take memory."""
BOM = "\ufeff"
_NOT_UTF8 = re.compile("[\udc80-\udcff]")
_LINE_ENDS = "\r\n\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
"""What ``str.splitlines`` ends a line at."""


NOT_PLAIN = "not a plain number (ASCII digits, no '_')"
"""Why :func:`unplain_number` refuses a field, for the readers' messages."""


def plain(text: str) -> bool:
    """Whether ``text`` holds only ASCII and no ``_`` (see :func:`unplain_number`)."""
    return text.isascii() and "_" not in text


def unplain_number(parts: list[str]) -> int | None:
    """The index of the first of ``parts`` that Python reads as a number but
    C's ``strtod``, and so the tools that write and read these logs, do not:
    digits grouped by ``_`` (``1_000`` is 1000 to Python, 1 to C) or digits
    of another script (fullwidth, Arabic-Indic); None if every part is plain
    ASCII. A log holding one was edited or garbled: read as Python reads it,
    its value would differ from the one its tools see."""
    if plain("".join(parts)):
        return None
    return next(k for k, p in enumerate(parts) if not plain(p))


def check_exists(path: Path) -> None:
    """A one-line :class:`GslamError` if there is nothing at ``path``: no
    such file, a link to nothing, or a loop of links (which ``exists``
    takes for nothing too)."""
    try:
        os.stat(path)
        return
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise GslamError(f"{path}: too many levels of symbolic links (a link that leads back to itself)") from None
    if path.is_symlink():
        raise GslamError(f"{path}: a symbolic link to {os.readlink(path)}, which does not exist")
    raise GslamError(f"{path}: no such file or directory")


def log_lines(path: Path, what: str) -> Iterator[str]:
    """The lines of the text log ``path`` (gzip'd where its name ends in
    ``.gz``), whose fields are ASCII numbers and words (CARMEN, libRSF), as
    ``str.splitlines`` splits its text. It is read :data:`SNIFF_BYTES` at a
    time, so memory holds a line and a chunk, never the file.

    A leading byte-order mark is dropped. A stray byte that is not UTF-8 (a
    Latin-1 host name or comment) is kept as it is, so that only a field
    that is read can fail, at its line. UTF-16 text, NUL bytes or mostly
    undecodable bytes are refused as binary content, and a line over
    :data:`MAX_LINE_BYTES` at its number. A byte-order mark further on
    (two files joined by ``cat``) hid its line's record type, which was
    then skipped as unknown: it is dropped too, with one warning naming the
    first line that had one once the log is read."""
    marks, first = 0, 0
    for lineno, line in enumerate(_decoded_lines(path, what), start=1):
        if BOM in line:
            marks, first = marks + line.count(BOM), first or lineno
            line = line.replace(BOM, "")
        yield line
    if marks:
        log.warning("%s:%d: a byte-order mark inside the %s (files joined?)%s; read past it", path, first, what,
                    f", and {marks - 1} more after it" if marks > 1 else "")


def _decoded_lines(path: Path, what: str) -> Iterator[str]:
    opener = gzip.open if path.name.lower().endswith(".gz") else open
    # A byte that is not UTF-8 is kept as Python keeps a path's (a lone
    # surrogate), so that gslam inject writes the log back byte for byte.
    decoder = codecs.getincrementaldecoder("utf-8")(errors="surrogateescape")
    pending, lineno = "", 0
    try:
        with opener(path, "rb") as f:
            chunk = f.read(SNIFF_BYTES)
            if chunk.startswith(b"\xef\xbb\xbf"):
                chunk = chunk[3:]
            wide = wide_encoding(chunk)
            if wide is not None:
                raise GslamError(f"{path}: cannot read: {wide} text; expected a {what} in ASCII or UTF-8 "
                                 "(save it as UTF-8)")
            while True:
                text = decoder.decode(chunk)
                if "\0" in text or len(_NOT_UTF8.findall(text)) > 0.1 * max(len(text), 1):
                    raise GslamError(f"{path}: cannot read: not a {what} (binary content)")
                lines = (pending + text).splitlines(keepends=True)
                # The last piece may go on in the next chunk (a "\r" too: its "\n" may follow).
                last_open = lines and (lines[-1].endswith("\r") or not lines[-1].endswith(("\n", "\r")))
                pending = lines.pop() if last_open else ""
                lineno += len(lines)
                yield from (line.rstrip(_LINE_ENDS) for line in lines)
                if len(pending) > MAX_LINE_BYTES:
                    raise GslamError(f"{path}:{lineno + 1}: a line of over {MAX_LINE_BYTES >> 20} MB; no {what} "
                                     "record is that long (a damaged or foreign file?)")
                chunk = f.read(SNIFF_BYTES)
                if not chunk:
                    break
            pending += decoder.decode(b"", final=True)
    except FileNotFoundError:
        raise GslamError(f"{path}: no such file") from None
    except EOFError:
        raise GslamError(f"{path}: truncated gzip file: it ends before its end-of-stream marker "
                         "(an incomplete download or copy?)") from None
    except (gzip.BadGzipFile, zlib.error) as e:
        raise GslamError(f"{path}: not a valid gzip file ({e})") from None
    except OSError as e:
        raise GslamError(f"{path}: cannot read ({e.strerror or e})") from None
    yield from pending.splitlines()
