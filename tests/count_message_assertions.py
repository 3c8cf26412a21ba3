"""Issue 47 count: assertions in tests/ that match message TEXT vs ones that check FIELDS.

Unit: one assert statement, or one pytest.raises/warns(..., match=...) call (counted at its first line).
TEXT  : pytest.raises/warns(match=...); or an assert with a comparison (in / not in / == / !=) or a
        .startswith/.endswith/re.search between a string literal (str, f-string, concatenation) and a
        "textual" expression: str(...)/repr(...), .stderr/.stdout/.out/.err, capsys.readouterr(), .message,
        .cause, .reason, .said/.problem/.what (an error's words, kept apart from its fix), .describe(),
        .getvalue(), a record's ["message"]/["cause"]/["reason"]/["error"] (a safety event or a sweep row read
        back as a dict), or a local name assigned from one of those (a comprehension: from what it holds, not
        from its filter; a subscript: from what it indexes, not from its index).
        Not text: such a field compared (== / !=) with a code, a literal with no space in it
        (``exc.reason == "other-key"``): a field.
(A parse of a file's data, json.loads(...)/yaml.safe_load(...), or of a message by one of tests/located.py's readers
below, is read as fields, not text.)
FIELD : an assert that reads a field of an error/result: .diagnostics .mark .line .col .quantity .rule
        .breach .returncode .setting .at_s .located .fix, or .joint/.limit/.path not being called (as attributes
        or as a record's keys, ``event["rule"]``), any attribute of a caught error but its words
        (``exc.value.field``; ``err.key`` after ``except ... as err``), or a name `code`/`exit_code`/`rc`
        compared with an int, or a call of tests/located.py's readers (located(), where(), set_located(), at_bag():
        a CLI's `file:line:col: path:` lines / a ScenarioError's diagnostics read back as fields; suggested(): the
        names a misspelt name's fix offers).

The TEXT assertions split in two kinds (an assertion with both is an "errors" one: it asserts an error's words):
  errors: what an error or a refusal says — a pytest.raises/warns(match=...); a text comparison on .message,
          .cause, .reason, .said/.problem/.what, .text or .describe() (an error's, a Diagnostic's, a breach's
          or a safety event's words) or on a record's ["message"]/["cause"]/["reason"]/["error"]; on
          str()/repr() of a caught error (bound by ``pytest.raises(...) as x``, ``except ... as x``, or a name
          taken from one: ``err = x.value``) or format_exc(); on a command's .stderr/.err where the command is
          expected to fail: that process's ``.returncode`` asserted non-zero in the test, or — a process whose
          returncode the test does not assert, or capsys — the exit code asserted last at or before its line
          (else the first after it: ``main(...)``, ``cli(...)``, ``code``/``rc``, ``.returncode`` compared with an
          int, asserted whole or as a part of an ``and``, not as one side of an ``or``) is a non-zero one.
  output: a person's reading matter — .stdout/.out of a command, .stderr/.err of a successful one (its
          warnings), reports and tables, str() of a result that is no caught error, file text read with
          read_text(), log lines, .getvalue() of a stream.
          A text comparison's kind is that of the text searched, not of a literal's interpolated parts
          (``f"PLAN {warning}" in log_lines`` reads log lines). A local name has the kinds of what it was
          assigned from, at its line.
Usage: python count_message_assertions.py [tests-dir] [-v]   (prints per-file counts and totals, then the split)
       --list: also print each TEXT assertion's file:line and its kind (errors/output); counts unchanged
"""
import ast
import re
import sys
from collections import Counter
from pathlib import Path

TEXT_ATTRS = {"stderr", "stdout", "out", "err", "message", "cause", "reason", "text", "output", "said", "problem",
              "what"}
TEXT_CALLS = {"str", "repr", "readouterr", "describe", "getvalue", "read_text", "format_exc"}
TEXT_KEYS = {"message", "cause", "reason", "error"}  # a record's words (a safety event's, a sweep row's error)
FIELD_ATTRS = {"diagnostics", "mark", "line", "col", "quantity", "rule", "breach", "returncode", "setting",
               "at_s", "located", "joint", "limit", "path", "fix"}
