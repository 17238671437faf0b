"""YAML loading that remembers the line of every key, so errors can point at it, and that
refuses, in one line and before building anything, what a careless or hostile file could do:
bytes that are not UTF-8, a file too large, nesting too deep for the parser's recursion,
aliases that expand past a bound ("billion laughs"), a key given twice."""

from pathlib import Path
from typing import Any

import yaml

from bilba_dist.errors import TaskError
from bilba_dist.files import read_bytes

Location = tuple[str | int, ...]

#: A task or jobs file larger than this is refused unread [bytes].
MAX_FILE_BYTES = 2 * 2**20
#: Nesting deeper than this is refused (PyYAML's composer recurses per level).
MAX_DEPTH = 50
#: Nodes after expanding every alias: the built-in tasks have ~1 000.
MAX_NODES = 200_000

_OPEN = (yaml.MappingStartEvent, yaml.SequenceStartEvent)
_CLOSE = (yaml.MappingEndEvent, yaml.SequenceEndEvent)


def load_yaml_with_lines(text: str, source: str) -> tuple[Any, dict[Location, int]]:
    """Parse ``text``; return the data and a map from key path to 1-based line number."""
    lines: dict[Location, int] = {}
    try:
        _check_shape(text, source)
        loader = yaml.SafeLoader(text)
        try:  # one composition serves the line index and the data
            node = loader.get_single_node()
            data = None
            if node is not None:  # indexed first: constructing flattens merge keys in place
                _index(node, (), lines, source)
                try:
                    data = loader.construct_document(node)
                except yaml.YAMLError:
                    raise
                except Exception as exc:  # PyYAML's constructors raise what they meet
                    raise TaskError(_unreadable_value(node, source, exc)) from None
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise TaskError(f"{where}: not valid YAML: {problem}") from None
    return data, lines


def _check_shape(text: str, source: str) -> None:
    """Walk the parser's events (iterative, nothing built): nesting depth, and the node
    count with every alias expanded (an anchor's size is known when its node closes)."""
    sizes: dict[str, int] = {}
    anchors: list[str | None] = [None]  # per open collection, and the document
    counts = [0]  # values inside each, aliases expanded
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        line = event.start_mark.line + 1 if event.start_mark else 0
        if isinstance(event, _OPEN):
            if len(counts) > MAX_DEPTH:
                raise TaskError(f"{source}:{line}: nested deeper than {MAX_DEPTH} levels")
            anchors.append(event.anchor)
            counts.append(1)
        elif isinstance(event, _CLOSE):
            anchor, size = anchors.pop(), counts.pop()
            counts[-1] += size
            if anchor is not None:
                sizes[anchor] = size
        elif isinstance(event, yaml.AliasEvent):
            counts[-1] += sizes.get(event.anchor or "", 1)
        elif isinstance(event, yaml.ScalarEvent):
            counts[-1] += 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        if sum(counts) > MAX_NODES:
            raise TaskError(
                f"{source}:{line}: aliases expand to over {MAX_NODES} values; write the "
                "repeated parts out, or anchor smaller pieces"
            )


def _index(node: yaml.Node, path: Location, lines: dict[Location, int], source: str) -> None:
    lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        seen: dict[Any, int] = {}
        for key, value in node.value:
            line = key.start_mark.line + 1
            if not isinstance(key, yaml.ScalarNode):  # `- [1, 2]: ` or `? {a: 1}`
                kind = "list" if isinstance(key, yaml.SequenceNode) else "mapping"
                raise TaskError(
                    f"{source}:{line}: a key must be a name, not a {kind} (a stray ':' after "
                    "a value?)"
                )
            if key.value in seen and key.tag != "tag:yaml.org,2002:merge":
                dotted = ".".join(str(p) for p in (*path, key.value))
                raise TaskError(
                    f"{source}:{line}: duplicate key {dotted!r} (first at line {seen[key.value]})"
                )
            seen.setdefault(key.value, line)
            child = (*path, key.value)
            lines[child] = line
            _index(value, child, lines, source)
    elif isinstance(node, yaml.SequenceNode):
        for i, value in enumerate(node.value):
            _index(value, (*path, i), lines, source)


def _unreadable_value(root: yaml.Node, source: str, exc: Exception) -> str:
    """The message for a document PyYAML composed but could not construct: a value its tag
    does not fit (``!!timestamp 5``, ``!!bool maybe``, an integer of over 4300 digits).
    Each scalar is constructed alone, in document order, to find the line."""
    stack, seen = [root], set()
    while stack:
        node = stack.pop()
        if id(node) in seen:  # an alias: the same node again
            continue
        seen.add(id(node))
        if isinstance(node, yaml.ScalarNode) and node.tag != "tag:yaml.org,2002:merge":
            try:
                yaml.SafeLoader("").construct_object(node)
            except Exception as scalar_exc:
                reason = (
                    str(scalar_exc).splitlines()[0] if isinstance(scalar_exc, ValueError) else ""
                )
                tag = node.tag.rsplit(":", 1)[-1]
                detail = reason or f"{node.value[:40]!r} is not a {tag}"
                return f"{source}:{node.start_mark.line + 1}: not valid YAML: {detail}"
        elif isinstance(node, yaml.MappingNode):
            stack.extend(n for pair in reversed(node.value) for n in reversed(pair))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend(reversed(node.value))
    return f"{source}: not valid YAML: {str(exc).splitlines()[0] or type(exc).__name__}"


def line_of(location: Location, lines: dict[Location, int]) -> int | None:
    """The line of the deepest known key along ``location`` (unknown parts are skipped)."""
    path: Location = ()
    best = lines.get(())
    for part in location:
        candidate = (*path, part)
        if candidate in lines:
            path = candidate
            best = lines[candidate]
    return best


def read_text(path: Path, what: str = "task file", limit: int = MAX_FILE_BYTES) -> str:
    """The file's text, which must be a regular file, UTF-8 and at most ``limit`` bytes (a
    device or a pipe is refused before it is opened: /dev/zero never ends, a FIFO blocks)."""
    data = read_bytes(path, what, limit, TaskError)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        utf16 = data[:2] in (b"\xff\xfe", b"\xfe\xff")
        kind = "UTF-16 text" if utf16 else f"byte 0x{data[exc.start]:02X} is not UTF-8"
        raise TaskError(f"{path}:{line}: not UTF-8 ({kind}); save the {what} as UTF-8") from None
