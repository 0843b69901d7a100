"""The generated references of the documentation: the configuration (every section of `NeoSLAMConfig`), the
command line (every command of `neoslam.cli.app`) and the source tree (every module), written from the code at
build time so that they cannot drift.

MkDocs loads this file as a hook (`hooks:` in mkdocs.yml) and calls `on_page_markdown` for every page; a page asks
for a reference with a marker line, `<!-- generated: configuration -->`, `<!-- generated: cli -->` or
`<!-- generated: layout -->` (the source tree, a row per module). Nothing here
imports MkDocs: the tests import this file and check the references without it."""

from __future__ import annotations

import ast
import json
import re
import types
import typing
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import annotated_types
from pydantic import BaseModel, TypeAdapter
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

MARKER = re.compile(r"^<!-- generated: ([a-z-]+) -->$", re.MULTILINE)


RICH_ESCAPE = "\\["  # typer's help strings escape a literal [ from rich markup


def _one_line(text: str) -> str:
    return " ".join(str(text).replace(RICH_ESCAPE, "[").split())


def _cell(text: str) -> str:
    """Text for a markdown table cell: one line, no column breaks, no HTML read into it (outside code spans, which
    keep their text as it is)."""
    parts = _one_line(text).split("`")
    for index in range(0, len(parts), 2):
        parts[index] = parts[index].replace("|", "\\|").replace("<", "&lt;")
    return "`".join(parts)


def _code(text: str) -> str:
    """`text` as a code span in a table cell (Python-Markdown keeps | and < inside one as they are)."""
    return f"`{_one_line(text)}`"


def _number(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _bounds(metadata: list[Any]) -> list[str]:
    """The Field constraints ge/gt/le/lt as `≥ 0`, `< 1`, ..."""
    signs = {annotated_types.Ge: ("≥", "ge"), annotated_types.Gt: (">", "gt")}
    signs |= {annotated_types.Le: ("≤", "le"), annotated_types.Lt: ("<", "lt")}
    bounds = []
    for item in metadata:
        for kind, (sign, attribute) in signs.items():
            if isinstance(item, kind):
                bounds.append(f"{sign} {_number(getattr(item, attribute))}")
    return bounds


def _type_name(annotation: Any, element_bounds: list[str]) -> str:
    """A field's type as a reader writes it in YAML terms (`float`, `"a" | "b"`, `tuple[int, int]`); bounds on the
    elements of a container (Annotated inside it) are collected in `element_bounds`."""
    origin = typing.get_origin(annotation)
    arguments = typing.get_args(annotation)
    if annotation is type(None):
        return "None"
    if origin is typing.Annotated:
        inner, *extras = arguments
        for extra in extras:
            metadata = extra.metadata if isinstance(extra, FieldInfo) else [extra]
            for bound in _bounds(metadata):
                if bound not in element_bounds:
                    element_bounds.append(bound)
        return _type_name(inner, element_bounds)
    if origin is typing.Literal:
        return " | ".join(json.dumps(value) for value in arguments)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_name(argument, element_bounds) for argument in arguments)
    if origin is not None:
        inner = ", ".join("..." if a is Ellipsis else _type_name(a, element_bounds) for a in arguments)
        return f"{getattr(origin, '__name__', str(origin))}[{inner}]"
    return getattr(annotation, "__name__", str(annotation))


