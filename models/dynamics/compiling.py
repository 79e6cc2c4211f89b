"""Never silent while numba compiles: a line when a call starts compiling, progress while it lasts.

numba compiles labtool's loops at their first use on a machine (seconds) and loads them from its
on-disk cache afterwards (milliseconds; labtool.models.dynamics.jit). A first command that sits
silent for that long looks hung, so a library call that may compile runs inside

    with compiling.announce("the elastic model"):
        ...                      # calls of compiled functions

and the moment the first labtool function in it starts compiling (numba's ``numba:compile``
event, which a load from the cache does not fire), one line goes to stderr saying what is
compiled, about how long it takes and that it happens once:

    labtool: compiling the elastic model for this machine (about 10 s, once: later runs load it from numba's cache)

When the compilation lasts over PROGRESS_AFTER_S, progress follows: on a terminal one line redrawn
in place (a bar over the estimate, seconds so far), cleared when the compilation ends; elsewhere
(a pipe, a log) a status line every STATUS_EVERY_S. A call served by the cache prints nothing.
Each ``what`` is announced once a process; a compilation outside every announced scope (a kernel
called directly) is announced by its package (``_fallback_what``). ``quiet()`` silences it all
for a caller that shows its own progress (``labtool warmup``), and so does the environment variable
LABTOOL_COMPILE_NOTICES=0; ``totals()`` counts what compiled. A command whose first compilation
comes late (the report reads and aligns its measurement first) says it at its start instead:
``has_entry`` tells whether a function's cache entry is there, ``announce_now`` says it.

ESTIMATES_S are the compile times of benchmarks/compile_times.py with an empty cache on the
2-core development machine (docs/performance.md, "First call and compile time"): "about" means
that; a slower machine takes longer, and the progress line says so as it goes.
"""
from __future__ import annotations

import contextlib
import os
import sys
import threading
import time

PROGRESS_AFTER_S = 2.0      # progress shown for a compilation longer than this (s)
STATUS_EVERY_S = 5.0        # a status line this often when stderr is not a terminal (s)
TICK_S = 0.25               # the progress thread's period (s)
IDLE_S = 0.5                # no compilation for this long ends a burst: the terminal line is cleared (s)

# what -> seconds to compile it from an empty cache (benchmarks/compile_times.py; module doc)
ESTIMATES_S = {
    "the elastic model": 10.0,
    "the rigid model": 8.0,
    "the stand's twin": 8.0,
    "the processing kernels": 7.0,
    "the report's metrics": 2.0,
}

_lock = threading.RLock()
_state = {
    "scopes": [],            # the announced scopes open, innermost last: [what, ...]
    "announced": set(),      # what was announced in this process
    "spent": {},             # what -> seconds spent compiling it in this process (finished compilations)
    "depth": 0,              # nesting of numba compilations in progress (a compile compiles its callees)
    "current": None,         # (what, perf_counter at its start) of the top-level compilation in progress
    "last_end": None,        # perf_counter at the end of the last top-level compilation
    "burst": None,           # the compilation being shown: dict(what, shown, last)
    "functions": 0,          # labtool functions compiled in this process
    "quiet": int(os.environ.get("LABTOOL_COMPILE_NOTICES", "1") == "0"),   # quiet() nesting; the variable
                             # set to 0 silences it all (a script that reads stderr, the test suite)
    "thread": None,
    "listening": False,
}


def totals() -> tuple[int, float]:
    """(labtool functions compiled, seconds spent compiling them) in this process so far."""
    with _lock:
        return _state["functions"], sum(_spent(w) for w in set(_state["spent"]) | {_current_what()} if w)


def _current_what():
    current = _state["current"]
    return None if current is None else current[0]


def _spent(what: str) -> float:
    """Seconds spent compiling ``what`` so far, the compilation in progress included."""
    s = _state["spent"].get(what, 0.0)
    current = _state["current"]
    if current is not None and current[0] == what:
        s += time.perf_counter() - current[1]
    return s


