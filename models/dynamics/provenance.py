"""Provenance of a simulation dataset: the whole scene, the mechanism's source and labtool's version.

Every dataset ``labtool.models.dynamics.simulate.simulate`` returns carries these attributes (CF: a dataset's
attributes say how it was made), so a file written by ``labtool simulate -o`` can be simulated
again from its attributes alone.
"""
from __future__ import annotations

import functools
from importlib import metadata

from labtool.common.operating_point import OperatingPoint, from_attrs


@functools.lru_cache(maxsize=1)
def labtool_version() -> str:
    try:
        return metadata.version("labtool")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


@functools.lru_cache(maxsize=1)
def models_source_sha256() -> str:
    """SHA-256 of every Python source and data file of the ``models`` package: what a sweep's
    results depend on besides its inputs. labtool's version alone does not change in a checkout,
    and the kernels' hash (labtool.models.dynamics.jit) covers compiled code only."""
    from pathlib import Path
    return tree_sha256(Path(__file__).resolve().parents[1])


def tree_sha256(root) -> str:
    """SHA-256 of the .py, .toml and .csv files below ``root`` (relative paths and contents, sorted;
    caches such as __pycache__ do not count)."""
    import hashlib
    from pathlib import Path

    root = Path(root)
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.suffix in (".py", ".toml", ".csv") and p.is_file()):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def mechanism_attributes(mech) -> dict:
    """The mechanism's name, source (a file path, or built-in) and the SHA-256 of its TOML text."""
    return {"mechanism": mech.name, "mechanism_source": mech.source, "mechanism_sha256": mech.source_sha256}


def scene_attributes(scene) -> dict:
    """The scene as attributes (netCDF: booleans as 0/1): its operating point as the owner writes
    it (OperatingPoint.attrs, edge units), its extent, the mechanism's source and labtool's version
    with the hash of its compiled kernels' source. ``scene_from_attributes`` reads it back."""
    from labtool.models.dynamics.jit import KERNEL_SOURCES_HASH

    out = OperatingPoint.attrs(scene)
    out.update(revolutions=float(scene.revolutions), rise_only=int(scene.rise_only))
    out.update(mechanism_attributes(scene.mechanism))
    out.update(labtool_version=labtool_version(), labtool_kernels_sha256=KERNEL_SOURCES_HASH[:16])
    return out


def scene_from_attributes(attrs, mechanism=None):
    """The Scene a dataset's attributes (``scene_attributes``) describe, with ``mechanism`` (default:
    the built-in one; a dataset records its mechanism's source and hash, not its parameters)."""
    from labtool.models.dynamics.scene import Scene
    from labtool.models.mechanism import Mechanism

    point = from_attrs(attrs, where="the dataset")
    return Scene.at(point, revolutions=float(attrs.get("revolutions", 1.0)),
                    rise_only=bool(int(attrs.get("rise_only", 1))), mechanism=mechanism or Mechanism.default())
