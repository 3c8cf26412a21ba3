"""Plugin discovery: entry points, conflicts, broken plugins, config models."""

import types

import pytest
from pydantic import BaseModel, ValidationError

from rehabkit import hookimpl
from rehabkit.core.plugins.registry import PluginConflictError, Provider, UnknownPluginError, load_plugins
from tests.located import suggested


def test_built_in_plugins_come_from_entry_points():
    reg = load_plugins()
    assert {"hit", "dh", "mjcf", "urdf"} <= set(reg.names("robot"))
    assert "multi-cubic" in reg.names("planner")
    assert "joint-pd" in reg.names("controller")
    assert "joint-encoder" in reg.names("sensor")
    assert "mujoco" in reg.names("backend")
    info = reg.get("planner", "multi-cubic")
    assert info.provider.package == "rehabkit" and info.provider.entry_point == "multi-cubic"
    assert info.description.startswith("Multi-cubic")
    assert not reg.broken, [b.error for b in reg.broken]


def test_config_model_gets_a_type_literal_and_forbids_extra_keys():
    cfg = load_plugins().get("planner", "multi-cubic").config
    ok = cfg.model_validate({"type": "multi-cubic", "segment_durations": [1.0]})
    assert ok.type == "multi-cubic"
    with pytest.raises(ValidationError) as extra:
        cfg.model_validate({"type": "multi-cubic", "segment_durations": [1.0], "speed": 2})
    assert [(e["type"], e["loc"]) for e in extra.value.errors()] == [("extra_forbidden", ("speed",))]


class _Cfg(BaseModel):
    pass


def _planner_plugin(name):
    ns = types.SimpleNamespace()

    @hookimpl
    def rehabkit_register_planners(registry):
        registry.add(name, config=_Cfg, factory=lambda c, ctx: None, description="test")

    ns.rehabkit_register_planners = rehabkit_register_planners
    return ns


def test_duplicate_kind_and_name_names_both_packages():
    with pytest.raises(PluginConflictError) as exc:
        load_plugins(extra=[(_planner_plugin("multi-cubic"), Provider("evil-planners", "9.9", "mc"))])
    assert (exc.value.kind, exc.value.name) == ("planner", "multi-cubic")
    assert [(p.package, p.version) for p in exc.value.providers] == [("rehabkit", "0.1.0"), ("evil-planners", "9.9")]


def test_broken_plugin_is_listed_and_the_others_keep_working():
    def boom():
        raise ImportError("No module named 'cv3'")

    class Lazy:  # an entry point whose import fails
        pass

    broken_hook = types.SimpleNamespace()

    @hookimpl
    def rehabkit_register_planners(registry):
        raise RuntimeError("planner config is invalid")

    broken_hook.rehabkit_register_planners = rehabkit_register_planners
    misspelt = types.SimpleNamespace(rehabkit_register_planner=hookimpl(lambda registry: None))
    reg = load_plugins(extra=[
        (broken_hook, Provider("broken-pkg", "1.0", "bad")),
        (misspelt, Provider("typo-pkg", "1.0", "typo")),
        (_planner_plugin("fine-planner"), Provider("good-pkg", "1.0", "fine")),
    ])
    causes = {b.provider.package: b.error for b in reg.broken}
    assert "planner config is invalid" in causes["broken-pkg"]
    assert "rehabkit_register_planner" in causes["typo-pkg"]  # hook with no spec fails loudly
    assert "fine-planner" in reg.names("planner") and "multi-cubic" in reg.names("planner")


def test_unknown_plugin_suggests_the_closest_name():
    with pytest.raises(UnknownPluginError) as unknown:
        load_plugins().get("planner", "multicubic")
    assert (unknown.value.kind, unknown.value.name, suggested(str(unknown.value))) == (
        "planner", "multicubic", ["multi-cubic"])


def test_bad_registrations_are_rejected():
    class WithType(BaseModel):
        type: str = "x"

    for bad, match in [(dict(name="Bad Name", config=_Cfg), "lower-case"),
                       (dict(name="ok", config=dict), "pydantic model"),
                       (dict(name="ok", config=WithType), "must not declare 'type'")]:
        plugin = types.SimpleNamespace()

        @hookimpl
        def rehabkit_register_planners(registry, bad=bad):
            registry.add(bad["name"], config=bad["config"], factory=lambda c, ctx: None)

        plugin.rehabkit_register_planners = rehabkit_register_planners
        reg = load_plugins(extra=[(plugin, Provider("p", "1", "e"))])
        assert any(match in b.error for b in reg.broken), (match, [b.error for b in reg.broken])
