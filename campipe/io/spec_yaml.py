"""Reading study specs: YAML through ``yaml.SafeLoader`` only, within bounds.

A spec is plain data (mappings, lists, strings, numbers). The safe loader builds no Python
objects, so a tag such as ``!!python/object`` is refused; a key written twice in one mapping
is refused too (PyYAML would otherwise keep the last one silently).

Numbers and booleans are read as YAML 1.2 reads them (its core schema), not as PyYAML's
YAML 1.1: ``1e-5`` is a number (YAML 1.1 wants ``1.0e-5`` and reads ``1e-5`` as text), ``010``
is ten (not octal eight), ``1:30`` is text (not ninety, base 60), and only ``true`` and
``false`` are booleans (``no``, ``off``, ``yes``, ``on`` are text, so ``seat: no`` is not
``seat: false``).

A few hundred bytes of YAML can describe an enormous document: aliases (``*a``) repeat what
an anchor (``&a``) names, so nine lines of nine aliases each make a billion strings ("billion
laughs"), and deep nesting exhausts the parser's recursion. Before anything is built, the
document's nesting depth (:data:`MAX_DEPTH`) and its size with every alias expanded
(:data:`MAX_NODES`) are checked; a spec file may hold :data:`MAX_SPEC_BYTES` at most.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from campipe.errors import CampipeError, excerpt
from campipe.io import read_text


class SpecFileError(CampipeError, ValueError):
    """A spec file that cannot be read as YAML data."""


#: Largest spec file read [bytes].
MAX_SPEC_BYTES = 2**20
#: Deepest nesting of mappings and lists.
MAX_DEPTH = 32
#: Most nodes (values, keys, mappings, lists) of a document with its aliases expanded.
MAX_NODES = 200_000


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate mapping keys, deep nesting and documents whose
    aliases expand beyond MAX_NODES nodes."""

    _depth = 0

    def compose_node(self, parent, index):  # noqa: D102 - PyYAML's hook
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise SpecFileError(
                    f"line {mark.line + 1}: nested more than {MAX_DEPTH} levels deep; a spec "
                    "is a few levels of mappings and lists"
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def get_single_node(self):  # noqa: D102 - PyYAML's hook
        node = super().get_single_node()
        if node is not None:
            expanded_size(node)
        return node


def expanded_size(node: yaml.Node) -> int:
    """Nodes of the document under ``node`` with every alias expanded, counted without
    expanding them (an alias is the anchored node itself, shared); SpecFileError beyond
    MAX_NODES or for an alias that contains itself."""
    sizes: dict[int, int] = {}
    active: set[int] = set()

    def size(n: yaml.Node) -> int:
        key = id(n)
        if key in sizes:
            return sizes[key]
        if key in active:
            raise SpecFileError(
                f"line {n.start_mark.line + 1}: an alias refers to a value that contains it; "
                "a spec holds plain data, without cycles"
            )
        active.add(key)
        total = 1
        if isinstance(n, yaml.SequenceNode):
            total += sum(size(child) for child in n.value)
        elif isinstance(n, yaml.MappingNode):
            total += sum(size(k) + size(v) for k, v in n.value)
        active.discard(key)
        if total > MAX_NODES:
            raise SpecFileError(
                f"line {n.start_mark.line + 1}: with its aliases (*name) expanded the "
                f"document holds more than {MAX_NODES} values; write a smaller spec "
                "(a sweep's range {from, to, num} spells a long list in one line)"
            )
        sizes[key] = total
        return total

    return size(node)


def _construct_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    """A mapping whose own keys are each written once. A merge key's (``<<: *base``) are
    not its own: a key written beside it overrides the merged one, as YAML's merge says."""
    own = [k for k, _ in node.value if k.tag != "tag:yaml.org,2002:merge"]
    loader.flatten_mapping(node)
    seen: dict[object, int] = {}
    for key_node in own:
        key = loader.construct_object(key_node, deep=True)
        line = key_node.start_mark.line + 1
        if not isinstance(key, str | int | float | bool | None):
            raise SpecFileError(f"line {line}: a key is {excerpt(key)}; keys are names")
        if key in seen:
            raise SpecFileError(
                f"line {line}: key {excerpt(key)} appears twice in one mapping "
                f"(first on line {seen[key] + 1}); write each key once"
            )
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)

#: YAML 1.2's core schema for plain scalars (https://yaml.org/spec/1.2.2/#1032-tag-resolution):
#: tag → (pattern, the first characters it can start with).
_BOOL, _INT, _FLOAT = (f"tag:yaml.org,2002:{t}" for t in ("bool", "int", "float"))
_CORE = {
    _BOOL: (r"^(?:true|True|TRUE|false|False|FALSE)$", "tTfF"),
    _INT: (r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$", "-+0123456789"),
    _FLOAT: (
        r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
        r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$",
        "-+.0123456789",
    ),
}
_UniqueKeyLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag not in _CORE]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
for _tag, (_pattern, _first) in _CORE.items():
    _UniqueKeyLoader.add_implicit_resolver(_tag, re.compile(_pattern), list(_first))


def _construct_int(loader: _UniqueKeyLoader, node: yaml.ScalarNode) -> int:
    """An integer as YAML 1.2 reads it: decimal (a leading 0 is not octal), 0o…, 0x…."""
    text = str(loader.construct_scalar(node))
    if text.startswith(("0o", "0x")):
        return int(text[2:], 8 if text[1] == "o" else 16)
    return int(text, 10)


_UniqueKeyLoader.add_constructor(_INT, _construct_int)


def parse_spec_text(text: str, source: str = "<spec>") -> object:
    """Parse YAML text into plain data.

    Parameters
    ----------
    text : str
        The YAML document.
    source : str
        Name of the document in error messages (a file name).

    Raises
    ------
    SpecFileError
        For invalid YAML, a Python-object tag or a duplicate key.
    """
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except SpecFileError as exc:
        raise SpecFileError(f"{source}: {exc}") from None
    except (ValueError, OverflowError, RecursionError) as exc:  # e.g. an int of 5000 digits
        raise SpecFileError(
            f"{source}: a value cannot be read ({excerpt(str(exc), 120)})"
        ) from None
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}: " if mark else ""
        raise SpecFileError(
            f"{source}: {where}{exc.problem}; a spec holds plain data only "
            "(mappings, lists, strings, numbers)"
        ) from None
    except yaml.YAMLError as exc:
        tabs = " (indent with spaces: YAML does not take tabs)" if "\t" in text else ""
        raise SpecFileError(f"{source}: not valid YAML{tabs} ({exc})") from None


def read_spec(path: str | Path) -> tuple[object, str]:
    """Read a spec file: its parsed data and its text (kept in the archive).

    Raises
    ------
    SpecFileError
        For a missing, unreadable or oversized file (more than MAX_SPEC_BYTES), or YAML that
        :func:`parse_spec_text` refuses.
    """
    path = Path(path)
    text = read_text(path, "the spec", SpecFileError, MAX_SPEC_BYTES)
    return parse_spec_text(text, str(path)), text


def parse_value(text: str, source: str) -> object:
    """One value written as YAML (``campipe study --set KEY=VALUE``), within the same bounds
    as a spec."""
    if len(text) > MAX_SPEC_BYTES:
        raise SpecFileError.at(source, f"longer than {MAX_SPEC_BYTES} characters")
    return parse_spec_text(text, source)
