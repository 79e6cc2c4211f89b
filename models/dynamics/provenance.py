"""Provenance of a simulation dataset: the whole scene, the mechanism's source and labtool's version.

Every dataset ``labtool.models.dynamics.simulate.simulate`` returns carries these attributes (CF: a dataset's
attributes say how it was made), so a file written by ``labtool simulate -o`` can be simulated
again from its attributes alone.
"""
from __future__ import annotations

import dataclasses
import functools
from importlib import metadata

# Scene field -> (attribute name, how to store it): names carry their unit as elsewhere in labtool
SCENE_ATTRIBUTES = {
    "law": "law", "cam_speed_rpm": "cam_speed_rpm", "Fu": "Fu_N", "backlash": "backlash_m",
    "jt_factor": "jt_factor", "omega1_mode": "omega1_mode", "restitution": "restitution",
    "contact_length": "contact_length_m", "kc_factor": "kc_factor",
    "contact_damping": "contact_damping_s_per_m", "elastic_gap": "elastic_gap", "accuracy": "accuracy",
    "revolutions": "revolutions", "rise_only": "rise_only",
}


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
    """Every field of the scene (netCDF attributes: booleans as 0/1), the mechanism's source and
    labtool's version with the hash of its compiled kernels' source."""
    from labtool.models.dynamics.jit import KERNEL_SOURCES_HASH

    fields = {f.name for f in dataclasses.fields(scene)} - {"mechanism"}
    missing = fields - set(SCENE_ATTRIBUTES)
    if missing:        # a new Scene field must be recorded too
        raise AssertionError(f"provenance: Scene fields without an attribute name: {sorted(missing)}")
    out = {}
    for field, name in SCENE_ATTRIBUTES.items():
        value = getattr(scene, field)
        out[name] = int(value) if isinstance(value, bool) else value
    out.update(mechanism_attributes(scene.mechanism))
    out.update(labtool_version=labtool_version(), labtool_kernels_sha256=KERNEL_SOURCES_HASH[:16])
    return out
