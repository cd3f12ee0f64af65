"""Every documentation page that the code, its help texts and its docstrings name (a path under
``docs/`` ending in ``.md``) exists, so a reader sent there finds the page."""

from __future__ import annotations

import re
from pathlib import Path

#: Where the product's, the scripts' and the tests' Python files are, relative to the repository.
SCANNED = ("specgen_addon", "ops", "scripts", "bench", "tests", "batch.py", "__init__.py")

#: A documentation page named in text: ``docs/`` then a relative path ending in ``.md``.
DOC_REFERENCE = re.compile(r"docs/[A-Za-z0-9_./-]+\.md")


def _python_files(repo: Path) -> list[Path]:
    files: list[Path] = []
    for name in SCANNED:
        path = repo / name
        if path.is_file():
            files.append(path)
        elif path.is_dir():
            files.extend(p for p in sorted(path.rglob("*.py")) if "__pycache__" not in p.parts)
    return files


def test_every_docs_file_named_in_code_exists(repo_dir: Path) -> None:
    files = _python_files(repo_dir)
    assert len(files) > 100, "the scan found too few Python files to be looking in the right place"
    missing = []
    for path in files:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            for reference in DOC_REFERENCE.findall(line):
                if not (repo_dir / reference).is_file():
                    missing.append(f"{path.relative_to(repo_dir)}:{number}: {reference}")
    assert not missing, "documentation pages named in code but absent:\n" + "\n".join(missing)