def _model_of(annotation: Any) -> tuple[type[BaseModel] | None, bool]:
    """The section model a field holds (also through `Model | None`) and whether it holds a list of them; None for a
    plain value."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation, False
    origin = typing.get_origin(annotation)
    for argument in typing.get_args(annotation):
        model, many = _model_of(argument)
        if model is not None:
            return model, many or origin in (list, tuple)
    return None, False


def _sections(model: type[BaseModel], prefix: str) -> Iterator[tuple[str, type[BaseModel], bool]]:
    for name, field in model.model_fields.items():
        section, many = _model_of(field.annotation)
        if section is not None:
            path = f"{prefix}{name}"
            yield path, section, many
            yield from _sections(section, f"{path}.")


def config_sections() -> Iterator[tuple[str, type[BaseModel]]]:
    """Every section of the configuration, depth first, as (dotted path, model): `perception`,
    `perception.detector`, ..., `motion_limits`."""
    from neoslam.config import NeoSLAMConfig

    for path, model, _ in _sections(NeoSLAMConfig, ""):
        yield path, model


def _anchor(path: str) -> str:
    return "section-" + path.replace(".", "-").replace("_", "-")


def _default(field: FieldInfo) -> str:
    if field.default is PydanticUndefined and field.default_factory is None:
        return "required"
    value = field.default if field.default_factory is None else field.default_factory()  # type: ignore[call-arg]
    dumped = TypeAdapter(field.annotation).dump_python(value, mode="json")
    return f"`{json.dumps(dumped, ensure_ascii=False)}`"


def configuration_reference() -> str:
    """The configuration reference: a heading per section (its dotted path, its docstring) and a table of its
    fields: name, type, default, range (the Field's ge/gt/le/lt) and description."""
    from neoslam.config import NeoSLAMConfig
    from neoslam.config.loading import ENV_NESTED_DELIMITER, ENV_PREFIX

    lines: list[str] = []
    for path, model, many in _sections(NeoSLAMConfig, ""):
        variable = ENV_PREFIX + path.upper().replace(".", ENV_NESTED_DELIMITER) + ENV_NESTED_DELIMITER + "FIELD"
        lines += [f"## `{path}` {{#{_anchor(path)}}}", ""]
        if model.__doc__:
            lines += [" ".join(model.__doc__.split()), ""]
        if many:
            lines += [f"`{path}` is a list; each of its items has these fields.", ""]
        elif any(_model_of(field.annotation)[0] is None for field in model.model_fields.values()):
            lines += [f"Environment variables: `{variable}`.", ""]
        lines += ["| field | type | default | range | description |", "|---|---|---|---|---|"]
        for name, field in model.model_fields.items():
            section, items = _model_of(field.annotation)
            if section is not None:
                link = f"[`{path}.{name}`](#{_anchor(f'{path}.{name}')})"
                kind, default = (f"list of {link}", _default(field)) if items else ("section", link)
                row = [_code(name), kind, default, "", _cell(field.description or "")]
            else:
                element_bounds: list[str] = []
                kind = _type_name(field.annotation, element_bounds)
                bounds = ", ".join(_bounds(field.metadata))
                if element_bounds:
                    bounds = ", ".join(filter(None, [bounds, "each " + ", ".join(element_bounds)]))
                row = [_code(name), _code(kind), _default(field), _cell(bounds), _cell(field.description or "")]
            lines.append("| " + " | ".join(row) + " |")
        lines.append("")
    return "\n".join(lines)


def _commands() -> tuple[Any, Any, list[tuple[str, Any, Any]]]:
    """The root click command of the typer app, its context, and (name, command, context) of every command."""
    import typer.main

    from neoslam.cli import app

    root = typer.main.get_command(app)
    context = root.context_class(root, info_name="neoslam")
    commands = []
    for name in root.list_commands(context):
        command = root.get_command(context, name)
        commands.append((name, command, command.context_class(command, info_name=name, parent=context)))
    return root, context, commands


def _parameters(command: Any, context: Any) -> list[str]:
    rows = []
    for parameter in command.params:
        if parameter.hidden:
            continue
        record = parameter.get_help_record(context)
        if record is None:
            continue
        names, help_text = record
        if parameter.envvar and "env var" not in help_text:
            help_text += f"  [env var: {parameter.envvar}]"
        kind = "argument" if parameter.param_type_name == "argument" else "option"
        rows.append(f"| {_code(names)} | {kind} | {_cell(help_text)} |")
    if not rows:
        return []
    return ["| name | kind | help |", "|---|---|---|", *rows, ""]


def cli_reference() -> str:
    """The command-line reference: `neoslam`'s own options, then per command its usage, help and parameters."""
    root, context, commands = _commands()
    lines = [_one_line(root.help or ""), "", "```text", root.get_usage(context), "```", ""]
    lines += _parameters(root, context)
    for name, command, command_context in commands:
        lines += [f"## `neoslam {name}` {{#command-{name}}}", ""]
        lines += [_one_line(command.help or ""), ""]
        lines += ["```text", command.get_usage(command_context), "```", ""]
        lines += _parameters(command, command_context)
    return "\n".join(lines)


SOURCE = Path(__file__).resolve().parents[2] / "src" / "neoslam"


def _summary(path: Path) -> str:
    """A module's first sentence (of its docstring's first paragraph)."""
    docstring = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    paragraph = _one_line(docstring.split("\n\n")[0])
    sentence = re.split(r"(?<=[a-z0-9)`])(?<!\beq)(?<!e\.g)(?<!i\.e)\. ", paragraph, maxsplit=1)[0]
    return sentence.removesuffix(".")


def layout_reference() -> str:
    """The source tree: a row per module, with the first sentence of its docstring."""
    rows = ["| module | what it holds |", "|---|---|"]
    for path in sorted(SOURCE.rglob("*.py"), key=lambda p: (p.parent != SOURCE, p.parent.as_posix(), p.name)):
        name = path.relative_to(SOURCE.parent).as_posix()
        rows.append(f"| `{name}` | {_cell(_summary(path))} |")
    return "\n".join(rows) + "\n"


GENERATORS: dict[str, Callable[[], str]] = {
    "configuration": configuration_reference,
    "cli": cli_reference,
    "layout": layout_reference,
}


def expand(markdown: str) -> str:
    """`markdown` with every `<!-- generated: NAME -->` line replaced by the reference NAME."""

    def generated(found: re.Match[str]) -> str:
        name = found.group(1)
        if name not in GENERATORS:
            raise ValueError(f"unknown generated reference {name!r} (known: {', '.join(GENERATORS)})")
        return GENERATORS[name]()

    return MARKER.sub(generated, markdown)


def on_page_markdown(markdown: str, **_: Any) -> str:
    """MkDocs hook: expand the markers of every page."""
    return expand(markdown)
