"""Every document the repository mentions is in the repository.

Users read README.md and docs/ from a checkout, and the code, line files and tests point
them at sections of those documents ("docs/physics.md eq. 1.4", "[dataset.md](dataset.md)").
This test scans every tracked text file for

(a) mentions of a ``*.md`` file name, and
(b) relative markdown link targets ``](path)`` (web, mailto and ``#anchor`` links skipped),

and asserts that each resolves to a file of the repository: a bare name against the
mentioning file's directory, the repository root and ``docs/``; a path with a slash against
the mentioning file's directory and the root. Files come from ``git ls-files`` (tracked and
untracked-but-not-ignored); without git (an sdist) the tree is walked.

It also checks that a cited place exists in docs/physics.md or docs/solver.md (an equation
"eq. 1.4", a section "§2.3", a verification case "V22"), and that nothing cites the
project's design notes, which are not part of the repository, by section.
"""

from __future__ import annotations

import functools
import os
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SELF = Path(__file__).resolve().relative_to(REPO).as_posix()

SUFFIXES = {".md", ".py", ".yaml", ".yml", ".toml", ".txt", ".cfg", ".sh"}
EXTRA = {".ci/run"}
SKIP_DIRS = {
    ".git",
    "__pycache__",
    ".pytest_cache",
    ".ruff_cache",
    "build",
    "dist",
    "runs",
    ".venv",
    "venv",
    "node_modules",
}

#: ``*.md`` names that are not documents of this repository but files that scripts write
#: into their output directory: bare (``writes report.md``) or under a placeholder
#: (``OUT/report.md``).
GENERATED = {"report.md"}

URL = re.compile(r"(?:https?|file|ftp)://\S+|mailto:\S+")
MD_NAME = re.compile(r"(?<![\w./*{}<>-])((?:\.{1,2}/)*(?:[\w-]+/)*[\w-]+\.md)\b(?!\()")
LINK = re.compile(r"\]\(\s*<?([^()\s<>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def _files() -> list[str]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
            cwd=REPO,
            capture_output=True,
            check=True,
            timeout=20,
        ).stdout
        names = [n for n in out.decode("utf-8", "replace").split("\0") if n]
    except (OSError, subprocess.SubprocessError):
        names = []
        for root, dirs, files in os.walk(REPO):
            dirs[:] = [d for d in dirs if d not in SKIP_DIRS and not d.endswith(".egg-info")]
            for f in files:
                names.append(Path(root, f).relative_to(REPO).as_posix())
    return sorted(
        n for n in names if (Path(n).suffix in SUFFIXES or n in EXTRA) and (REPO / n).is_file()
    )


@functools.lru_cache(maxsize=1)
def _texts() -> tuple[tuple[str, str], ...]:
    """(name, text) of every scanned file but this one."""
    out = []
    for name in _files():
        if name == SELF:
            continue  # its own examples of good and bad references
        try:
            out.append((name, (REPO / name).read_text(encoding="utf-8")))
        except (UnicodeDecodeError, OSError):
            continue
    return tuple(out)


def _generated(target: str) -> bool:
    head, _, base = target.rpartition("/")
    return base in GENERATED and (not head or re.fullmatch(r"[A-Z_]+", head) is not None)


def _resolves(target: str, source: str) -> bool:
    """True when ``target`` (as written in ``source``) names a file of the repository."""
    target = target.split("#", 1)[0].split("?", 1)[0]
    if not target:
        return True  # a pure anchor
    here = (REPO / source).parent
    bases = [here, REPO] + ([REPO / "docs"] if "/" not in target else [])
    for base in bases:
        p = (base / target).resolve()
        try:
            p.relative_to(REPO)
        except ValueError:
            continue  # outside the repository: users do not have it
        if p.exists():
            return True
    return False


@functools.lru_cache(maxsize=1)
def _references() -> tuple[tuple[str, int, str], ...]:
    """(file, line number, target) of every document mention and relative link."""
    refs = []
    for name, text in _texts():
        for no, line in enumerate(text.splitlines(), 1):
            line = URL.sub(" ", line)
            for m in MD_NAME.finditer(line):
                if not _generated(m.group(1)):
                    refs.append((name, no, m.group(1)))
            if name.endswith(".md"):
                for m in LINK.finditer(line):
                    target = m.group(1)
                    if target.startswith(("#", "mailto:")) or re.match(r"\w+:", target):
                        continue
                    refs.append((name, no, target))
    return tuple(refs)


