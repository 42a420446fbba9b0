"""The first page and the docs: short, and pointing only inside the repository (the test data's
folder is named in CONTRIBUTING.md alone)."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: a parent folder, or an absolute path on a machine
OUTSIDE = re.compile(r"(?<![\w.])(\.\./[\w./-]*|/(?:work|root|home|tmp|opt|mnt|srv|usr)/)")
#: a relative link in Markdown
LINK = re.compile(r"\]\(([^)#\s]+)")


def doc_files():
    return [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*")
                                        if p.suffix in (".md", ".json", ".txt", ".log"))]


def test_readme_fits_a_first_page():
    readme = (ROOT / "README.md").read_bytes()
    assert len(readme) <= 12_000, len(readme)
    sections = re.findall(r"^## (.+)$", readme.decode(), re.M)
    assert sections[:4] == ["Install in Blender", "Quick start in Blender", "The two commands",
                            "Fill methods"], sections
    assert "bash tools/setup.sh && .venv/bin/mocap-gapfill demo" in readme.decode()
    assert "bash tools/test.sh" in readme.decode()


def test_no_doc_points_outside_the_repository():
    found = []
    for path in doc_files():
        for line, text in enumerate(path.read_text(errors="replace").splitlines(), 1):
            for match in OUTSIDE.finditer(text):
                where = (path.parent / match[1]).resolve()
                if match[1].startswith("../") and where.is_relative_to(ROOT):
                    continue  # a relative link that stays inside
                found.append(f"{path.relative_to(ROOT)}:{line}: {match[1]}")
    assert not found, "\n".join(found)


def test_every_link_in_the_docs_resolves():
    broken = []
    for path in [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *(ROOT / "docs").glob("*.md")]:
        for target in LINK.findall(path.read_text()):
            if "://" not in target and not (path.parent / target).exists():
                broken.append(f"{path.relative_to(ROOT)}: {target}")
    assert not broken, broken
