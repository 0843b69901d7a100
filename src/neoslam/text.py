"""Text input files, read one way everywhere: UTF-8 with an optional byte-order mark, one clear error otherwise.

Every reader of a text format (CSV tables, TUM/KITTI files, JSON lines, YAML, calib.txt) goes through
`read_text`, so that a file a Windows editor saved with a BOM is accepted by all of them alike, and a file that is
not text is refused by all of them with the line of its first bad byte.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from neoslam.errors import InputError
from neoslam.inputs import MAX_CONFIG_BYTES, MAX_TEXT_BYTES, read_input_bytes

__all__ = ["DuplicateKey", "YamlLoader", "load_yaml", "read_text", "read_yaml", "utf8_text"]


class DuplicateKey(yaml.constructor.ConstructorError):
    """A mapping that names one key twice (YAML forbids it; PyYAML would keep the last silently)."""

    def __init__(self, key: Any, first: yaml.Mark, again: yaml.Mark) -> None:
        super().__init__(None, None, f"duplicate key {key!r} (first on line {first.line + 1})", again)
        self.key, self.first_line = key, first.line + 1


class YamlLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # libyaml's parser where PyYAML has it
    """PyYAML's safe loader with YAML 1.2's booleans: only true and false. YAML 1.1 also reads on, off, yes and no
    as booleans, so `synchronous: off` would become False instead of the setting's value "off". A key given twice
    in one mapping is refused (DuplicateKey) rather than the last one winning unseen."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, yaml.Mark] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # `<<: *defaults` may be overridden: that is its use
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.setdefault(key, key_node.start_mark)
            except TypeError:  # an unhashable key: SafeConstructor refuses it with its own message
                continue
            if first is not key_node.start_mark:
                raise DuplicateKey(key, first, key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


YamlLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF")
)


def utf8_text(text: str) -> str:
    """Text that encodes as UTF-8: a name from a file name whose bytes are not UTF-8 (os.fsdecode's surrogate
    escapes) has them as `\\xNN` escapes, so that a file it is written into reads back (as that text)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    return text


def load_yaml(text: str) -> Any:
    """A YAML document of safe types, booleans as YAML 1.2 reads them (see YamlLoader)."""
    return yaml.load(text, Loader=YamlLoader)  # noqa: S506 - a SafeLoader subclass


def read_text(path: Path, missing: str = "file not found", limit: int = MAX_TEXT_BYTES) -> str:
    """The file's text; InputError when it is missing (`missing` says so), not a regular file, over `limit`
    bytes, unreadable or not UTF-8 (see neoslam.inputs).

    Line ends are kept as they are (csv needs "\\r\\n" inside quotes intact); `str.splitlines` handles all of them.
    """
    data = read_input_bytes(path, missing, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[: error.start].count(b"\n") + 1
        bad = data[error.start]
        raise InputError(path, f"not a text file (not UTF-8: byte 0x{bad:02x})", line=line) from None


def read_yaml(path: Path, missing: str = "file not found", limit: int = MAX_CONFIG_BYTES) -> Any:
    """The file's YAML document (safe types only), read by `read_text`; InputError naming the line where YAML knows
    it, and for nesting too deep for the parser."""
    text = read_text(path, missing, limit)
    try:
        return load_yaml(text)
    except DuplicateKey as error:
        raise InputError(path, f"not valid YAML ({error.problem})", line=error.problem_mark.line + 1) from None
    except yaml.YAMLError as error:
        if "nesting depth" in str(getattr(error, "problem", "")):  # libyaml's own limit
            raise InputError(path, "not valid YAML (nested too deeply)") from None
        mark = getattr(error, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        raise InputError(path, f"not valid YAML ({error.__class__.__name__})", line=line) from None
    except RecursionError:
        raise InputError(path, "not valid YAML (nested too deeply)") from None
