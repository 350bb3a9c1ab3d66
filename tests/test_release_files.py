"""The files a release carries agree with the package: CITATION.cff cites this version and
the thesis, CHANGELOG.md has a section for it."""

from __future__ import annotations

import re

import yaml

from r2rsim import __version__

from conftest import REPO


def _release(version: str) -> str:
    """0.2.0.dev0 -> 0.2.0: the release a development version leads to."""
    return re.match(r"\d+\.\d+\.\d+", version).group(0)


def test_citation_cites_this_version_and_the_thesis():
    cff = yaml.safe_load((REPO / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0"
    assert cff["version"] == __version__
    assert cff["license"] == "BSD-3-Clause"
    thesis = [r for r in cff["references"] if r["type"] == "thesis"]
    assert len(thesis) == 1 and thesis[0]["year"] == 2018
    assert thesis[0]["authors"][0]["family-names"] == "Shui"


def test_changelog_has_this_release():
    text = (REPO / "CHANGELOG.md").read_text(encoding="utf-8")
    heads = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", text, flags=re.M)
    assert heads and heads[0] == _release(__version__)
