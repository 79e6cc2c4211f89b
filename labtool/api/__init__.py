"""labtool's Python API: what the commands do, as functions a script or a notebook calls
(``labtool.simulate``, ``labtool.process``, ``labtool.report``, ``labtool.fit``,
``labtool.suggest``). Each is a thin layer over the library call the command of the same name
makes, so the two give the same results (docs/architecture.md, "The API layer")."""
