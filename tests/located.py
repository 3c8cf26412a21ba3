"""Read the CLI's located errors back into fields: ``file:line:col: path: message`` lines as (file, line, col, path),
so a test asserts where an error points (and which setting) rather than how it is worded (issue 47; the wording
is asserted once per kind of message in tests/test_message_wording.py)."""

from __future__ import annotations

import re

LOCATED = re.compile(r"^(?P<file>.+?):(?P<line>\d+):(?P<col>\d+): (?P<path>[\w.\-<> ]+?): ", re.M)


def located(text: str) -> list[tuple[str, int, int, str]]:
    """Every ``file:line:col: path: …`` line of ``text`` (a CLI's stderr) as (file, line, col, path)."""
    return [(m["file"], int(m["line"]), int(m["col"]), m["path"]) for m in LOCATED.finditer(text)]


def where(err) -> list[tuple[int, int, str]]:
    """A :class:`ScenarioError`'s diagnostics as (line, col, path)."""
    return [(d.mark.line, d.mark.col, d.path) for d in err.diagnostics]


SET = re.compile(r"^<--set (?P<set>[^>]+)>: (?P<path>[\w.\-]+): ", re.M)


def set_located(text: str) -> list[tuple[str, str]]:
    """Every ``<--set KEY>: path: …`` line of ``text`` (an error in a ``--set`` override) as (KEY, path)."""
    return [(m["set"], m["path"]) for m in SET.finditer(text)]


AT_BAG = re.compile(r"^(?P<bag>.+?): --topics (?P<role>\w+): ", re.M)


def at_bag(text: str) -> list[tuple[str, str]]:
    """Every ``BAG: --topics ROLE: …`` line of ``text`` (a bag that does not fit the replay, said at the ``--topics``
    role concerned: a :class:`rehabkit.bags.bag_content.BagError`) as (BAG, ROLE)."""
    return [(m["bag"], m["role"]) for m in AT_BAG.finditer(text)]


SUGGESTED = re.compile(r"did you mean ((?:'[^']+'(?: or )?)+)\?")


def suggested(text: str) -> list[str]:
    """Every name a ``did you mean 'a' or 'b'?`` of ``text`` offers (the fix :func:`rehabkit.core.kinds.names.suggest`
    words), in order: a misspelt name's nearest ones, asserted as names rather than as the sentence around them."""
    return [name for m in SUGGESTED.finditer(text) for name in re.findall(r"'([^']+)'", m[1])]


def said(text: str) -> list[str]:
    """What each ``file:line:col: path: …`` (or ``<--set KEY>: path: …``) line of ``text`` says after its place:
    compared with an error's own rendering of the fields a test expects (``WrongUnitKey(...).describe()``), not with
    words written in the test."""
    found = sorted([*LOCATED.finditer(text), *SET.finditer(text)], key=lambda m: m.start())
    return [text[m.end():].split("\n", 1)[0] for m in found]


def refusal(scenario, *sets: str):
    """What ``rehabkit validate SCENARIO --set SET …`` refuses, as the :class:`ScenarioError` it prints: the file,
    then the run's setup but its backend, then its first plan, as validate checks them — its diagnostics' fields
    (``.fix`` among them) asserted rather than its stderr's words (validate has no machine-readable output)."""
    from rehabkit.core.plugins.lifecycle import default_extensions
    from rehabkit.core.plugins.registry import default_registry
    from rehabkit.core.scenario.errors import ScenarioError
    from rehabkit.core.scenario.loader import load_scenario
    from rehabkit.core.setup.assembly import assemble
    from rehabkit.core.setup.first_plan import check_first_plan

    try:
        check_first_plan(assemble(load_scenario(scenario, list(sets)), default_registry(), default_extensions(),
                                  upto="plugins"))
    except ScenarioError as exc:
        return exc
    raise AssertionError(f"validate accepts {scenario} {' '.join(sets)}")
