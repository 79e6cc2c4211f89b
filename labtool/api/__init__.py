"""labtool's Python API: what the commands do, as functions a script or a notebook calls
(``labtool.simulate``, ``labtool.process``, ``labtool.report``, ``labtool.fit``). The commands
``simulate``, ``process``, ``report`` and ``fit`` call the same functions (docs/architecture.md,
"The API layer")."""
