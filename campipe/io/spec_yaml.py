"""Reading study specs: YAML through ``yaml.SafeLoader`` only.

A spec is plain data (mappings, lists, strings, numbers). The safe loader builds no Python
objects, so a tag such as ``!!python/object`` is refused; a key written twice in one mapping
is refused too (PyYAML would otherwise keep the last one silently).
"""

from __future__ import annotations

from pathlib import Path

import yaml

from campipe.errors import CampipeError
from campipe.io import read_text


class SpecFileError(CampipeError, ValueError):
    """A spec file that cannot be read as YAML data."""


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate mapping keys."""


def _construct_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    loader.flatten_mapping(node)
    seen: dict[object, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if key in seen:
            raise SpecFileError(
                f"line {key_node.start_mark.line + 1}: key {key!r} appears twice in one mapping "
                f"(first on line {seen[key] + 1}); write each key once"
            )
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


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
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}: " if mark else ""
        raise SpecFileError(
            f"{source}: {where}{exc.problem}; a spec holds plain data only "
            "(mappings, lists, strings, numbers)"
        ) from None
    except yaml.YAMLError as exc:
        raise SpecFileError(f"{source}: not valid YAML ({exc})") from None


def read_spec(path: str | Path) -> tuple[object, str]:
    """Read a spec file: its parsed data and its text (kept in the archive).

    Raises
    ------
    SpecFileError
        For a missing or unreadable file, or YAML that :func:`parse_spec_text` refuses.
    """
    path = Path(path)
    text = read_text(path, "the spec", SpecFileError)
    return parse_spec_text(text, str(path)), text