CODE_NAMES = {"code", "exit_code", "rc", "status"}
FIELD_READERS = {"located", "where", "set_located", "at_bag", "suggested"}
ERROR_ATTRS = {"message", "cause", "reason", "text", "said", "problem", "what"}  # an error's/event's words
ERROR_CALLS = {"describe", "format_exc"}  # a breach's (an error's) rendering; a traceback
STREAM_ERR = {"stderr", "err"}  # errors when the command failed, else output (a successful command's warnings)
EXIT_CALLS = {"main", "cli", "run_cli"}  # a command run in-process or as a subprocess, its exit code compared
CODE = re.compile(r"^[\w.:/+-]+$")  # a literal with no space in it: a code, not words


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


def _fname(f):
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None


def _walk(n):
    """ast.walk, not descending into a structured parse (``json.loads(p.read_text())["ended"]["how"]`` reads a
    field of a summary, not a message), nor into a comprehension's filter (``[r for r in rows if "x" in r.err]``
    holds rows, not text), nor into a subscript's index."""
    todo = [n]
    while todo:
        s = todo.pop()
        yield s
        if isinstance(s, ast.Call) and _fname(s.func) in STRUCTURED | FIELD_READERS:
            continue  # (a parse into fields: of a file's data, or tests/located.py's of a message)
        if isinstance(s, (ast.ListComp, ast.SetComp, ast.GeneratorExp)):
            todo.append(s.elt)  # what it holds (its names read text where they iterate over text), not its filter
        elif isinstance(s, ast.DictComp):
            todo += [s.key, s.value]
        elif isinstance(s, ast.Subscript):
            todo.append(s.value)  # an item of it: its index is no part of the text (``levels[lines.index(w)]``)
        else:
            todo.extend(ast.iter_child_nodes(s))


def _key(n):
    """The string key of a subscript ``x["key"]``, else None."""
    if isinstance(n, ast.Subscript) and isinstance(n.slice, ast.Constant) and isinstance(n.slice.value, str):
        return n.slice.value
    return None


def message_field(n):
    """``n`` is an error's or record's words read directly: ``.message``/``.cause``/``.reason``, ``["error"]``."""
    return (isinstance(n, ast.Attribute) and n.attr in {"message", "cause", "reason"}) or _key(n) in TEXT_KEYS


def is_code(n):
    return isinstance(n, ast.Constant) and isinstance(n.value, str) and bool(CODE.match(n.value))


