"""Sphinx configuration of labtool's documentation (``make docs``).

Markdown pages through MyST, the Python API reference from the numpydoc docstrings, and the
example scripts of ``docs/examples/`` executed by sphinx-gallery on every build, so a page that no
longer runs fails the build (``-W``: every warning is an error).
"""
from __future__ import annotations

import os
import warnings

import labtool

project = "labtool"
author = "labtool's authors"
copyright = "labtool's authors, MIT licence"
version = release = labtool.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.intersphinx",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
# examples/ is read by sphinx-gallery, which writes the pages of auto_examples/
exclude_patterns = ["_build", "examples", "auto_examples/*.ipynb", "auto_examples/*.py",
                    "auto_examples/*.zip", "auto_examples/*.md5", "auto_examples/*.json"]

# --- MyST: the pages stay plain Markdown that reads well on a forge too
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3          # [text](page.md#a-heading) links resolve

# --- API reference: numpydoc, and every parameter of every documented function documented
autodoc_default_options = {"members": False}
autodoc_typehints = "none"        # the docstrings state types and units
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
# PR01: a parameter missing from the docstring; PR02: a documented parameter the function lacks
numpydoc_validation_checks = {"PR01", "PR02"}
# a result type the caller reads and never builds: its fields are documented as Attributes
numpydoc_validation_exclude = {r"^labtool\.(Simulation|Acquisition|Kinematics|DesignRun)$"}
intersphinx_mapping = {}

# --- the executed examples: run through the API on the simulated stand during every build
os.environ.setdefault("MPLBACKEND", "Agg")
warnings.filterwarnings("ignore", message="Matplotlib is currently using agg")
sphinx_gallery_conf = {
    "examples_dirs": ["examples"],
    "gallery_dirs": ["auto_examples"],
    "filename_pattern": r"/plot_",          # every plot_*.py is executed
    "abort_on_example_error": True,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "plot_gallery": "True",
}

# --- HTML
html_theme = "furo"
html_title = f"labtool {release}"
html_static_path = []
html_show_sourcelink = False
