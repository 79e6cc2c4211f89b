"""File names as text that can be printed and written anywhere (UTF-8, one line)."""
from __future__ import annotations

import os


def utf8_text(path) -> str:
    """A file name as UTF-8 text, exactly as given except bytes that are not UTF-8 (``\\xff``);
    for outputs whose writer quotes the rest (TOML, JSON)."""
    raw = os.fsencode(os.fspath(path)) if not isinstance(path, bytes) else path
    return raw.decode("utf-8", "backslashreplace")


def shown(path) -> str:
    """A file name as text that can be printed and written anywhere (UTF-8, one line).

    Bytes that are not UTF-8 in a POSIX file name (Python keeps them as lone surrogates) appear as
    ``\\xff``; control characters (a newline in a name) as their escapes."""
    text = utf8_text(path)
    if any(c < " " or c == "\x7f" for c in text):
        text = "".join(c if c >= " " and c != "\x7f" else repr(c)[1:-1] for c in text)
    return text