class Context:
    """What one test function tells about its textual expressions: which names hold text (and of which kinds),
    which hold a caught error, and which commands it expects to fail."""

    def __init__(self, func):
        self.func = func
        self.caught = self._caught()
        self.exits = self._exits()
        self.names = self._text_names()

    def _caught(self):
        caught = set()
        for s in ast.walk(self.func):
            if isinstance(s, ast.withitem) and isinstance(s.context_expr, ast.Call) and \
                    _fname(s.context_expr.func) in ("raises", "warns") and isinstance(s.optional_vars, ast.Name):
                caught.add(s.optional_vars.id)
            if isinstance(s, ast.ExceptHandler) and s.name:
                caught.add(s.name)
        for _ in range(2):  # a name taken from one: ``err = refused.value``
            for s in ast.walk(self.func):
                if isinstance(s, ast.Assign) and any(isinstance(x, ast.Name) and x.id in caught
                                                     for x in ast.walk(s.value)) and not _text_producing(s.value):
                    caught |= {x.id for t in s.targets for x in ast.walk(t) if isinstance(x, ast.Name)}
        return caught

    def _exits(self):
        """(line, process name or None, non-zero?) for every exit code the test asserts."""
        out = []
        for a in ast.walk(self.func):
            if not isinstance(a, ast.Assert):
                continue
            for s in _asserted(a.test):
                if not isinstance(s, ast.Compare):
                    continue
                parts = [s.left, *s.comparators]
                for x, op, y in zip(parts, s.ops, parts[1:]):
                    pairs = [(x, y)]
                    if isinstance(x, ast.Tuple) and isinstance(y, ast.Tuple) and len(x.elts) == len(y.elts):
                        pairs += list(zip(x.elts, y.elts))
                    for left, right in pairs:
                        for subj, val in ((left, right), (right, left)):
                            who = self._exit_subject(subj)
                            if who is False or not (isinstance(val, ast.Constant) and type(val.value) is int):
                                continue
                            nonzero = val.value != 0 if isinstance(op, ast.Eq) else \
                                val.value == 0 if isinstance(op, ast.NotEq) else isinstance(op, ast.Gt)
                            out.append((a.lineno, who, nonzero))
        return out

    @staticmethod
    def _exit_subject(n):
        """The process whose exit code ``n`` is (its name), None for one not named, False if ``n`` is none."""
        if isinstance(n, ast.Attribute) and n.attr == "returncode":
            return n.value.id if isinstance(n.value, ast.Name) else None
        if isinstance(n, ast.Call) and _fname(n.func) in EXIT_CALLS:
            return None
        if isinstance(n, ast.Name) and n.id in CODE_NAMES:
            return None
        return False

    def failed(self, proc, line):
        """The command (``proc``: its name, or None) read at ``line`` is one the test expects to fail."""
        own = [nz for _, who, nz in self.exits if proc is not None and who == proc]
        if own:
            return any(own)
        before = [(ln, nz) for ln, who, nz in self.exits if ln <= line]
        after = [(ln, nz) for ln, who, nz in self.exits if ln > line]
        if before:
            return max(before)[1]
        return min(after)[1] if after else False

    def kinds(self, n, names=None):
        """The kinds ("errors", "output") of the text ``n`` reads; empty if ``n`` is not textual."""
        names = self.names if names is None else names
        line = getattr(n, "lineno", 0)
        found = set()
        for s in _walk(n):
            if isinstance(s, ast.Attribute) and s.attr in TEXT_ATTRS:
                if s.attr in ERROR_ATTRS:
                    found.add("errors")
                elif s.attr in STREAM_ERR:
                    proc = s.value.id if isinstance(s.value, ast.Name) else None
                    found.add("errors" if self.failed(proc, line) else "output")
                else:
                    found.add("output")
            elif _key(s) in TEXT_KEYS:
                found.add("errors")
            elif isinstance(s, ast.Call) and _fname(s.func) in TEXT_CALLS:
                fn = _fname(s.func)
                of_caught = fn in ("str", "repr") and any(
                    isinstance(x, ast.Name) and x.id in self.caught for a in s.args for x in ast.walk(a))
                found.add("errors" if fn in ERROR_CALLS or of_caught else "output")
            elif isinstance(s, ast.Name) and s.id in names:
                found |= names[s.id]
        return found

    def _text_names(self):
        names = {}
        for _ in range(3):
            for s in ast.walk(self.func):
                if isinstance(s, (ast.Assign, ast.AnnAssign)) and s.value is not None:
                    targets = s.targets if isinstance(s, ast.Assign) else [s.target]
                    k = self.kinds(s.value, names)
                    if k and not isinstance(s.value, (ast.Dict, ast.DictComp)):
                        for t in targets:
                            for x in ast.walk(t):
                                if isinstance(x, ast.Name):
                                    names[x.id] = names.get(x.id, set()) | k
                if isinstance(s, (ast.For, ast.comprehension)):
                    k = self.kinds(s.iter, names)
                    if k:
                        for x in ast.walk(s.target):
                            if isinstance(x, ast.Name):
                                names[x.id] = names.get(x.id, set()) | k
        return names

    def text_kinds(self, test):
        """The kinds of text an assert's ``test`` matches; empty if it matches none."""
        found = set()
        for s in ast.walk(test):
            if isinstance(s, ast.Compare):
                parts = [s.left, *s.comparators]
                for a, op, b in zip(parts, s.ops, parts[1:]):
                    if not isinstance(op, (ast.In, ast.NotIn, ast.Eq, ast.NotEq)):
                        continue
                    if isinstance(op, (ast.Eq, ast.NotEq)) and (message_field(a) and is_code(b) or
                                                                  message_field(b) and is_code(a)):
                        continue  # a code compared, not words
                    ka, kb = self.kinds(a), self.kinds(b)
                    # the text searched, not the literal's own parts (``f"PLAN {warning}" in lines``: log lines)
                    if is_str(a) and kb and not is_str(b):
                        found |= kb
                    elif is_str(b) and ka and not is_str(a):
                        found |= ka
                    elif isinstance(op, (ast.Eq, ast.NotEq)) and ka and kb and (is_str(a) or is_str(b)):
                        found |= ka | kb
            if isinstance(s, ast.Call) and isinstance(s.func, ast.Attribute):
                if s.func.attr in ("startswith", "endswith"):
                    found |= self.kinds(s.func.value)
                if s.func.attr in ("search", "match", "fullmatch", "findall"):
                    for a in s.args[1:]:
                        found |= self.kinds(a)
        return found

    def is_field_assert(self, test):
        called = {id(s.func) for s in ast.walk(test) if isinstance(s, ast.Call)}
        for s in ast.walk(test):
            if isinstance(s, ast.Attribute) and s.attr in FIELD_ATTRS and id(s) not in called:
                return True
            if _key(s) in FIELD_ATTRS:
                return True
            if isinstance(s, ast.Attribute) and id(s) not in called and s.attr not in TEXT_ATTRS | {"value", "args"} \
                    and _rooted_in(s.value, self.caught):
                return True  # a caught error's own field
            if isinstance(s, ast.Call) and isinstance(s.func, ast.Name) and s.func.id in FIELD_READERS:
                return True
            if isinstance(s, ast.Compare):
                parts = [s.left, *s.comparators]
                if any(isinstance(p, ast.Name) and p.id in CODE_NAMES for p in parts) and any(
                        isinstance(p, ast.Constant) and isinstance(p.value, int) for p in parts):
                    return True
                if any(message_field(p) for p in parts) and any(is_code(p) for p in parts) and \
                        all(isinstance(op, (ast.Eq, ast.NotEq)) for op in s.ops):
                    return True  # a code
        return False


