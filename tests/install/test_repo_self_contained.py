"""The repository stands alone: it cites no file it does not contain, and every section of
``docs/architecture.md`` that the code cites exists."""

from __future__ import annotations

import re
from pathlib import Path

from .readme import REPO_ROOT, repo_files

ARCHITECTURE = REPO_ROOT / "docs" / "architecture.md"
# Files of the project's private working notes that are not part of the repository.
OUTSIDE = ("DESIGN.md", "STYLE.md", "NOTES.md", "../shared", "shared/seed", "/work/shared")
GENERATED = Path("tests/fastdds_peer/gen")     # fastddsgen's output, committed as generated
THIS_FILE = Path(__file__).resolve().relative_to(REPO_ROOT)
CITATION = re.compile(r"docs/architecture\.md\)?\s*§\s*(\d+)")


def _texts() -> dict[Path, str]:
    texts = {}
    for rel in repo_files():
        if rel == THIS_FILE or GENERATED in rel.parents:
            continue
        try:
            texts[rel] = (REPO_ROOT / rel).read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue    # binary files
    return texts


def test_no_file_cites_files_outside_the_repository():
    # GIVEN every file of the repository (generated code aside)
    found = [f"{rel}:{n}: {line.strip()}"
             for rel, text in _texts().items()
             for n, line in enumerate(text.splitlines(), 1)
             if any(name in line for name in OUTSIDE)]
    # THEN none mentions the design notes or the paper by a path outside the repository
    assert not found, "references to files outside the repository:\n" + "\n".join(found)


def test_architecture_document_keeps_the_section_numbers_code_cites():
    # GIVEN docs/architecture.md  THEN its numbered sections are 1..10, in order
    headings = re.findall(r"^## (\d+)\. (.+)$", ARCHITECTURE.read_text(encoding="utf-8"), flags=re.MULTILINE)
    assert [int(n) for n, _ in headings] == list(range(1, 11))
    titles = {int(n): t for n, t in headings}
    assert titles[3].startswith("Frames and units")
    assert titles[7].startswith("MAVLink") and "not built" not in titles[7]


def test_every_cited_architecture_section_exists():
    # GIVEN every "docs/architecture.md §N" in the repository
    sections = {int(n) for n in re.findall(r"^## (\d+)\. ", ARCHITECTURE.read_text(encoding="utf-8"), flags=re.MULTILINE)}
    cited = [(rel, int(n)) for rel, text in _texts().items() for n in CITATION.findall(text)]
    # THEN the code does cite it, and each cited section is a heading of the document
    assert len({rel for rel, _ in cited if rel.parts[0] == "unetyemu_ecs"}) >= 15
    missing = [f"{rel}: §{n}" for rel, n in cited if n not in sections]
    assert not missing, "cited sections missing from docs/architecture.md: " + ", ".join(missing)
