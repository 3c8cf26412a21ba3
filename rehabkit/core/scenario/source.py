"""A scenario's YAML as data with the file, line and column of every key and value: reading, ``extends:``,
a patient profile given as a file, ``--set`` overrides. Validation is :mod:`rehabkit.core.scenario.loader`'s."""

from __future__ import annotations

import copy
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from rehabkit.core.io import YAML_LOADER, load_yaml
from rehabkit.core.scenario.errors import Diagnostic, Mark, ScenarioError

KeyPath = tuple[Any, ...]


@dataclass
class Source:
    """Raw scenario data and where each key path came from."""

    data: dict[str, Any]
    key_marks: dict[KeyPath, Mark]
    value_marks: dict[KeyPath, Mark]
    files: list[Path]


# PyYAML's problems in plain words, with the usual cause and its fix
_USUAL = (
    ("mapping values are not allowed", "a `key: value` where none can be: usually this line is indented deeper than "
     "the key above it (indent it as its siblings are), or a value holding ': ' that needs quotes"),
    ("could not find expected ':'", "a line that is not `key: value`: a ':' missing, or the space after it "
     "(`type:hit` must be `type: hit`)"),
    ("expected <block end>", "this line's indentation does not match its section's: align it with the keys beside "
     "it"),
    ("did not find expected key", "this line's indentation does not match its section's: align it with the keys "
     "beside it"),
    ("did not find expected ',' or ']'", "a list in [brackets] not closed: end it with ']'"),
    ("did not find expected ',' or '}'", "a mapping in {braces} not closed: end it with '}'"),
    ("found unexpected end of stream", "a quote or bracket opened and never closed"),
    ("found duplicate anchor", "an anchor (&name) defined twice"),
    ("found undefined alias", "an alias (*name) whose anchor (&name) is not defined above it"),
)


NO_SPACE = re.compile(r"^[A-Za-z_][\w.-]*:[^\s:/]")  # a key glued to its value (`type:hit`; not a URI's `://`)


def yaml_words(exc: yaml.MarkedYAMLError, text: str) -> str:
    """PyYAML's problem in words a person can act on (its own words after them, in parentheses)."""
    problem = exc.problem or str(exc)
    mark = exc.problem_mark
    if mark is not None and 0 <= mark.index < len(text) and text[mark.index] == "\t":
        return f"a tab: YAML indents with spaces only (replace the tab with spaces) ({problem})"
    for start, words in _USUAL:
        if problem.startswith(start):
            return f"{words} ({problem})"
    return problem


def _mark(file: str, m: yaml.Mark) -> Mark:
    return Mark(file, m.line + 1, m.column + 1)