def _asserted(test):
    """What an assert's ``test`` asserts of itself: it, or each part of an ``and`` of parts (not what one side of an
    ``or`` says: ``"x" not in out or proc.returncode == 1`` expects no failure)."""
    if isinstance(test, ast.BoolOp) and isinstance(test.op, ast.And):
        return [p for v in test.values for p in _asserted(v)]
    return [test]


def _rooted_in(n, names):
    """``n`` is ``x``, ``x.value`` or ``x.value.where`` for a name ``x`` of ``names``."""
    while isinstance(n, ast.Attribute):
        n = n.value
    return isinstance(n, ast.Name) and n.id in names


def _text_producing(n):
    return isinstance(n, ast.Call) and _fname(n.func) in TEXT_CALLS


def scan(path):
    """(text, field, errors) of a file: the lines of its text assertions, its field ones, and of the text ones
    those asserting an error's words (the rest of the text ones: output)."""
    tree = ast.parse(path.read_text())
    text, field, errors = set(), set(), set()
    funcs = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))] + [tree]
    seen = set()
    for func in funcs:
        ctx = Context(func)
        for s in ast.walk(func):
            if id(s) in seen:
                continue
            if isinstance(s, ast.Assert):
                seen.add(id(s))
                kinds = ctx.text_kinds(s.test)
                if kinds:
                    text.add(s.lineno)
                    if "errors" in kinds:
                        errors.add(s.lineno)
                if ctx.is_field_assert(s.test):
                    field.add(s.lineno)
            elif isinstance(s, ast.Call) and any(k.arg == "match" for k in s.keywords) and (
                    isinstance(s.func, ast.Attribute) and s.func.attr in ("raises", "warns")):
                seen.add(id(s))
                text.add(s.lineno)
                errors.add(s.lineno)
    return text, field, errors


def main():
    root = Path(next((a for a in sys.argv[1:] if not a.startswith("-")), "tests"))
    files = sorted(p for p in root.rglob("*.py") if "bad_scenarios" not in p.parts and "data" not in p.parts)
    t_all, f_all, e_all, per = 0, 0, 0, Counter()
    for p in files:
        t, f, e = scan(p)
        t_all += len(t)
        f_all += len(f)
        e_all += len(e)
        if t or f:
            per[p.name] = (len(t), len(f), len(e))
        if "--list" in sys.argv:  # each counted TEXT line with its kind, to find the ones to convert
            for ln in sorted(t):
                print(f"{p.name}:{ln}: {'errors' if ln in e else 'output'}")
    if "-v" in sys.argv:
        for name, (t, f, e) in sorted(per.items(), key=lambda kv: (-kv[1][0], kv[0])):
            print(f"{t:4d} text {f:4d} field  {name}   (errors {e}, output {t - e})")
    print(f"TOTAL message-text assertions: {t_all}   field assertions: {f_all}")
    print(f"TEXT split: errors {e_all}, output {t_all - e_all}")


if __name__ == "__main__":
    main()
