"""The release is ready (issue 33): one version source, install instructions that work before any index
has the package, the research library's records (LICENSE, CITATION.cff, CHANGELOG.md, the release
procedure) and the documentation site in strict mode. .ci/run builds the sdist and the wheel, checks them
with twine and imports the wheel in a fresh virtual environment; the site test here runs where the `docs`
extra is installed."""
import importlib.util
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

import penny_env

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_one_version_source():
    """pyproject.toml reads the version from penny_env.__version__; CHANGELOG.md's newest section and
    CITATION.cff name the same version (docs/release.md changes all three together)."""
    project = PYPROJECT["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "penny_env.__version__"}
    assert re.fullmatch(r"\d+\.\d+\.\d+", penny_env.__version__)
    changelog = (ROOT / "CHANGELOG.md").read_text()
    newest = re.search(r"^## \[(\d+\.\d+\.\d+)\] - (Unreleased|\d{4}-\d{2}-\d{2})$", changelog, re.M)
    assert newest and newest.group(1) == penny_env.__version__, newest
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["version"] == penny_env.__version__
    if newest.group(2) != "Unreleased":  # a tagged release carries its date in both
        assert str(citation["date-released"]) == newest.group(2)


def test_license_and_citation():
    license_text = (ROOT / "LICENSE").read_text()
    assert license_text.startswith("MIT License") and "the penny_env developers" in license_text
    assert PYPROJECT["project"]["license"] == "MIT" and PYPROJECT["project"]["license-files"] == ["LICENSE"]
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["cff-version"] == "1.2.0" and citation["type"] == "software" and citation["license"] == "MIT"
    paper = next(r for r in citation["references"] if r["title"] == "The Bouncing Penny and Nonholonomic Impacts")
    assert [a["family-names"] for a in paper["authors"]] == ["Clark", "Bloch"]
    assert paper["doi"] == "10.1109/CDC40024.2019.9029545" and paper["url"] == "https://arxiv.org/abs/1909.11192"
    assert PYPROJECT["project"]["urls"]["Paper"] == paper["url"]


INSTALL_FROM_INDEX = re.compile(r"pip install\s+(?:-U\s+|--upgrade\s+)?['\"]?penny[-_]env\b")


def test_every_install_instruction_and_hint_installs_from_a_clone():
    """No index has penny-env yet: no instruction (README, docs/) and no error hint (the package, training/)
    may tell anyone to `pip install penny-env`; the README says to install from a clone."""
    files = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "penny_env").rglob("*.py"),
             *(ROOT / "training").rglob("*.py"), *(ROOT / "examples").rglob("*.py")]
    offenders = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in files for m in INSTALL_FROM_INDEX.finditer(p.read_text())
                 if p.name != "release.md"]  # the release procedure shows the install from TestPyPI
    assert offenders == []
    readme = (ROOT / "README.md").read_text()
    assert "not on a package index yet" in readme and "from a clone" in readme


def test_the_cuda_hint_names_the_install_from_a_clone(monkeypatch):
    from penny_env import batch
    monkeypatch.setitem(sys.modules, "numba_cuda", None)  # as if the cuda extra were missing: find_spec -> None
    with pytest.raises(ValueError, match=r'pip install -e "\.\[cuda\]"'):
        batch.simulate([[0.0, 0.0, 0.0, 0.3, 1.0, 0.2]], table=penny_env.Circle(0.2), t_final=0.1, backend="cuda")
    with pytest.raises(ValueError, match=r'pip install -e "\.\[cuda\]"'):
        penny_env.PennyVectorEnv(2, backend="cuda")


def test_torch_comes_from_pytorchs_cpu_index_in_both_readme_commands_and_ci():
    """PyTorch's own instruction for a CPU-only install, in the README's two commands and in .ci/run; the
    README also says how to get the CUDA build."""
    from studies.measure_readme import readme_block, steps_of
    readme = (ROOT / "README.md").read_text()
    cpu = "pip install torch --index-url https://download.pytorch.org/whl/cpu"
    for part in ("main", "tests"):
        steps = steps_of(readme_block(readme, part))
        assert cpu in steps and steps.index(cpu) < next(i for i, s in enumerate(steps) if s.startswith("pip install -e"))
    assert cpu in (ROOT / ".ci" / "run").read_text().splitlines()
    assert "CUDA build" in readme and "pytorch.org/get-started" in readme


def test_release_procedure_and_ci_build_the_same_way():
    release = (ROOT / "docs" / "release.md").read_text()
    for step in ("git tag -a vX.Y.Z", "python -m build", "twine check --strict dist/*", "twine upload dist/*",
                 "CHANGELOG.md", "CITATION.cff", "penny_env/__init__.py"):
        assert step in release, step
    ci = (ROOT / ".ci" / "run").read_text()
    for step in ("python -m build", "twine check --strict dist/*", "mkdocs build --strict"):
        assert step in ci, step
    extras = PYPROJECT["project"]["optional-dependencies"]
    tools = {"docs": ("mkdocs", "mkdocs-material", "mkdocstrings"), "release": ("build", "twine")}
    for extra, names in tools.items():
        assert all(any(dep.startswith(n) for dep in extras[extra]) for n in names), extra
        assert f"penny-env[{extra}]" not in extras["all"][0] and extra not in extras["all"][0]
    assert not any(d.startswith(("build", "twine", "mkdocs")) for d in PYPROJECT["project"]["dependencies"])


def test_the_site_lists_every_page_of_docs():
    """mkdocs.yml's navigation has every Markdown page of docs/ (a page left out of it is a warning, which
    the strict build turns into an error: this says which one without building)."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text().replace("!!python", "#"))

    def pages(nav):
        for item in nav:
            for value in item.values():
                yield from (pages(value) if isinstance(value, list) else [value])

    listed = set(pages(config["nav"]))
    on_disk = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    assert listed == on_disk, (sorted(on_disk - listed), sorted(listed - on_disk))


@pytest.mark.slow
def test_the_site_builds_in_strict_mode(tmp_path):
    if shutil.which("mkdocs") is None and importlib.util.find_spec("mkdocs") is None:
        pytest.skip("mkdocs is not installed (the docs extra: pip install -e \".[docs]\")")
    if importlib.util.find_spec("mkdocstrings_handlers") is None or importlib.util.find_spec("material") is None:
        pytest.skip("mkdocs-material or mkdocstrings[python] is not installed (the docs extra)")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "site" / "api" / "simulator" / "index.html").is_file()


def test_every_link_of_docs_opens_a_file():
    """Each relative link of a docs/ page names a file that exists, read from the page's folder (as on GitHub
    and in the site): a report that copies the README's links (`docs/x.md`) into docs/ breaks the strict
    build, and this says which page without mkdocs installed."""
    link = re.compile(r"\[[^\]\n]+\]\(([^)\s]+)\)")
    broken = []
    for page in sorted((ROOT / "docs").rglob("*.md")):
        for target in link.findall(page.read_text()):
            path = target.split("#")[0]
            if "://" in target or target.startswith("mailto:") or not path:
                continue
            if not (page.parent / path).exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, broken
