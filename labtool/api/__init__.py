"""labtool's Python API: what each command does, as functions a notebook calls (``labtool.simulate``,
``labtool.process``, ``labtool.report``, ``labtool.fit``, ``labtool.acquire``). The commands call
the same functions."""
