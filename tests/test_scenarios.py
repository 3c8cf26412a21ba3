"""Scenario variations through the pytest plugin's fixture.

Every built-in scenario is also collected as a test of its own by the plugin (``testpaths``
includes ``scenarios/``), so they are not run a second time here.
"""

import pytest

from tests.conftest import SCENARIOS


@pytest.mark.parametrize("durations, limit_deg", [([1.5] * 4, 0.5), ([3.0] * 4, 0.2)])
def test_hit_tracking_scales_with_speed(run_scenario, durations, limit_deg):
    fast = run_scenario(SCENARIOS / "hit_roundtrip.yaml", planner__segment_durations=durations,
                        duration=sum(durations) + 0.5, write=False)
    assert fast.passed and fast.metrics["tracking_rms_deg"] < limit_deg
