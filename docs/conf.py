"""Sphinx configuration of r2rsim's documentation: the user guides of docs/ (Markdown, read
by MyST), the tutorial, and the API reference generated from the numpydoc docstrings.

Build it (as .ci/run does, warnings are errors)::

    pip install -e ".[docs]"
    sphinx-build -W --keep-going -b html docs docs/_build/html
"""

from r2rsim import __version__

project = "r2rsim"
author = "r2rsim developers"
copyright = "2026, r2rsim developers"
version = release = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "ci-example", "reproduction", "**/__pycache__"]

# MyST: `$`-free Markdown as the guides are written; headings get anchors for #links
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]
# The guides link to files of the repository outside docs/ (lines/, scenarios/, tests/,
# benchmarks/): they are not pages of the site. tests/test_doc_references.py checks that
# every such link resolves in the repository instead.
suppress_warnings = ["myst.xref_missing"]

# API reference: numpydoc docstrings; the documented names only, in source order
autodoc_default_options = {"members": False, "member-order": "bysource"}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False

html_theme = "alabaster"
html_title = f"r2rsim {release}"
