"""What a release carries and what a new user reads: the licence the package declares, a
changelog, citation metadata matching the version, templates in the package data, documents
that name the physics and the literature rather than internal work items, and scripts that say
where their data comes from."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import yaml

import insgnss
from insgnss.commands.init import FORMATS, template_path

REPO = Path(__file__).resolve().parents[1]
#: internal references that mean nothing to a reader of the documents
INTERNAL = re.compile(r"seed (report|000|001|002|003|004|eq)|seed's|\bissue [0-9]+(?!\.[0-9])|\(issue\b|"
                      r"\bsession\b", re.I)


def test_licence_changelog_citation():
    meta = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "BSD-3-Clause"
    lic = (REPO / "LICENSE").read_text()
    assert lic.startswith("BSD 3-Clause License") and "Neither the name of the copyright" in lic
    cff = yaml.safe_load((REPO / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["license"] == "BSD-3-Clause"
    assert str(cff["version"]) == insgnss.__version__
    log = (REPO / "CHANGELOG.md").read_text()
    assert "## [Unreleased]" in log and f"## [{insgnss.__version__}]" in log


def test_templates_are_package_data():
    data = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]["insgnss"]
    assert "data/templates/*.toml" in data
    for fmt in FORMATS:
        assert template_path(fmt).is_file()


def test_documents_have_no_internal_references():
    files = [REPO / "README.md", REPO / "CHANGELOG.md", *sorted((REPO / "docs").glob("*.md")),
             *sorted((REPO / "insgnss").rglob("*.py")), *sorted((REPO / "bench").glob("*.py")),
             *sorted((REPO / "scenarios").rglob("*.py")), *sorted((REPO / "scenarios").rglob("*.toml"))]
    hits = []
    for f in files:
        rel = f.relative_to(REPO).as_posix()
        for k, line in enumerate(f.read_text().splitlines(), 1):
            if INTERNAL.search(line):
                hits.append(f"{rel}:{k}: {line.strip()}")
    assert not hits, "\n".join(hits)


def test_run_pyshoe_says_where_the_data_comes_from(tmp_path):
    r = subprocess.run([sys.executable, str(REPO / "scenarios" / "pyshoe" / "run_pyshoe.py"),
                        "--data", str(tmp_path / "nowhere")], capture_output=True, text=True,
                       cwd=REPO, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "10.21227/v1z6-9z84" in r.stderr and "--data" in r.stderr
    r = subprocess.run([sys.executable, str(REPO / "scenarios" / "pyshoe" / "run_pyshoe.py"),
                        "--data", str(tmp_path)], capture_output=True, text=True, cwd=REPO,
                       timeout=300)
    assert r.returncode == 2 and "no .mat trial" in r.stderr
