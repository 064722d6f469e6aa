"""The one YAML reader of the files users write: duplicate keys refused, lines kept.

PyYAML's ``safe_load`` lets the last of two equal keys win, so a vehicle file with ``mass``
twice is read with the second value and no word said. :func:`load_yaml` refuses it, naming
the file, both lines and the key, and keeps the line of every key and list item
(:attr:`YamlDoc.lines`), so that a later check (:mod:`dampest_ros.io.schema`, a physics
check) can name the line of the value it refuses (:meth:`YamlDoc.error`).

Every message has one form, ``<file>:<line>: <key>: <what is wrong>; <how to fix it>``
(:class:`InputError`).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from dampest_ros.core.physics.rigid_body import ConfigError

#: A position in a document: mapping keys and list indices from the top.
KeyPath = tuple[Any, ...]


class InputError(ConfigError):
    """A user's file refused: the file, the line, the key, what is wrong and the fix.

    ``str(exc)`` is the one line ``<file>:<line>: <key>: <reason>`` (without the line when
    it is unknown, without the key for the document as a whole).
    """

    def __init__(self, source: str, line: int | None, key: str, reason: str) -> None:
        super().__init__(key, reason)
        self.source, self.line = source, line
        where = f"{source}:{line}" if line is not None else source
        self.args = (f"{where}: {key}: {reason}" if key else f"{where}: {reason}",)


def key_text(path: Sequence[Any]) -> str:
    """A key path as users write it: ``thrusters.units[2].position``."""
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


@dataclass(frozen=True)
class YamlDoc:
    """A parsed YAML file and where each of its keys stands.

    Attributes
    ----------
    data : Any
        What ``yaml.safe_load`` gives for the file.
    source : str
        The file, for messages.
    lines : dict
        Key path (mapping keys as text, list indices as int) → 1-based line of the key, or
        of the item's start for a list item.
    """

    data: Any
    source: str
    lines: dict[KeyPath, int] = field(default_factory=dict)

    def line(self, path: Sequence[Any]) -> int | None:
        """The line of ``path``, or of its nearest ancestor that has one."""
        path = tuple(k if isinstance(k, int) else str(k) for k in path)
        for n in range(len(path), -1, -1):
            if path[:n] in self.lines:
                return self.lines[path[:n]]
        return None

    def error(self, path: Sequence[Any], reason: str) -> InputError:
        """An :class:`InputError` for the value at ``path``, its line looked up."""
        return InputError(self.source, self.line(path), key_text(path), reason)


class _Loader(yaml.SafeLoader):  # type: ignore[misc]
    """PyYAML's safe loader; :func:`loads_yaml` checks its node tree before constructing."""


def _walk(loader: _Loader, node: yaml.Node, path: KeyPath, doc: YamlDoc) -> None:
    """Record the lines under ``node`` and refuse a mapping's duplicate keys."""
    if isinstance(node, yaml.MappingNode):
        seen: dict[Hashable, int] = {}
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # '<<': merged keys may be overridden
                _walk(loader, value_node, path, doc)
                continue
            key = loader.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            if isinstance(key, Hashable) and key in seen:
                raise InputError(doc.source, line, key_text((*path, key)),
                                 f"duplicate key (also at line {seen[key]}): the reader would "
                                 "keep only the last value silently; delete one of them")
            if isinstance(key, Hashable):
                seen[key] = line
            doc.lines.setdefault((*path, str(key)), line)
            _walk(loader, value_node, (*path, str(key)), doc)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            doc.lines.setdefault((*path, i), item.start_mark.line + 1)
            _walk(loader, item, (*path, i), doc)


def loads_yaml(text: str, source: str) -> YamlDoc:
    """Parse YAML text (``source`` names it in messages).

    Raises
    ------
    InputError
        Not valid YAML (the line of the problem), or a mapping with a key twice (both lines).
    """
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        doc = YamlDoc(None, source)
        if node is not None:
            _walk(loader, node, (), doc)
            doc = YamlDoc(loader.construct_document(node), source, doc.lines)
        return doc
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        raise InputError(source, None if mark is None else mark.line + 1, "",
                         f"not valid YAML: {exc.problem or exc.context}; fix the syntax "
                         "there") from None
    except yaml.YAMLError as exc:
        raise InputError(source, None, "", f"not valid YAML: {exc}") from None
    finally:
        loader.dispose()


def load_yaml(path: str | Path, kind: str = "a YAML text file") -> YamlDoc:
    """:func:`loads_yaml` of a file.

    Parameters
    ----------
    path : str or Path
    kind : str
        What the file should be, for the message refusing a directory or a binary file
        (e.g. a bag given where a model file belongs).

    Raises
    ------
    InputError
        See :func:`loads_yaml`; a directory, or a file that is not UTF-8 text.
    OSError
        The file cannot be read.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except IsADirectoryError:
        raise InputError(str(path), None, "", f"is a directory, not {kind}") from None
    except UnicodeDecodeError as exc:
        raise InputError(str(path), None, "", f"not a text file (byte {exc.start} is not "
                                              f"UTF-8: binary data, e.g. a bag or an "
                                              f"archive); expected {kind}") from None
    return loads_yaml(text, str(path))
