"""``jit``: numba's ``njit(cache=True)`` with an on-disk cache that cannot go stale.

numba keys a cached function on the source of its own file only. A compiled loop inlines the
functions it calls from other files (the Dormand-Prince driver, the contact law, a model's
equations), so an edit there, or an upgrade of labtool, would leave the loop running the old code
from the cache (SAFETY in the driver changed from 0.9 to 0.5 and the elastic loop kept
the old controller). Here every cached function of labtool's models is stamped with one hash of
the source of every module that compiled code can reach: the modules that import this one and,
transitively, the first-party modules they import (``KERNEL_SOURCES``), plus the versions of
numba and llvmlite. A change to any of them invalidates every cached entry at its next load
(numba compares the stamp stored in each index file and recompiles on a mismatch).

The cache directory is numba's usual choice (``NUMBA_CACHE_DIR`` if set, else ``__pycache__``
beside the source, else the user-wide cache); only the stamp changes. Where numba's cache machinery
is not the one this was written against, caching is off (always correct, slower first calls):
``CACHING`` says which.

A cache entry that cannot be read is compiled again, never an error: numba unpickles an index
before it compares the stamp, and a cached function's environment imports its module by the name
it had when it was compiled, so a cache left by a labtool laid out otherwise (the same source
files under other module names) or by a damaged write raised ModuleNotFoundError or an unpickling
error at the first call. Every function compiled through ``jit`` reads its cache tolerantly
(``_tolerant``); the processing and report kernels use ``jit`` too, for that alone (their
stamp stays numba's: the file itself, for they call no compiled code of another file).
"""
from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

import numba
from numba import njit

from labtool.models.dynamics import compiling

# the folder that holds models/ and common/: the repository in a source tree, site-packages/labtool
# in a wheel (labtool.models.x lives in <_ROOT>/models/x.py either way)
_ROOT = Path(__file__).resolve().parents[2]
_SEED = "from labtool.models.dynamics.jit import"          # a module that compiles code (jit or kernel)
# the names imported: in parentheses (over lines) or to the end of the line; an import group that
# ran on to the next line swallowed the import there (its module was left out of the stamp)
_IMPORT = re.compile(r"^[ \t]*(?:from[ \t]+(labtool\.(?:models|common)(?:\.\w+)*)[ \t]+import[ \t]+(\([^)]*\)|[\w \t,]+)"
                     r"|import[ \t]+(labtool\.(?:models|common)(?:\.\w+)*))", re.MULTILINE)


def _module_file(name: str) -> Path | None:
    base = _ROOT.joinpath(*name.split(".")[1:])         # 'labtool.models.x' -> <_ROOT>/models/x
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


# imported by compiled modules, but no compiled code reaches it (it watches numba compile): an edit of
# it must not invalidate every cached loop
_NOT_COMPILED = {"labtool.models.dynamics.compiling"}


def _first_party_imports(text: str) -> set[str]:
    out = set()
    for m in _IMPORT.finditer(text):
        if m.group(3):
            out.add(m.group(3))
            continue
        out.add(m.group(1))
        for name in re.split(r"[\s,()]+", m.group(2)):     # 'from labtool.models.dynamics import contact'
            if name:
                out.add(f"{m.group(1)}.{name}")
    return out - _NOT_COMPILED


def kernel_sources() -> list[Path]:
    """Every source file compiled code can reach (sorted): the modules under models/ that compile
    with ``jit``, this one, and the first-party modules they import, transitively."""
    seeds = [p for p in sorted((_ROOT / "models").rglob("*.py")) if _SEED in p.read_text(encoding="utf-8")]
    seeds.append(Path(__file__).resolve())
    seen, todo = set(), list(seeds)
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        for name in _first_party_imports(path.read_text(encoding="utf-8")):
            found = _module_file(name)
            if found is not None and found not in seen:
                todo.append(found)
    return sorted(seen)


