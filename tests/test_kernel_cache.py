"""The numba disk cache of the compiled loops cannot go stale (labtool.models.dynamics.jit).

A copy of the package runs in fresh processes that share one NUMBA_CACHE_DIR: a second run loads
the loop from the cache; after a constant of the Dormand-Prince driver (a file the loop inlines,
not the loop's own file) is edited, the next run recompiles and computes with the new value.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DRIVER = Path("models/dynamics/kernels/dopri5.py")

PROBE = """
import json
from labtool.models.dynamics import accuracy, jit
from labtool.models.dynamics.scene import Scene
from labtool.models.dynamics.kernels import dopri5
stats = {}
accuracy.run_model(Scene(accuracy="fast"), "elastic", stats=stats)
loop = dopri5.run
print(json.dumps(dict(nfev=stats["nfev"], hits=sum(loop.stats.cache_hits.values()),
                      misses=sum(loop.stats.cache_misses.values()), caching=jit.CACHING)))
"""


def _run(tree: Path, cache: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(tree), LABTOOL_COMPILE_NOTICES="1")
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=tree, env=env, capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    return dict(json.loads(out.stdout.strip().splitlines()[-1]), stderr=out.stderr)


@pytest.mark.slow
def test_an_edited_kernel_constant_is_recompiled_not_loaded_stale(tmp_path):
    tree = tmp_path / "tree"                     # laid out as the wheel installs it: labtool/models, ...
    (tree / "labtool").mkdir(parents=True)
    shutil.copy2(ROOT / "labtool" / "__init__.py", tree / "labtool" / "__init__.py")
    for pkg in ("models", "common"):
        shutil.copytree(ROOT / pkg, tree / "labtool" / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "numba_cache"
    first = _run(tree, cache)
    assert first["caching"] is True
    # an empty cache: the compilation is announced, once (labtool.models.dynamics.compiling)
    assert first["stderr"].count("labtool: compiling the elastic model for this machine (about ") == 1
    again = _run(tree, cache)
    assert again["hits"] >= 1 and again["misses"] == 0            # loaded from the disk cache
    assert again["nfev"] == first["nfev"]
    assert "compil" not in again["stderr"]                        # nothing compiled: nothing said

    driver = tree / "labtool" / DRIVER
    text = driver.read_text()
    assert "SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9," in text
    driver.write_text(text.replace("SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9,", "SAFETY, MIN_FACTOR, MAX_FACTOR = 0.5,"))
    edited = _run(tree, cache)
    assert edited["misses"] >= 1 and edited["hits"] == 0            # the stale entry was not used
    assert edited["nfev"] != first["nfev"]                          # the new controller ran


FOREIGN_PROBE = """
import importlib, json, sys
import numpy as np
kernels = importlib.import_module(sys.argv[1])
x = np.ascontiguousarray(np.sin(np.linspace(0.0, 20.0, 500))[:, None].repeat(2, axis=1))
lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
kernels.scan_block(x, lo, hi)
peaks = kernels.find_peaks(np.abs(x[:, 0]), 0.5, 5)
print(json.dumps(dict(lo=lo.tolist(), hi=hi.tolist(), peaks=np.asarray(peaks).tolist(),
                      hits=sum(kernels.scan_block.stats.cache_hits.values()))))
"""


def _foreign(module: str, cache: Path, pythonpath: str | None = None) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath
    out = subprocess.run([sys.executable, "-c", FOREIGN_PROBE, module], cwd=cache.parent, env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_a_cache_written_under_other_module_names_is_compiled_again_not_a_crash(tmp_path):
    """The layout before the one ``labtool`` package: the same processing/kernels.py imported as
    ``processing.kernels`` (the repository on the path). Its cached entries name that module; the
    same file under its ``labtool.`` name (same source, so the same stamp) must compile again
    instead of raising ModuleNotFoundError, then load its own entries."""
    cache = tmp_path / "numba_cache"
    old = _foreign("processing.kernels", cache, pythonpath=str(ROOT))
    new = _foreign("labtool.processing.kernels", cache)
    assert new["hits"] == 0                                    # the foreign entry was not used
    assert new == old
    again = _foreign("labtool.processing.kernels", cache)
    assert again["hits"] >= 1 and {**again, "hits": 0} == new   # its own entry, loaded


@pytest.mark.slow
def test_a_damaged_cache_index_is_a_miss(tmp_path):
    cache = tmp_path / "numba_cache"
    first = _foreign("labtool.processing.kernels", cache)
    indexes = list(cache.rglob("*.nbi")) + list(cache.rglob("*.nbc"))
    assert indexes
    for path in indexes:                       # cut short, as by a full disk or a killed writer
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    assert {**_foreign("labtool.processing.kernels", cache), "hits": 0} == {**first, "hits": 0}