def test_the_model_documents_are_in_docs():
    for name in ("physics.md", "solver.md", "model.md", "dataset.md", "diagnostics.md"):
        assert (REPO / "docs" / name).is_file(), f"docs/{name} is missing"


def test_scan_finds_the_references_it_is_meant_to_check():
    refs = _references()
    assert len(refs) > 50
    assert any(t.endswith("physics.md") for _, _, t in refs)


def test_every_mentioned_document_is_in_the_repository():
    missing = [f"{f}:{no}: {t}" for f, no, t in _references() if not _resolves(t, f)]
    assert not missing, "documents mentioned but not in the repository:\n" + "\n".join(missing)


@pytest.mark.parametrize(
    "target, source, ok",
    [
        ("physics.md", "lines/pet_film_line.yaml", True),  # bare name: found in docs/
        ("dataset.md#3-samples", "docs/model.md", True),  # same directory, anchor dropped
        ("docs/physics.md", "r2rsim/schema/line.py", True),  # path: against the root
        ("../elsewhere/notes.md", "docs/model.md", False),  # outside the repository
        ("NOT_IN_THE_REPO.md", "README.md", False),
    ],
)
def test_resolution_rules(target, source, ok):
    assert _resolves(target, source) is ok


#: a section cited by a document's name without ``.md`` ("NOTES §8", "some-notes §5"): an
#: upper-case or hyphenated name before "§" must be a document of the repository
#: (``README §2`` is README.md); a plain word ("thesis §3.5", "of §2") is not a name
SECTION_OF = re.compile(r"\b([A-Z][A-Z0-9_]{2,}|[a-z0-9]+(?:-[a-z0-9]+)+)`?\s*§")


def _unresolved_section_citations(name: str, text: str) -> list[str]:
    return [
        f"{name}:{no}: {line.strip()}"
        for no, line in enumerate(text.splitlines(), 1)
        for m in SECTION_OF.finditer(line)
        if not _resolves(m.group(1) + ".md", name)
    ]


@pytest.mark.parametrize(
    "line, found",
    [
        ("see NOTES §8", True),
        ("the some-notes §5.5 protocol", True),
        ("README §2", False),
        ("thesis §3.5", False),
        ("docs/dataset.md §8.2", False),
    ],
)
def test_the_section_rule(line, found):
    assert bool(_unresolved_section_citations("README.md", line)) is found


def test_no_section_citation_of_a_document_outside_the_repository():
    bad = []
    for name, text in _texts():
        bad += _unresolved_section_citations(name, text)
    assert not bad, "\n".join(bad)


#: "physics.md eq. 1.4", "physics.md §2.3", "physics.md 1.10", "physics.md V22(b)",
#: "solver.md §4.1": the place a mention points at inside the document.
PLACE = re.compile(
    r"\b(physics|solver)\.md\W{0,3}\s*"
    r"(?:eqs?\.\s*\(?(\d\.\d+)|§\s*(\d+(?:\.\d+)?)|(\d\.\d+)\b|V(\d+))"
)


def test_cited_sections_equations_and_cases_exist():
    docs = {
        d: (REPO / "docs" / f"{d}.md").read_text(encoding="utf-8") for d in ("physics", "solver")
    }
    headings = {
        d: set(re.findall(r"^#{2,4} (\d+(?:\.\d+)?)[. ]", t, re.M)) for d, t in docs.items()
    }
    missing = []
    for name, text in _texts():
        for m in PLACE.finditer(text):
            doc, eq, sec, bare, case = m.groups()
            if eq:
                ok = f"({eq})" in docs[doc]
            elif case:
                ok = f"**V{case} —" in docs[doc]
            else:
                ok = (sec or bare) in headings[doc]
            if not ok:
                missing.append(f"{name}: {m.group(0)!r}")
    assert not missing, "\n".join(missing)
