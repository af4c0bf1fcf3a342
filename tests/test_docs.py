"""The repository stands alone.

Its documents and code refer to the model in docs/model.md, never to a file outside the repository,
and every section they cite exists there, as does every section of docs/performance.md and
docs/performance_history.md they name.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXT = (".py", ".md", ".yaml", ".yml", ".toml", ".txt", ".cfg")


def _tracked_text_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        files = [ROOT / f for f in out.splitlines()]
    except (OSError, subprocess.CalledProcessError):  # not a checkout: every file under the root
        files = [p for p in ROOT.rglob("*") if ".git" not in p.parts]
    return [f for f in files if f.suffix in TEXT and f.is_file() and ".venv" not in f.parts]


def test_nothing_refers_to_files_outside_the_repository():
    files = _tracked_text_files()
    assert len(files) > 50
    bad = [
        f"{f.relative_to(ROOT)}: {line.strip()}"
        for f in files
        if f.name != "test_docs.py"
        for line in f.read_text(errors="replace").splitlines()
        if "../shared" in line or re.search(r"(?<![\w/.])MODEL\.md", line)
    ]
    assert not bad, "\n".join(bad)


def test_every_cited_section_of_the_model_exists():
    model = (ROOT / "docs" / "model.md").read_text()
    sections = set(re.findall(r"^## (\d+[a-z]?)\. ", model, flags=re.M))
    assert {str(n) for n in range(1, 11)} <= sections
    cited = {
        m
        for f in _tracked_text_files()
        for m in re.findall(r"docs/model\.md §(\d+[a-z]?)", f.read_text(errors="replace"))
    }
    assert cited, "nothing cites the model"
    assert cited <= sections, f"cited but missing in docs/model.md: {sorted(cited - sections)}"


@pytest.mark.parametrize("name", ["performance", "performance_history"])
def test_every_named_section_of_the_performance_notes_exists(name):
    notes = (ROOT / "docs" / f"{name}.md").read_text()
    headings = {h.strip() for h in re.findall(r"^#{2,3} (.+)$", notes, flags=re.M)}
    named = set()
    for f in _tracked_text_files():
        # a citation may wrap onto the next line of a comment or docstring
        text = re.sub(r"\s*\n\s*(?:#\s*)?", " ", f.read_text(errors="replace"))
        named |= set(re.findall(rf'docs/{name}\.md, "([^"]+)"', text))
    assert named, f"nothing names a section of docs/{name}.md"
    # a name is a heading or its start ("Borrowed views" for "Borrowed views: no reference counts ...")
    missing = sorted(n for n in named if not any(h.startswith(n) for h in headings))
    assert not missing, f"named but missing in docs/{name}.md: {missing}"


@pytest.mark.parametrize(
    "name", ["damping_bend", "damping_stretch", "length_lag", "added_mass", "mu_forward", "duty", "refine"]
)
def test_the_model_documents_the_new_parameters(name):
    assert name in (ROOT / "docs" / "model.md").read_text()
