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
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=tree, env=env, capture_output=True,
                         text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


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
    again = _run(tree, cache)
    assert again["hits"] >= 1 and again["misses"] == 0            # loaded from the disk cache
    assert again["nfev"] == first["nfev"]

    driver = tree / "labtool" / DRIVER
    text = driver.read_text()
    assert "SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9," in text
    driver.write_text(text.replace("SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9,", "SAFETY, MIN_FACTOR, MAX_FACTOR = 0.5,"))
    edited = _run(tree, cache)
    assert edited["misses"] >= 1 and edited["hits"] == 0            # the stale entry was not used
    assert edited["nfev"] != first["nfev"]                          # the new controller ran
