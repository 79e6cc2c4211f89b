"""File names as text that can be printed and written anywhere (UTF-8, one line)."""
from __future__ import annotations

import os


def shown(path) -> str:
    """A file name as text that can be printed and written anywhere (UTF-8, one line).

    Bytes that are not UTF-8 in a POSIX file name (Python keeps them as lone surrogates) appear as
    ``\\xff``; control characters (a newline in a name) as their escapes."""
    raw = os.fsencode(os.fspath(path)) if not isinstance(path, bytes) else path
    text = raw.decode("utf-8", "backslashreplace")
    if any(c < " " or c == "\x7f" for c in text):
        text = "".join(c if c >= " " and c != "\x7f" else repr(c)[1:-1] for c in text)
    return text
