"""Reading a recording's text logs: one-line errors for what is not text."""

from __future__ import annotations

import errno
import logging
import os
import re
from pathlib import Path

from slam.errors import GslamError
from validation.base.yamlio import wide_encoding

log = logging.getLogger(__name__)

SNIFF_BYTES = 1 << 20
"""How much of a text log is looked at before the whole is read: a binary
file (a disk image, a sparse file of zeros) is refused on its first
megabyte, not after gigabytes are in memory."""
BOM = "\ufeff"
_NOT_UTF8 = re.compile("[\udc80-\udcff]")


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


def sniff_log(head: bytes, source: str | Path, what: str) -> None:
    """Refuse a log whose first bytes ``head`` are binary (as :func:`decode_log`)."""
    _text(head, source, what)


def decode_log(data: bytes, source: str | Path, what: str) -> str:
    """The text of a log whose fields are ASCII numbers and words (CARMEN,
    libRSF): a byte-order mark dropped, a stray byte that is not UTF-8 (a
    Latin-1 host name or comment) kept as it is, so that only a field that
    is read can fail, at its line. NUL bytes, or mostly undecodable bytes,
    are binary content. A byte-order mark further on (two files joined by
    ``cat``) hid its line's record type, which was then skipped as unknown:
    it is dropped too, with one warning naming the first line that had one."""
    text = _text(data, source, what)
    marks = text.count(BOM)
    if marks:
        line = len((text[: text.index(BOM)] + ".").splitlines())
        log.warning("%s:%d: a byte-order mark inside the %s (files joined?)%s; read past it", source, line, what,
                    f", and {marks - 1} more after it" if marks > 1 else "")
        text = text.replace(BOM, "")
    return text


def _text(data: bytes, source: str | Path, what: str) -> str:
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    wide = wide_encoding(data)
    if wide is not None:
        raise GslamError(f"{source}: cannot read: {wide} text; expected a {what} in ASCII or UTF-8 (save it as UTF-8)")
    # A byte that is not UTF-8 is kept as Python keeps a path's (a lone
    # surrogate), so that gslam inject writes the log back byte for byte.
    text = data.decode("utf-8", errors="surrogateescape")
    if "\0" in text or len(_NOT_UTF8.findall(text)) > 0.1 * max(len(text), 1):
        raise GslamError(f"{source}: cannot read: not a {what} (binary content)")
    return text