@contextlib.contextmanager
def announce(what: str):
    """Announce (once a process) and show the progress of any compilation of labtool code inside
    (module doc); ``what``: a noun phrase, "the elastic model"."""
    listen()
    with _lock:
        _state["scopes"].append(what)
    try:
        yield
    finally:
        with _lock:
            _state["scopes"].pop()
            burst = _state["burst"]
            if burst is not None and burst["what"] == what and _state["depth"] == 0:
                _end_burst()


def announces(what: str):
    """Decorator: the function runs inside ``announce(what)``."""
    def wrap(fn):
        import functools

        @functools.wraps(fn)
        def inner(*args, **kwargs):
            with announce(what):
                return fn(*args, **kwargs)
        return inner
    return wrap


@contextlib.contextmanager
def quiet():
    """No announcement and no progress inside (the caller shows its own); compilations still count
    in ``totals``."""
    listen()
    with _lock:
        _state["quiet"] += 1
    try:
        yield
    finally:
        with _lock:
            _state["quiet"] -= 1


def estimate_text(*whats: str) -> str:
    seconds = [ESTIMATES_S.get(w) for w in whats]
    return "a few seconds" if None in seconds else f"about {sum(seconds):.0f} s"


def has_entry(dispatcher, first_argument: str | None = None) -> bool:
    """Does numba's on-disk cache hold a compiled ``dispatcher`` (a labtool ``jit`` function), up
    to date (its index's stamp is the sources' one), for a first argument whose numba type starts
    with ``first_argument`` ("ElasticModel(": the driver compiled for that model), or for any
    arguments? Reads the function's small index file only; False when caching is off or the index
    is foreign or unreadable (then it will compile)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is None:
        return False
    try:
        index = cache_file._load_index()
    except Exception:                               # noqa: BLE001  (an unreadable index: it will compile)
        return False
    return any(first_argument is None or (key[0] and str(key[0][0]).startswith(first_argument))
               for key in index)


def announce_now(whats) -> None:
    """One notice now, before anything compiles, for the ``whats`` (noun phrases, as ``announce``'s)
    that a command is about to compile (the caller knows their cache entries are missing: a
    command's first compilation may come seconds after its start); each is then not announced
    again, and its compilations show progress as usual."""
    listen()
    with _lock:
        whats = [w for w in whats if w not in _state["announced"]]
        if not whats or _state["quiet"]:
            return
        _state["announced"].update(whats)
    names = whats[0] if len(whats) == 1 else ", ".join(whats[:-1]) + " and " + whats[-1]
    _write(f"labtool: compiling {names} for this machine ({estimate_text(*whats)}, once: later runs load "
           f"{'it' if len(whats) == 1 else 'them'} from numba's cache)\n")


def _fallback_what(module: str) -> str:
    """What to call a compilation outside every announced scope, from the function's module."""
    if module.startswith("labtool.processing"):
        return "the processing kernels"
    if module.startswith("labtool.reports"):
        return "the report's metrics"
    if module.startswith(("labtool.models.dynamics.kernels.twin", "labtool.models.dynamics.twin")):
        return "the stand's twin"
    if module.startswith(("labtool.models.dynamics.kernels.elastic", "labtool.models.dynamics.elastic")):
        return "the elastic model"
    if module.startswith(("labtool.models.dynamics.kernels.rigid", "labtool.models.dynamics.rigid")):
        return "the rigid model"
    return "labtool's compiled models"


def _ours(data) -> str | None:
    """The module of the compiled function if it is labtool's, else None."""
    fn = getattr(data.get("dispatcher"), "py_func", None)
    module = getattr(fn, "__module__", None) or ""
    return module if module.startswith("labtool.") else None


def listen() -> None:
    """Follow numba's compilations from now on (labtool.models.dynamics.jit does, at its import)."""
    with _lock:
        if _state["listening"]:
            return
        _state["listening"] = True
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, ev):
            _compile_started(ev.data)

        def on_end(self, ev):
            _compile_ended(ev.data)

    event.register("numba:compile", Listener())


def _compile_started(data) -> None:
    with _lock:
        _state["depth"] += 1
        module = _ours(data)
        if module is None:
            return
        _state["functions"] += 1
        if _state["depth"] != 1:
            return
        what = _state["scopes"][-1] if _state["scopes"] else _fallback_what(module)
        _state["current"] = (what, time.perf_counter())
        burst = _state["burst"]
        if burst is not None and burst["what"] != what:
            _end_burst()
            burst = None
        if burst is not None or _state["quiet"]:
            return
        _state["burst"] = dict(what=what, shown=False, drawn=False, last=time.perf_counter())
        if what not in _state["announced"]:
            _state["announced"].add(what)
            _write(f"labtool: compiling {what} for this machine ({estimate_text(what)}, once: later runs "
                   "load it from numba's cache)\n")
        _start_thread()


def _compile_ended(data) -> None:
    with _lock:
        _state["depth"] = max(0, _state["depth"] - 1)
        current = _state["current"]
        if _state["depth"] == 0 and current is not None:
            now = time.perf_counter()
            _state["spent"][current[0]] = _state["spent"].get(current[0], 0.0) + now - current[1]
            _state["current"] = None
            _state["last_end"] = now


def _terminal() -> bool:
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def _write(text: str) -> None:
    try:
        sys.stderr.write(text)
        sys.stderr.flush()
    except (OSError, ValueError):                       # a closed or broken stderr: stay silent
        pass


def _start_thread() -> None:
    thread = _state["thread"]
    if thread is not None and thread.is_alive():
        return
    thread = threading.Thread(target=_tick, name="labtool-compile-progress", daemon=True)
    _state["thread"] = thread
    thread.start()


def _tick() -> None:
    """The progress thread: redraws (terminal) or writes (elsewhere) while a compilation lasts. A
    burst outside every scope ends after IDLE_S without compilation; one inside a scope lasts as
    long as the scope (a model compiles in several bursts between its Python steps), its terminal
    line cleared while nothing compiles, so the command's own output does not land on it."""
    while True:
        time.sleep(TICK_S)
        with _lock:
            burst = _state["burst"]
            if burst is None:
                _state["thread"] = None
                return
            now = time.perf_counter()
            idle = _state["depth"] == 0 and (_state["last_end"] is None or now - _state["last_end"] > IDLE_S)
            if idle and burst["what"] not in _state["scopes"]:
                _end_burst()
                _state["thread"] = None
                return
            if idle:
                if burst["drawn"]:
                    _write("\r\033[K")
                    burst["drawn"] = False
            elif _spent(burst["what"]) >= PROGRESS_AFTER_S:
                _show(burst, now)


def _show(burst: dict, now: float) -> None:
    what = burst["what"]
    spent, estimate = _spent(what), ESTIMATES_S.get(what)
    if _terminal():
        if estimate:
            width = 24
            done = min(width - 1, int(width * spent / estimate))
            text = f"labtool: compiling {what} [{'#' * done}{'-' * (width - done)}] {spent:.0f} s of about {estimate:.0f} s"
        else:
            text = f"labtool: compiling {what}: {spent:.0f} s"
        _write("\r" + text + "\033[K")
        burst["shown"] = burst["drawn"] = True
    elif not burst["shown"] or now - burst["last"] >= STATUS_EVERY_S:
        about = f" (about {estimate:.0f} s in all)" if estimate else ""
        _write(f"labtool: still compiling {what}: {spent:.0f} s so far{about}\n")
        burst["shown"], burst["last"] = True, now


def _end_burst() -> None:
    """The last word of a burst that showed progress: how long it took (the terminal's line
    replaced by it)."""
    burst = _state["burst"]
    _state["burst"] = None
    if burst is None or not burst["shown"]:
        return
    text = f"labtool: compiled {burst['what']} in {_spent(burst['what']):.0f} s"
    _write(f"\r{text}\033[K\n" if _terminal() else f"{text}\n")