def _source_hash() -> str:
    import llvmlite

    h = hashlib.sha256(f"numba {numba.__version__} llvmlite {llvmlite.__version__}".encode())
    for path in kernel_sources():
        h.update(str(path.relative_to(_ROOT)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


KERNEL_SOURCES_HASH = _source_hash()


def _install_locator() -> bool:
    """Put the stamping locator first in numba's list; False if numba's internals differ."""
    try:
        from numba.core import caching
        impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl      # numba >= 0.61 / before
        base = caching._CacheLocator
        inner_classes = list(impl._locator_classes)
    except (ImportError, AttributeError):
        return False
    if any(getattr(c, "_labtool", False) for c in inner_classes):
        return True

    class KernelSourceLocator(base):
        """numba's own locator for the file, with the stamp extended by KERNEL_SOURCES_HASH."""

        _labtool = True

        def __init__(self, inner):
            self._inner = inner

        def ensure_cache_path(self):
            self._inner.ensure_cache_path()

        def get_cache_path(self):
            return self._inner.get_cache_path()

        def get_source_stamp(self):
            return (self._inner.get_source_stamp(), KERNEL_SOURCES_HASH)

        def get_disambiguator(self):
            return self._inner.get_disambiguator()

        def __getattr__(self, name):                   # numba's other reads (_py_file in a warning)
            if name == "_inner":
                raise AttributeError(name)
            return getattr(self._inner, name)

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                Path(py_file).resolve().relative_to(_ROOT / "models")
            except (ValueError, OSError):
                return None                           # not labtool's: numba's own locators decide
            for inner_cls in inner_classes:
                inner = inner_cls.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner)
            return None

    impl._locator_classes.insert(0, KernelSourceLocator)
    return True


def _tolerant_classes():
    """(cache class, cache file class): numba's, with every failure to read an entry taken as a
    miss; None if numba's internals are not the ones this was written against."""
    try:
        from numba.core import caching
        cache_base, file_base = caching.FunctionCache, caching.IndexDataCacheFile
        cache_base.load_overload, file_base._load_index       # noqa: B018  (the methods overridden)
    except (ImportError, AttributeError):
        return None

    class TolerantCacheFile(file_base):
        """An index that cannot be unpickled here (written by another layout of the modules, cut
        short) reads as empty: the function compiles and its save replaces the index."""

        def _load_index(self):
            try:
                return super()._load_index()
            except Exception:                       # noqa: BLE001  (any unreadable index: a miss)
                return {}

    class TolerantCache(cache_base):
        """An entry that cannot be loaded (its environment imports a module that is not there,
        its data is damaged) is a miss: numba compiles the function and saves it over the entry."""

        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except Exception:                       # noqa: BLE001  (any unloadable entry: a miss)
                return None

    return TolerantCache, TolerantCacheFile


_TOLERANT = _tolerant_classes()
CACHING = not os.environ.get("NUMBA_CACHE_LOCATOR_CLASSES") and _TOLERANT is not None and _install_locator()
compiling.listen()          # a compilation of labtool's code is never silent (labtool.models.dynamics.compiling)


def _tolerant(dispatcher):
    """``dispatcher`` with its cache read tolerantly (module doc); its cache is off if the cache
    object is not numba's usual one (correct, slower first calls)."""
    cache = getattr(dispatcher, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    if cache is None:
        return dispatcher
    if _TOLERANT is None:                       # numba's internals differ: no cache, rather than a fragile one
        from numba.core.caching import NullCache
        dispatcher._cache = NullCache()
        return dispatcher
    if type(cache) is _TOLERANT[0].__base__ and type(cache_file) is _TOLERANT[1].__base__:
        cache.__class__, cache_file.__class__ = _TOLERANT
    elif not isinstance(cache, _TOLERANT[0]) and cache_file is not None:
        from numba.core.caching import NullCache
        dispatcher._cache = NullCache()
    return dispatcher


def _one_type_per_value_kind(dispatcher):
    """``dispatcher`` compiled for the plain type of an argument that compiled code passes as a
    constant (numba would compile it once for ``Literal[int](0)``, once for ``Literal[int](1)``
    ... and once more for int64): a table lookup called with its columns 0..7 compiled 8 times,
    the driver's inner loop twice (a counter starting at the constant 0, then int64). A call from
    Python is not concerned (it passes values, not constants)."""
    from numba.core import types

    base = dispatcher.get_call_template

    def get_call_template(args, kws):
        return base(tuple(types.unliteral(a) for a in args), {k: types.unliteral(v) for k, v in kws.items()})
    dispatcher.get_call_template = get_call_template
    return dispatcher


def jit(fn=None, internal: bool = False, **options):
    """``numba.njit`` with the on-disk cache (stamped as above, read tolerantly) when CACHING, else
    without; compiled once per argument type, not per constant (``_one_type_per_value_kind``).

    Nothing is compiled that no caller uses: no C callback wrapper (labtool passes no compiled
    function as a value), and with ``internal`` (a function called from compiled code only) no
    CPython wrapper either: unboxing a model struct of arrays is long code, and the wrappers were
    ~10 % of a model's first compilation. An ``internal`` function called from Python raises a
    TypeError (``_compiled_only_class``)."""
    options.setdefault("cache", CACHING)
    options.setdefault("no_cfunc_wrapper", True)
    if internal:
        options["no_cpython_wrapper"] = True
    if fn is None:
        return lambda f: jit(f, internal=internal, **options)
    dispatcher = _one_type_per_value_kind(njit(**options)(fn))
    if internal:
        dispatcher.__class__ = _compiled_only_class()
    return _tolerant(dispatcher) if options["cache"] else dispatcher


_COMPILED_ONLY = []


def _compiled_only_class():
    """numba's dispatcher for a function compiled without its CPython wrapper (``jit(internal=
    True)``): its compilations are kept for compiled callers but not entered in the table that a
    call from Python looks up (the entry would be no wrapper: a crash), so such a call reaches
    ``_compile_for_args``, which refuses it in one line."""
    if not _COMPILED_ONLY:
        from numba.core.registry import CPUDispatcher

        class CompiledOnly(CPUDispatcher):
            def add_overload(self, cres):
                self.overloads[tuple(cres.signature.args)] = cres

            def _compile_for_args(self, *args, **kws):
                raise TypeError(f"{self.py_func.__module__}.{self.py_func.__qualname__} is called from compiled "
                                "code only (compiled without a Python wrapper); call its caller, or its .py_func")
        _COMPILED_ONLY.append(CompiledOnly)
    return _COMPILED_ONLY[0]


def kernel(fn=None, **options):
    """``jit`` without numba's reference counting, for compiled functions that allocate nothing
    (no array created, none returned): every array they touch is borrowed from a caller that keeps
    it alive for the call. With reference counting each call of such a function costs an atomic
    increment and decrement per array argument and per array read from a struct: perf put 52 % of
    the elastic loop's time in them; a right-hand side called from a loop costs 25 ns
    without them against 75 ns with. The compiler refuses a body that would need them."""
    options.setdefault("_nrt", False)
    return jit(fn, **options)
