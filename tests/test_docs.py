"""The documentation: the generated references name every configuration field and every command (docs/hooks/
reference.py writes them when MkDocs builds the site; MkDocs itself is not needed here), every page is in the
site's navigation, the links between the pages and from the README resolve, and the README's Python example runs."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from types import ModuleType

import pytest
import yaml

from neoslam.config import NeoSLAMConfig

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _reference() -> ModuleType:
    spec = importlib.util.spec_from_file_location("docs_reference", DOCS / "hooks" / "reference.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _section_text(reference: str, path: str) -> str:
    """The part of the configuration reference under the heading of section `path`."""
    start = reference.index(f"## `{path}` ")
    end = reference.find("\n## ", start + 1)
    return reference[start : end if end != -1 else None]


def test_the_configuration_reference_names_every_field_of_every_section() -> None:
    reference_module = _reference()
    reference = reference_module.configuration_reference()
    sections = dict(reference_module.config_sections())
    assert set(NeoSLAMConfig.model_fields) <= set(sections)  # every top-level section, nested ones too
    assert {"perception.detector", "simulator.world", "moving_objects"} <= set(sections)
    for path, model in sections.items():
        text = _section_text(reference, path)
        for name in model.model_fields:
            assert f"| `{name}` |" in text, f"{path}.{name} is missing from the configuration reference"


def test_the_configuration_reference_gives_defaults_and_ranges() -> None:
    text = _section_text(_reference().configuration_reference(), "matching")
    row = next(line for line in text.splitlines() if line.startswith("| `min_inliers` |"))
    assert "`4`" in row and "> 0" in row and "≤ 1000" in row
    row = next(line for line in text.splitlines() if line.startswith("| `tolerances` |"))
    assert '"covariance" | "fixed"' in row


def test_the_cli_reference_names_every_command_and_option() -> None:
    import typer.main

    from neoslam.cli import app

    reference = _reference().cli_reference()
    root = typer.main.get_command(app)
    assert list(root.commands)  # the app has commands to document
    for name, command in root.commands.items():
        start = reference.index(f"## `neoslam {name}`")
        end = reference.find("\n## ", start + 1)
        text = reference[start : end if end != -1 else None]
        for parameter in command.params:
            shown = parameter.opts[0] if parameter.param_type_name == "option" else parameter.name
            assert shown in text, f"neoslam {name}: {shown} is missing from the command-line reference"


def test_every_marker_is_expanded_and_an_unknown_one_refused() -> None:
    reference = _reference()
    expanded = reference.expand("# Page\n\n<!-- generated: cli -->\n")
    assert "<!-- generated" not in expanded and "## `neoslam run`" in expanded
    with pytest.raises(ValueError, match="unknown generated reference"):
        reference.expand("<!-- generated: nothing -->\n")
    for page in DOCS.rglob("*.md"):
        for name in reference.MARKER.findall(page.read_text()):
            assert name in reference.GENERATORS, f"{page}: unknown marker {name}"


def _nav_pages(node: object) -> list[str]:
    if isinstance(node, str):
        return [node]
    if isinstance(node, dict):
        return [page for value in node.values() for page in _nav_pages(value)]
    if isinstance(node, list):
        return [page for value in node for page in _nav_pages(value)]
    return []


def test_every_page_is_in_the_navigation() -> None:
    # mkdocs.yml holds no Python tags, so the safe loader reads it
    config = yaml.safe_load((REPO / "mkdocs.yml").read_text())
    listed = _nav_pages(config["nav"])
    pages = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md"))
    assert sorted(listed) == pages
    assert all((DOCS / page).is_file() for page in listed)


@pytest.mark.parametrize("page", [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted(DOCS.rglob("*.md"))])
def test_relative_links_resolve(page: Path) -> None:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code blocks hold no links
    for target in LINK.findall(text):
        if "://" in target or target.startswith(("#", "mailto:")):
            continue
        path = target.split("#", 1)[0]
        assert (page.parent / path).exists(), f"{page.relative_to(REPO)}: broken link {target}"


def test_the_readme_python_example_runs() -> None:
    readme = (REPO / "README.md").read_text()
    code = re.search(r"## Python API\n\n```python\n(.*?)```", readme, re.S)
    assert code, "the README has no Python example under its Python API heading"
    namespace: dict[str, object] = {}
    exec(compile(code.group(1), "README.md", "exec"), namespace)
    result = namespace["result"]
    assert len(result.estimate.poses) == 50  # type: ignore[attr-defined]
