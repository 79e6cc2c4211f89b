"""labtool installs as one import package, ``labtool``, and works beside a user's own modules.

The design card's folders (models/, processing/, ...) stay at the top of the repository and are
mapped into the ``labtool`` namespace by pyproject.toml. Here a wheel is built from the tree,
installed into a fresh virtual environment, and run from a folder holding ``models.py``,
``common.py``, ``reports.py`` and ``processing.py`` that raise if anything imports them.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ("common", "acquisition", "processing", "execution", "models", "reports", "campaign", "identification")
USER_MODULES = ("models", "common", "reports", "processing")


def _tree_packages() -> set[str]:
    out = {"labtool." + ".".join(p.parent.relative_to(ROOT / "labtool").parts) if p.parent != ROOT / "labtool"
           else "labtool" for p in (ROOT / "labtool").rglob("__init__.py")}
    for top in SUBPACKAGES:
        out |= {"labtool." + ".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / top).rglob("__init__.py")}
    return out


def test_pyproject_lists_every_package_of_the_tree():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert set(conf["packages"]) == _tree_packages()
    assert conf["package-dir"] == {"labtool": "labtool", **{f"labtool.{t}": t for t in SUBPACKAGES}}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    # built from a copy of the tracked files: setuptools builds in the tree (build/, *.egg-info),
    # and two test workers building in one tree at once would trip over each other
    src = tmp_path_factory.mktemp("src")
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True).stdout
    for name in filter(None, files.decode().split("\0")):
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(src)],
                   check=True, capture_output=True)
    (whl,) = out.glob("labtool-*.whl")
    return whl


@pytest.mark.slow
def test_the_wheel_installs_labtool_alone_at_the_top(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"labtool"}
    for data in ("labtool/models/data/stb216.toml", "labtool/reports/templates/report.html.j2",
                 "labtool/campaign/templates/campaign.html.j2"):
        assert data in names


@pytest.fixture(scope="module")
def fresh_env(wheel, tmp_path_factory) -> Path:
    """A new venv holding the wheel; the dependencies come from this interpreter's site-packages
    through a .pth line (a path added so is not scanned for .pth files, so this environment's
    editable labtool stays out)."""
    env = tmp_path_factory.mktemp("venv") / "env"
    venv.EnvBuilder(with_pip=False).create(env)
    py = env / "bin" / "python"
    site = Path(subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "-q", str(wheel)],
                   check=True, capture_output=True)
    return env


@pytest.fixture
def shadowing_folder(tmp_path) -> Path:
    for name in USER_MODULES:
        (tmp_path / f"{name}.py").write_text(f"raise RuntimeError('the user\\'s own {name}.py was imported')\n")
    return tmp_path


def _run(env: Path, args, cwd: Path, timeout=900):
    e = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    e["MPLBACKEND"] = "Agg"
    return subprocess.run(args, cwd=cwd, env=e, capture_output=True, text=True, timeout=timeout)


@pytest.mark.slow
def test_python_m_labtool_runs_beside_a_users_models_py(fresh_env, shadowing_folder):
    py = str(fresh_env / "bin" / "python")
    where = _run(fresh_env, [py, "-c", "import labtool.models, labtool.cli; print(labtool.models.__file__)"],
                 shadowing_folder)
    assert where.returncode == 0, where.stderr
    assert str(fresh_env) in where.stdout           # the wheel's copy, not the source tree's
    res = _run(fresh_env, [py, "-m", "labtool", "simulate", "--model", "rigid", "--json"], shadowing_folder)
    assert res.returncode == 0, res.stderr
    assert '"model": "rigid"' in res.stdout


@pytest.mark.slow
def test_labtool_demo_runs_from_the_wheel_beside_a_users_modules(fresh_env, shadowing_folder):
    res = _run(fresh_env, [str(fresh_env / "bin" / "labtool"), "demo", "-o", "out"], shadowing_folder)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert (shadowing_folder / "out" / "report.html").exists()


SCRIPT = """
import labtool
sim = labtool.simulate(model="rigid", accuracy="fast")
measured = labtool.process("r.h5")
print(sim.model, sim.cycles.sizes["phi1"], round(float(measured.attrs["cam_speed_rpm_measured"])))
"""


@pytest.mark.slow
def test_a_script_calls_the_api_from_the_wheel_beside_a_users_modules(fresh_env, shadowing_folder):
    rec = _run(fresh_env, [str(fresh_env / "bin" / "labtool"), "acquire", "--device", "sim", "--fast", "--duration", "2",
                           "--status-every", "0", "-o", "r.h5"], shadowing_folder)
    assert rec.returncode == 0, rec.stderr
    (shadowing_folder / "script.py").write_text(SCRIPT)
    res = _run(fresh_env, [str(fresh_env / "bin" / "python"), "script.py"], shadowing_folder)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == ["rigid", "720", "180"]
