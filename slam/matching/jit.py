"""numba, imported with the environment settings it reads checked.

numba reads its ``NUMBA_*`` environment variables when it is imported. One
it cannot parse it reports in a warning holding a whole traceback, then
uses its default; a thread count below 1 ends the import with a traceback.
Here the thread count must be a positive whole number (the one setting whose
bad value numba refuses), and any other it cannot parse is said in one
warning line.
"""

from __future__ import annotations

import logging
import os
import re
import warnings
from types import ModuleType

from slam.errors import GslamError

log = logging.getLogger(__name__)

_UNPARSED = re.compile(r"Environment variable '(?P<name>[^']*)' is defined but its associated value '(?P<value>.*)' "
                       r"could not be parsed\.", re.DOTALL)


def import_numba() -> ModuleType:
    """numba, its environment checked (see the module docstring)."""
    threads = os.environ.get("NUMBA_NUM_THREADS")
    if threads is not None and not _positive_whole(threads):
        raise GslamError(f"environment variable NUMBA_NUM_THREADS={threads!r}: expected a positive whole number (the "
                         "threads numba's compiled code may use); give one, or unset it")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        import numba
    for w in said:
        unparsed = _UNPARSED.match(str(w.message))
        if unparsed is None:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            continue
        why = str(w.message).strip().splitlines()[-1]  # the parse's error, the traceback's last line
        log.warning(f"environment variable {unparsed['name']}={unparsed['value']!r}: numba cannot read it ({why}); "
                    "numba's default is used")
    return numba


def _positive_whole(text: str) -> bool:
    try:
        return int(text) > 0  # as numba reads it
    except ValueError:
        return False
