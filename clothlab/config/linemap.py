"""YAML with the position of every node: the values of a document and where each key and value was written.

:func:`load_yaml_with_lines` reads a YAML file (PyYAML's safe loader, YAML 1.1) and returns its data and a
:class:`LineMap`; :meth:`LineMap.at` gives the (line, column) of a dotted field such as
``fit.optimizer.max_evals`` or ``report.percentiles[1]``.  Lines and columns are 1-based, as editors
count them.  A field that was not written (a default) is placed at its nearest written parent key, so a
message about a missing key points at the section it is missing from.

While walking the composed document the map also rejects what PyYAML's constructor accepts silently but
a configuration must not hold: a key given twice in one mapping (PyYAML keeps the last) and an alias that
refers to the structure containing it (a cycle).  YAML merge keys (``<<: *anchor``) are followed: a merged
key is placed where the anchor wrote it, and a key written explicitly wins over a merged one.  Every
problem is a :class:`~clothlab.errors.ConfigError` naming the file and the line.
"""

from __future__ import annotations

from pathlib import Path

from clothlab.errors import ConfigError
from clothlab.untrusted import MAX_YAML_BYTES, compose_yaml, construct_yaml, read_text

_MERGE_TAG = "tag:yaml.org,2002:merge"

Position = tuple[int | None, int | None]
"""(line, column), both 1-based; (None, None) when nothing on the way to the field was written."""


def dotted(keys: tuple) -> str:
    """The dotted field name of a key path: ``("fit", "free", 1)`` -> ``"fit.free[1]"``."""
    out = ""
    for k in keys:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


class LineMap:
    """Positions of every key and value of one composed YAML document, by key path.

    Key paths are tuples of mapping keys (str) and sequence indices (int); :meth:`at` and :meth:`line`
    also take the dotted spelling of :func:`dotted`.  ``source`` names the document in error messages.
    An empty map (no document, e.g. settings given as a Python mapping) places every field at
    (None, None).
    """

    def __init__(self, root=None, source: str | None = None):
        self.source = source
        self._keys: dict[tuple, Position] = {}
        self._values: dict[tuple, Position] = {}
        self._by_name: dict[str, tuple] = {}
        self._open: set[int] = set()  # nodes being walked (an alias to one of them is a cycle)
        self._done: set[int] = set()  # nodes walked already (aliases are not walked again)
        if root is not None:
            self._walk(root, ())

    # -- queries --------------------------------------------------------------------------------------------

    def at(self, field, key: bool = False) -> Position:
        """(line, column) of the value of ``field`` (of its key with ``key=True``).

        A field that was not written (a default) falls back to the key of its nearest written parent, and
        to (None, None) when no parent was written either.
        """
        if not isinstance(field, tuple):
            return self._at_name(field, key)
        path = field
        table = self._keys if key else self._values
        if path in table:
            return table[path]
        return self.at(path[:-1], key=True) if len(path) > 1 else (None, None)

    def line(self, field, key: bool = False) -> int | None:
        """The line of :meth:`at`."""
        return self.at(field, key=key)[0]

    def fields(self) -> list[str]:
        """The dotted names of every value written in the document, in document order."""
        return [dotted(p) for p in self._values if p]

    def _at_name(self, name: str, key: bool) -> Position:
        if not name:
            return self.at((), key=key)
        if name in self._by_name:
            return self.at(self._by_name[name], key=key)
        # not written: the key of the longest written parent (names may hold dots, so match by prefix)
        parents = [n for n in self._by_name if n and name.startswith(n) and name[len(n)] in ".["]
        if not parents:
            return None, None
        return self.at(self._by_name[max(parents, key=len)], key=True)

    # -- building -------------------------------------------------------------------------------------------

    @staticmethod
    def _position(node) -> Position:
        return node.start_mark.line + 1, node.start_mark.column + 1

    def _error(self, message: str, node, path: tuple) -> ConfigError:
        return ConfigError(message, path=self.source, line=node.start_mark.line + 1, field=dotted(path) or None)

    def _walk(self, node, path: tuple, merged: bool = False) -> None:
        if not merged or path not in self._values:
            self._values[path] = self._position(node)
            self._by_name.setdefault(dotted(path), path)
        if id(node) in self._open:
            raise self._error("a YAML alias refers to the structure containing it (a cycle)", node, path)
        if id(node) in self._done and not merged:
            return
        self._open.add(id(node))
        try:
            self._walk_children(node, path, merged)
        finally:
            self._open.discard(id(node))
        self._done.add(id(node))

    def _walk_children(self, node, path: tuple, merged: bool) -> None:
        import yaml

        if isinstance(node, yaml.MappingNode):
            merges = []
            seen: dict[str, int] = {}
            for key_node, value_node in node.value:
                if key_node.tag == _MERGE_TAG:
                    merges.append(value_node)
                    continue
                if not isinstance(key_node, yaml.ScalarNode):
                    continue
                key = key_node.value
                line = key_node.start_mark.line + 1
                if key in seen and not merged:
                    raise self._error(f"duplicate key '{key}' (first given on line {seen[key]})", key_node,
                                      path + (key,))
                seen[key] = line
                sub = path + (key,)
                if merged and sub in self._keys:
                    continue  # an explicit key wins over a merged one
                self._keys[sub] = self._position(key_node)
                self._walk(value_node, sub, merged)
            for m in merges:  # YAML merge keys ('<<: *anchor'): positions of the anchor's keys
                for part in m.value if isinstance(m, yaml.SequenceNode) else [m]:
                    self._walk(part, path, merged=True)
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                self._walk(item, path + (i,), merged)


def parse_yaml_with_lines(text: str, source: str | None = None):
    """``(data, LineMap)`` of the YAML document ``text``; ``data`` is None for an empty document.

    The document is read by the strict, bounded loader of :mod:`clothlab.untrusted` (plain decimal numbers,
    no timestamps, depth and alias-expansion limits).  A syntax error, a duplicate key, an alias cycle or
    a bound exceeded raises :class:`~clothlab.errors.ConfigError` with ``source`` and the line.
    """
    node, loader = compose_yaml(text, path=source, error=ConfigError)
    try:
        lines = LineMap(node, source=source)
    except BaseException:
        loader.dispose()
        raise
    data = construct_yaml(loader, node, path=source, error=ConfigError)
    return data, lines


def _exists(path) -> bool:
    try:
        return Path(path).exists()
    except OSError:  # e.g. a name too long: the strict reader names the problem
        return True


def load_yaml_with_lines(path):
    """``(data, LineMap)`` of the YAML file ``path`` (a regular UTF-8 file of at most
    :data:`clothlab.untrusted.MAX_YAML_BYTES`); messages name the file as ``str(path)``."""
    source = str(path)
    if "\x00" not in source and not Path(path).is_file() and not Path(path).is_dir() and not _exists(path):
        raise ConfigError(f"configuration file not found: {Path(path).absolute()}", path=source)
    text = read_text(path, limit=MAX_YAML_BYTES, what="configuration file", error=ConfigError)
    return parse_yaml_with_lines(text, source=source)
