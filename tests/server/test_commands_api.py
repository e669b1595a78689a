"""Commands through the API are checked against the protocol's vocabulary before they are queued."""

from __future__ import annotations

from tests.conftest import Tenant


def test_a_bad_command_is_a_422_naming_the_field_and_nothing_is_queued(api, tenant: Tenant):
    uav = tenant.create_asset("uav")
    url = f"/api/v1/assets/{uav['id']}/commands"
    cases = [
        ({"name": "teleport"}, "unknown command 'teleport'"),
        ({"name": "start_charging", "params": {"current_limit_ma": "lots"}}, "current_limit_ma"),
        (
            {"name": "upload_mission", "params": {"items": [{"command": 16, "lat": 123.0}]}},
            "items.0.lat",
        ),
        ({"name": "open", "params": {"fast": True}}, "fast"),
    ]
    for body, where in cases:
        r = api.post(url, headers=tenant.h("operator"), json=body)
        assert r.status_code == 422, r.text
        error = r.json()["error"]
        assert error["code"] == "invalid_command" and where in error["message"], error
    assert api.get(url, headers=tenant.h("viewer")).json() == []


def test_a_good_command_is_queued_with_its_params_as_sent(api, tenant: Tenant):
    base = tenant.create_asset("landing_base")
    r = api.post(
        f"/api/v1/assets/{base['id']}/commands",
        headers=tenant.h("operator"),
        json={"name": "start_charging", "params": {"current_limit_ma": 4000}},
    )
    assert r.status_code == 202, r.text
    assert r.json()["params"] == {"current_limit_ma": 4000} and r.json()["status"] == "queued"
