"""Issue 47 count: assertions in tests/ that match message TEXT vs ones that check FIELDS.

Unit: one assert statement, or one pytest.raises(..., match=...) call (counted at its first line).
TEXT  : pytest.raises(match=...); or an assert with a comparison (in / not in / == / !=) or a
        .startswith/.endswith/re.search between a string literal (str, f-string, concatenation) and a
        "textual" expression: str(...)/repr(...), .stderr/.stdout/.out/.err, capsys.readouterr(), .message,
        .cause, .reason, .describe(), .getvalue(), or a local name assigned from one of those.
(A parse of a file's data, json.loads(...)/yaml.safe_load(...), is read as fields, not text.)
FIELD : an assert that reads a field of an error/result: .diagnostics .mark .line .col .quantity .rule
        .breach .returncode .setting .at_s .located .fix, or .joint/.limit/.path not being called,
        or a name `code`/`exit_code`/`rc` compared with an int, or a call of tests/located.py's readers
        (located(), where(), set_located(): a CLI's `file:line:col: path:` lines / a ScenarioError's
        diagnostics read back as fields).
Usage: python count_msgs.py [tests-dir]   (prints per-file counts and totals)
"""
import ast
import sys
from collections import Counter
from pathlib import Path

TEXT_ATTRS = {"stderr", "stdout", "out", "err", "message", "cause", "reason", "text", "output"}
TEXT_CALLS = {"str", "repr", "readouterr", "describe", "getvalue", "read_text", "format_exc"}
FIELD_ATTRS = {"diagnostics", "mark", "line", "col", "quantity", "rule", "breach", "returncode", "setting",
               "at_s", "located", "joint", "limit", "path", "fix"}
CODE_NAMES = {"code", "exit_code", "rc", "status"}
FIELD_READERS = {"located", "where", "set_located"}


def is_str(n):
    if isinstance(n, ast.Constant) and isinstance(n.value, str):
        return True
    if isinstance(n, ast.JoinedStr):
        return True
    if isinstance(n, ast.BinOp) and isinstance(n.op, (ast.Add, ast.Mod)):
        return is_str(n.left) or is_str(n.right)
    return isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr in ("format", "join") \
        and is_str(n.func.value)


STRUCTURED = {"loads", "load", "safe_load", "read_json"}  # a parse of a file's data (JSON, YAML): fields, not text


def _walk(n):
    """ast.walk, not descending into a structured parse (``json.loads(p.read_text())["ended"]["how"]`` reads a
    field of a summary, not a message)."""
    todo = [n]
    while todo:
        s = todo.pop()
        yield s
        if isinstance(s, ast.Call):
            f = s.func
            if (f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None) in STRUCTURED:
                continue
        todo.extend(ast.iter_child_nodes(s))


def textual(n, names):
    for s in _walk(n):
        if isinstance(s, ast.Attribute) and s.attr in TEXT_ATTRS:
            return True
        if isinstance(s, ast.Call):
            f = s.func
            fn = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
            if fn in TEXT_CALLS:
                return True
        if isinstance(s, ast.Name) and s.id in names:
            return True
    return False


def text_names(func):
    names = set()
    for _ in range(3):
        for s in ast.walk(func):
            if isinstance(s, (ast.Assign, ast.AnnAssign)) and s.value is not None:
                targets = s.targets if isinstance(s, ast.Assign) else [s.target]
                if textual(s.value, names) and not isinstance(s.value, (ast.Dict, ast.DictComp)):
                    for t in targets:
                        for x in ast.walk(t):
                            if isinstance(x, ast.Name):
                                names.add(x.id)
            if isinstance(s, (ast.For, ast.comprehension)) and textual(s.iter, names):
                for x in ast.walk(s.target):
                    if isinstance(x, ast.Name):
                        names.add(x.id)
    return names


def is_text_assert(test, names):
    for s in ast.walk(test):
        if isinstance(s, ast.Compare):
            parts = [s.left, *s.comparators]
            for a, op, b in zip(parts, s.ops, parts[1:]):
                if isinstance(op, (ast.In, ast.NotIn, ast.Eq, ast.NotEq)):
                    if (is_str(a) and textual(b, names)) or (is_str(b) and textual(a, names)):
                        return True
                    if isinstance(op, (ast.Eq, ast.NotEq)) and textual(a, names) and textual(b, names) and (
                            is_str(a) or is_str(b)):
                        return True
        if isinstance(s, ast.Call) and isinstance(s.func, ast.Attribute):
            if s.func.attr in ("startswith", "endswith") and textual(s.func.value, names):
                return True
            regex = s.func.attr in ("search", "match", "fullmatch", "findall")
            if regex and any(textual(a, names) for a in s.args[1:]):
                return True
    return False


def is_field_assert(test):
    called = {id(s.func) for s in ast.walk(test) if isinstance(s, ast.Call)}
    for s in ast.walk(test):
        if isinstance(s, ast.Attribute) and s.attr in FIELD_ATTRS and id(s) not in called:
            return True
        if isinstance(s, ast.Call) and isinstance(s.func, ast.Name) and s.func.id in FIELD_READERS:
            return True
        if isinstance(s, ast.Compare):
            parts = [s.left, *s.comparators]
            if any(isinstance(p, ast.Name) and p.id in CODE_NAMES for p in parts) and any(
                    isinstance(p, ast.Constant) and isinstance(p.value, int) for p in parts):
                return True
    return False


def scan(path):
    tree = ast.parse(path.read_text())
    text, field = set(), set()
    funcs = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))] + [tree]
    seen = set()
    for func in funcs:
        names = text_names(func)
        for s in ast.walk(func):
            if id(s) in seen:
                continue
            if isinstance(s, ast.Assert):
                seen.add(id(s))
                if is_text_assert(s.test, names):
                    text.add(s.lineno)
                if is_field_assert(s.test):
                    field.add(s.lineno)
            elif isinstance(s, ast.Call) and any(k.arg == "match" for k in s.keywords) and (
                    isinstance(s.func, ast.Attribute) and s.func.attr in ("raises", "warns")):
                seen.add(id(s))
                text.add(s.lineno)
    return text, field


def main():
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "tests")
    files = sorted(p for p in root.rglob("*.py") if "bad_scenarios" not in p.parts and "data" not in p.parts)
    t_all, f_all, per = 0, 0, Counter()
    for p in files:
        t, f = scan(p)
        t_all += len(t)
        f_all += len(f)
        if t or f:
            per[p.name] = (len(t), len(f))
    if "-v" in sys.argv:
        for name, (t, f) in sorted(per.items(), key=lambda kv: -kv[1][0]):
            print(f"{t:4d} text {f:4d} field  {name}")
    print(f"TOTAL message-text assertions: {t_all}   field assertions: {f_all}")


if __name__ == "__main__":
    main()