def read_yaml(path: Path) -> Source:
    """Parse one YAML file, keeping the position of every key and value."""
    name = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ScenarioError([Diagnostic(Mark(name, 0, 0), "", f"cannot read file: {exc.strerror}")]) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:  # located at the first byte that is not UTF-8
        line = raw.count(b"\n", 0, exc.start) + 1
        col = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ScenarioError([Diagnostic(Mark(name, line, col), "", f"the file is not UTF-8 text (byte "
                                        f"0x{raw[exc.start]:02x})", "save it as UTF-8")]) from None
    loader = YAML_LOADER(text)  # libyaml's parser where installed: the same marks
    try:
        node = loader.get_single_node()
        if node is None:
            raise ScenarioError([Diagnostic(Mark(name, 1, 1), "", "the file is empty")])
        data = loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = _mark(name, exc.problem_mark) if exc.problem_mark else Mark(name, 0, 0)
        if (exc.problem or "").startswith("could not find expected ':'") and exc.context_mark is not None:
            mark = _mark(name, exc.context_mark)  # (the line missing its ':'; PyYAML notices it on the next one)
        raise ScenarioError([Diagnostic(mark, "", f"YAML syntax: {yaml_words(exc, text)}")]) from None
    finally:
        loader.dispose()
    if not isinstance(data, dict):
        raise ScenarioError([Diagnostic(_mark(name, node.start_mark), "", "a scenario must be a mapping of sections")])

    key_marks: dict[KeyPath, Mark] = {}
    value_marks: dict[KeyPath, Mark] = {(): _mark(name, node.start_mark)}
    problems: list[Diagnostic] = []

    def walk(n: yaml.Node, path: KeyPath) -> None:
        if isinstance(n, yaml.MappingNode):
            seen: set[Any] = set()
            for k, v in n.value:
                key = k.value if isinstance(k, yaml.ScalarNode) else str(k.value)
                sub = (*path, key)
                if key in seen:
                    problems.append(
                        Diagnostic(
                            _mark(name, k.start_mark), _dotted(sub), "duplicate key (the later one would silently win)"
                        )
                    )
                seen.add(key)
                if isinstance(key, str) and NO_SPACE.match(key) and isinstance(v, yaml.ScalarNode) and v.value == "" \
                        and v.tag.endswith(":null"):  # `{type:hit}`: YAML reads one key, no value
                    left, right = key.split(":", 1)
                    problems.append(Diagnostic(_mark(name, k.start_mark), _dotted(sub), f"'{key}' is one key with no "
                                               f"value: a ':' needs a space after it (`{left}: {right}`)"))
                key_marks[sub] = _mark(name, k.start_mark)
                value_marks[sub] = _mark(name, v.start_mark)
                walk(v, sub)
        elif isinstance(n, yaml.SequenceNode):
            for i, v in enumerate(n.value):
                key_marks[(*path, i)] = value_marks[(*path, i)] = _mark(name, v.start_mark)
                walk(v, (*path, i))

    walk(node, ())
    if problems:
        raise ScenarioError(problems)
    return Source(data, key_marks, value_marks, [path])


def _dotted(path: Iterable[Any]) -> str:
    return ".".join(str(p) for p in path)


def deep_merge(base: Any, over: Any) -> Any:
    """``over`` on top of ``base``: mappings merge, everything else is replaced.

    A mapping whose ``type`` differs from the base's is a different plugin, so it
    replaces the base section instead of inheriting its keys. A key set to
    ``null`` in ``over`` removes the base's key.
    """
    if not (isinstance(base, dict) and isinstance(over, dict)):
        return copy.deepcopy(over)
    if "type" in over and base.get("type") not in (None, over["type"]):
        return copy.deepcopy(over)
    out = copy.deepcopy(base)
    for key, value in over.items():
        if value is None:  # deletes an inherited key (and is no key at all where nothing was inherited)
            out.pop(key, None)
        else:
            out[key] = deep_merge(out[key], value) if key in out else copy.deepcopy(value)
    return out


def read_with_extends(path: Path, chain: tuple[Path, ...] = ()) -> Source:
    """The file with the files it ``extends:`` merged under it (see :func:`deep_merge`), marks kept per key."""
    path = path.resolve()
    if path in chain:
        cycle = " -> ".join(str(p) for p in (*chain, path))
        raise ScenarioError([Diagnostic(Mark(str(path), 0, 0), "extends", f"circular extends: {cycle}")])
    src = read_yaml(path)
    parents = src.data.pop("extends", None)
    if parents is None:
        return src
    if isinstance(parents, str):
        parents = [parents]
    if not (isinstance(parents, list) and all(isinstance(p, str) for p in parents)):
        raise ScenarioError(
            [Diagnostic(src.value_marks[("extends",)], "extends", "expected a file path or a list of them")]
        )
    merged_data: dict[str, Any] = {}
    keys: dict[KeyPath, Mark] = {}
    values: dict[KeyPath, Mark] = {}
    files: list[Path] = []
    for i, parent in enumerate(parents):
        ppath = (path.parent / parent).resolve()
        mark = src.value_marks.get(("extends", i), src.value_marks[("extends",)])
        if not ppath.exists():
            raise ScenarioError([Diagnostic(mark, "extends", f"file not found: {ppath}")])
        if ppath in (*chain, path):  # (said at the line that closes the cycle)
            cycle = " -> ".join(str(p) for p in (*chain, path, ppath))
            raise ScenarioError([Diagnostic(mark, "extends", f"circular extends: {cycle} (a file cannot extend "
                                            "itself through others: remove this extends)")])
        base = read_with_extends(ppath, (*chain, path))
        merged_data = deep_merge(merged_data, base.data)
        keys.update(base.key_marks)
        values.update(base.value_marks)
        files += base.files
    keys = {k: v for k, v in keys.items() if k != ("extends",)}
    keys.update(src.key_marks)
    values.update(src.value_marks)
    return Source(deep_merge(merged_data, src.data), keys, values, [*files, path])


def with_file_sections(src: Source, path: Path, names: Iterable[str]) -> None:
    """``patient: some/profile.yaml`` (a section that may be a file) → that file's mapping, its marks kept (errors
    point into it); the path is relative to the file naming it (a base file's, say; ``--set``: the scenario's)."""
    for name in names:
        ref = src.data.get(name)
        if not isinstance(ref, str):
            continue
        written = src.value_marks.get((name,))
        folder = Path(written.file).parent if written is not None and not written.file.startswith("<") else \
            path.parent
        ppath = (folder / ref).resolve()
        if not ppath.exists():
            raise ScenarioError([Diagnostic(src.value_marks[(name,)], name, f"file not found: {ppath}")])
        held = read_yaml(ppath)
        src.data[name] = held.data
        for marks, theirs in ((src.key_marks, held.key_marks), (src.value_marks, held.value_marks)):
            marks.update({(name, *k): m for k, m in theirs.items()})
        src.files.append(ppath)


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"a.b.c=value"`` → (["a", "b", "c"], value parsed as YAML); a list item by its index, ``targets.1`` or
    ``targets[1]``."""
    if "=" not in text:
        raise ValueError(f"--set '{text}': expected key.path=value")
    key, _, raw = text.partition("=")
    parts = [p for p in re.sub(r"\[(\d+)\]", r".\1", key.strip()).split(".") if p]
    if not parts:
        raise ValueError(f"--set '{text}': empty key")
    try:
        value = load_yaml(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ValueError(f"--set '{text}': value is not valid YAML ({exc})") from None
    return parts, value


def apply_overrides(src: Source, overrides: Iterable[str] | Mapping[str, Any], flag: str = "--set") -> None:
    """Apply ``--set`` style overrides in place; list items are addressed by index; ``null`` deletes the key (its
    default applies), as in a file that extends another. ``flag``: what gave them, where their errors are said
    (``<--set KEY>``; a sweep's grid values ``<--grid KEY>``)."""
    items = overrides.items() if isinstance(overrides, Mapping) else (parse_override(o) for o in overrides)
    for key, value in items:
        parts = key.split(".") if isinstance(key, str) else list(key)
        mark = Mark(f"<{flag} {'.'.join(parts)}>", 0, 0)
        node: Any = src.data
        path: KeyPath = ()
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            if isinstance(node, list):
                if not (part.isdigit() and int(part) < len(node)):
                    raise ScenarioError(
                        [Diagnostic(mark, _dotted(parts), f"'{part}' is not an index of a list of {len(node)}")]
                    )
                part = int(part)
            elif not isinstance(node, dict):
                raise ScenarioError([Diagnostic(mark, _dotted(parts), f"'{_dotted(path)}' is not a mapping")])
            path = (*path, part)
            if last and value is None and isinstance(node, dict):  # null deletes, as in a file that extends
                node.pop(part, None)
            elif last:
                node[part] = (
                    copy.deepcopy(value)
                    if not isinstance(node, dict) or not isinstance(node.get(part), dict)
                    else deep_merge(node[part], value)
                )
            else:
                if isinstance(node, dict) and part not in node:
                    node[part] = {}
                node = node[part]
            src.key_marks[path] = src.value_marks[path] = mark
